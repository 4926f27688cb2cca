"""The evaluation runner: regenerable problem sets, result rows, resumption after kill -9, workers.

Planning uses the stub models of planning_stubs (exact toy dynamics, hand-written symbols); the
plans are refined and executed in the real (fast) Drake world. The CLI test uses small untrained
networks saved as a models directory, so that `tamp evaluate` loads models as users' runs do.
"""
from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from evaluation.configuration import EvalConfig
from evaluation.problems import generate_problems, read_problems, write_problems
from evaluation.row import ROW_KEYS, row_cause
from evaluation.run import evaluate, read_rows, strip_timings
from tamp.app.problem import Problem
from tamp.errors import UserError
from tamp.planning.config import Level1Config, PlanConfig
from tamp.planning.models import Models
from tamp.planning.search import SearchConfig
from tamp.planning.verify import goal_error
from tamp.planning.vocabulary import OUTCOMES
from tests.paths import ROOT
from tests.planning_stubs import StubModel, two_block_domain

SET = dict(ns=(2,), ks=(1, 2, 3), per_cell=1, seed=0)
METHODS = ("deterministic", "probabilistic", "probabilistic_oracle", "cfs", "bilevel", "bilevel_alg1",
           "bilevel_replan", "bilevel_loop")
LOOPS = ("bilevel_replan", "bilevel_loop")
CONFIG = EvalConfig(planner=PlanConfig(search=SearchConfig(max_expansions=300)), progress=False)


def stub_models() -> dict[str, Models]:
    stub = StubModel()
    models = Models(stub, stub, two_block_domain())
    return {m: models for m in METHODS}


@pytest.fixture(scope="module")
def problems_file(tmp_path_factory) -> Path:
    """Three random Drake problems (n = 2, k = 1, 2, 3) and one nothing can solve (the bar stood on its
    end: a scene the world can hold, but no pick-place puts it there)."""
    problems = generate_problems(**SET, progress=False)
    X = problems[0].X_init
    G = X.copy()
    bar = int(np.argmax(X[:, 4]))
    assert X[bar, 4] == 1
    G[bar, 2] = 0.125  # half its length above the table
    problems.append(Problem(X, G, k=1, seed=3, name="n2-unreachable"))
    return write_problems(tmp_path_factory.mktemp("problems") / "problems.jsonl", problems)


@pytest.fixture(scope="module")
def serial(problems_file, tmp_path_factory) -> Path:
    """The rows of one worker."""
    out = tmp_path_factory.mktemp("serial")
    (out / "models").mkdir()
    return evaluate(out / "models", problems_file, out / "results", config=CONFIG, models=stub_models())


def _by_key(rows: list[dict]) -> dict:
    return {(r["problem"], r["method"]): strip_timings(r) for r in rows}


@pytest.mark.sim
def test_problem_sets_are_regenerated_byte_for_byte(problems_file, tmp_path):
    again = write_problems(tmp_path / "again.jsonl", generate_problems(**SET, progress=False))
    first = problems_file.read_bytes().splitlines(keepends=True)[:3]
    assert again.read_bytes() == b"".join(first)
    problems = read_problems(again)
    assert [p.name for p in problems] == ["n2-k1-000", "n2-k2-000", "n2-k3-000"]
    for p in problems:  # the stored actions generated the goal, and they moved something
        assert len(p.actions) == p.k and goal_error(p.X_init, p.X_goal) > 0.01
    other = write_problems(tmp_path / "other.jsonl", generate_problems(ns=(2,), ks=(1,), per_cell=1, seed=1,
                                                                       progress=False))
    assert other.read_bytes() != first[0]


@pytest.mark.sim
def test_a_stuck_scene_is_replaced_by_the_next_seed_of_its_problem(monkeypatch):
    import evaluation.problems as ep

    real, tried = ep.random_problem, []

    def stuck_first(n, k, seed, world=None, name=None, **kwargs):
        tried.append(seed)
        if len(tried) == 1:
            raise ep.StuckScene("stuck")
        return real(n, k, seed, world=world, name=name, **kwargs)

    monkeypatch.setattr(ep, "random_problem", stuck_first)
    (problem,) = ep.generate_problems(ns=(2,), ks=(1,), per_cell=1, seed=5, progress=False)
    assert tried == [ep.scene_seed(5, 2, 1, 0), ep.scene_seed(5, 2, 1, 0, attempt=1)]
    assert problem.seed == tried[1] and problem.name == "n2-k1-000"
    monkeypatch.setattr(ep, "random_problem", lambda *a, **kw: (_ for _ in ()).throw(ep.StuckScene("stuck")))
    with pytest.raises(ep.UserError, match="n2-k1-000: no scene out of 10"):
        ep.generate_problems(ns=(2,), ks=(1,), per_cell=1, seed=5, progress=False)


@pytest.mark.sim
def test_the_paper_protocol_keeps_actions_that_move_nothing():
    """`paper`: the first k drawn actions whatever they do (replayed, they give the goal and move
    exactly `moved` times); `strict` redraws until every one moves a block."""
    from tamp.app.problem import MOVED_M
    from tamp.sim import World, WorldConfig

    args = dict(ns=(2,), ks=(1, 3), per_cell=3, seed=2, progress=False)
    paper = generate_problems(**args, protocol="paper")
    strict = generate_problems(**args)
    world = World(WorldConfig())
    for p, s in zip(paper, strict):
        assert (p.protocol, s.protocol, s.moved, p.name, p.seed) == ("paper", "strict", s.k, s.name, s.seed)
        assert np.array_equal(p.X_init, s.X_init) and len(p.actions) == p.k  # same scene, k actions kept
        X, moved = world.reset(X=p.X_init), 0
        for a in p.actions:
            X_next, _ = world.step(a)
            moved += np.max(np.linalg.norm(X_next[:, :3] - X[:, :3], axis=1)) >= MOVED_M
            X = X_next
        assert moved == p.moved and goal_error(X, p.X_goal) < 1e-3
    assert sum(p.moved for p in paper) < sum(p.k for p in paper)  # no-op actions were kept
    assert any(p.k == 1 and p.moved == 0 and goal_error(p.X_init, p.X_goal) < MOVED_M for p in paper)


@pytest.mark.sim
def test_several_runs_are_the_sets_of_consecutive_seeds():
    runs = generate_problems(ns=(2,), ks=(1,), per_cell=2, seed=4, runs=2, progress=False, protocol="paper")
    assert [(p.name, p.run) for p in runs] == [("r0-n2-k1-000", 0), ("r0-n2-k1-001", 0), ("r1-n2-k1-000", 1),
                                               ("r1-n2-k1-001", 1)]
    single = generate_problems(ns=(2,), ks=(1,), per_cell=2, seed=5, progress=False, protocol="paper")
    assert [p.seed for p in runs[2:]] == [p.seed for p in single] and single[0].run is None


@pytest.mark.sim
@pytest.mark.parametrize("edit, message", [
    (lambda lines: lines[:1] + ["{not json"] + lines[2:], "line 2: not valid JSON"),
    (lambda lines: lines[:2] + [lines[2].replace('"X_goal"', '"X_gaol"')] + lines[3:],
     "line 3: missing field 'X_goal'"),
    (lambda lines: lines[:1] + [lines[1].replace('"seed": ', '"seed": "x", "s": ')] + lines[2:],
     "line 2: seed: expected an integer, got \"x\""),
    (lambda lines: lines + [lines[0]], "line 5: duplicate problem name 'n2-k1-000' (also on line 1)"),
])
def test_a_malformed_problem_set_names_the_line_and_field(problems_file, tmp_path, edit, message):
    bad = tmp_path / "bad.jsonl"
    bad.write_text("\n".join(edit(problems_file.read_text().splitlines())) + "\n")
    with pytest.raises(ValueError) as info:
        read_problems(bad)
    assert str(bad) in str(info.value) and message in str(info.value)


@pytest.mark.sim
@pytest.mark.slow
def test_rows_follow_the_schema_and_their_outcomes_agree(serial, problems_file):
    rows = read_rows(serial)
    problems = {p.name: p for p in read_problems(problems_file)}
    assert sorted((r["problem"], r["method"]) for r in rows) == sorted((p, m) for p in problems for m in METHODS)
    for r in rows:
        assert tuple(r) == ROW_KEYS
        p = problems[r["problem"]]
        assert (r["n"], r["k"], r["fidelity"], r["eps_m"], r["tau_verify_m"]) == (p.n, p.k, "fast", 0.05, 0.07)
        assert r["outcome"] in OUTCOMES
        assert r["success"] == (r["outcome"] == "success")
        assert r["cause"] == row_cause(r) and (r["cause"] is None) == r["success"]  # recomputed from the row
        assert len(r["step_miss_m"] or []) == r["executed_actions"] and r["stop"]["loop"] in (None, "goal", "rounds",
                                                                                             "no_plan", "empty_plan")
        assert (r["refine_failure"] is None) == (r["refined"] is not False)
        assert r["planning_time_s"] > 0 and 0 <= r["level1_time_s"] <= r["planning_time_s"]
        assert len(r["candidates"]) <= 20
        assert (r["rounds"] is None) == (r["method"] not in LOOPS)
        assert (r["run"], r["protocol"], r["moved"]) == ((0, "strict", p.k) if p.actions else (0, None, None))
        assert r["symbolic_backend"] == (None if r["method"] == "cfs" else "python")
        if r["method"] in LOOPS:
            assert r["executed_plans"] is None
            steps = r["steps"] or []  # each executed action names its round, and whether that round planned or kept
            assert all(s["plan"] in ("planned", "widened search", "toward the closest state", "kept on course",
                                     "kept by rollout") for s in steps)
            assert [s["plan"] for s in steps[:1]] in ([], ["planned"], ["widened search"],
                                                      ["toward the closest state"])  # round 0 plans
            assert [s["round"] for s in steps] == sorted(s["round"] for s in steps)
        elif r["method"] != "probabilistic_oracle":
            assert r["executed_plans"] == int(r["solved"])
        if not r["solved"]:
            assert r["outcome"] == "no_plan" and r["plan"] is None and r["refined"] is None
            assert r["executed_actions"] == 0 and r["predicted_error_m"] is None and not r["effect_error_m"]
            assert r["final_error_m"] == pytest.approx(goal_error(p.X_init, p.X_goal), abs=1e-6)
            continue
        # the Dynamics Model's one-step error on every executed action (the stub mimics the world: cm, not m)
        assert len(r["effect_error_m"]) == r["executed_actions"]
        assert all(0 <= e < 0.1 for e in r["effect_error_m"])
        assert r["level"] in (1, 2) and r["predicted_error_m"] >= 0
        assert r["executed_actions"] == len(r["refine_time_s"]) <= len(r["plan"])
        if r["refine_failure"] is not None and not (r["method"] == "bilevel_loop" and r["success"]):
            stage = r["refine_failure"]["stage"]
            assert r["outcome"] == ("kinematic_failure" if stage == "ik" else "refinement_failure")
            if r["method"] not in LOOPS:  # open loop: execution stops at the failing action
                assert r["refine_failure"]["action"] == r["executed_actions"]
        else:
            assert r["outcome"] == ("success" if r["final_error_m"] < 0.05 else "wrong_plan")
            if r["method"] not in LOOPS:
                assert r["executed_actions"] == len(r["plan"])
    outcomes = {r["outcome"] for r in rows}
    assert {"success", "no_plan", "wrong_plan"} <= outcomes  # the set exercises the branches
    # what the Symbolic Model's bits mean on the set's scenes: the stub's bit is 'on the table'
    bits = {b["name"]: b for b in json.loads((serial.parent / "symbols.json").read_text())}
    assert set(bits) == {"u0", "r0", "r0(i,i)"} and bits["u0"]["count"] == 2 * 2 * len(problems)
    assert bits["u0"]["best"] == "elevated (z > 4 cm)" and bits["u0"]["negated"]["elevated (z > 4 cm)"]
    assert all(not r["solved"] for r in rows if r["problem"] == "n2-unreachable" and r["method"] not in LOOPS)
    assert [r["level"] for r in rows if r["method"] == "cfs" and r["solved"]] == [2] * sum(
        r["solved"] for r in rows if r["method"] == "cfs")


@pytest.mark.sim
def test_the_oracle_succeeds_iff_one_executed_plan_succeeds(serial):
    """probabilistic_oracle executes the ranked plans, top first, and stops at the first success."""
    rows = {(r["problem"], r["method"]): r for r in read_rows(serial)}
    problems = sorted({p for p, _ in rows})
    tried_more = 0
    for p in problems:
        top, oracle = rows[p, "probabilistic"], rows[p, "probabilistic_oracle"]
        assert oracle["solved"] == top["solved"] and oracle["candidates"] == top["candidates"]
        if not top["solved"]:
            assert oracle["executed_plans"] == 0 and not oracle["success"]
            continue
        assert 1 <= oracle["executed_plans"] <= min(len(oracle["candidates"]), CONFIG.oracle_max_plans)
        if top["success"]:  # the top plan is tried first, in the same reseeded world
            assert oracle["success"] and oracle["executed_plans"] == 1 and oracle["plan"] == top["plan"]
        elif oracle["success"]:  # a later plan reached the goal: it is the one reported
            assert oracle["executed_plans"] > 1 and oracle["plan"] != top["plan"]
            tried_more += 1
        else:  # every plan was tried (up to the cap) and none reached the goal
            assert oracle["executed_plans"] == min(len(oracle["candidates"]), CONFIG.oracle_max_plans)
            tried_more += oracle["executed_plans"] > 1
    assert tried_more >= 1  # the set exercises the oracle beyond the top plan


def test_the_oracle_counts_success_iff_some_plan_reaches_the_goal(monkeypatch):
    """Three ranked plans of which only the last reaches the goal: success after three executions;
    with a cap of two plans, failure after two."""
    import evaluation.run as er
    from evaluation.run import Evaluator
    from tamp.planning.results import Candidate, PlanResult

    problem = Problem(np.zeros((2, 5)), np.ones((2, 5)), k=1, seed=0, name="p")
    ranked = [Candidate(((0, 0, 1, 0),), 5, 0.5), Candidate(((0, 1, 1, 0),), 3, 0.3),
              Candidate(((1, 0, 0, 0),), 2, 0.2)]
    executed = []

    def fake_plan(method, models, X_init, X_goal, cfg):
        return PlanResult(method, [ranked[0].actions[0]], level=1, candidates=list(ranked), timings={"total": 0.01},
                          predicted_error=0.2)

    def fake_execute(self, problem, actions, models, plan_states=None, scene=None):
        executed.append(actions)
        good = actions == ranked[2].actions
        return {"refined": True, "refine_failure": None, "refine_time_s": [0.1], "executed_actions": 1,
                "final_error_m": 0.0 if good else 0.3, "effect_error_m": [0.01]}

    import tamp.planning.planners

    monkeypatch.setattr(tamp.planning.planners, "plan", fake_plan)
    monkeypatch.setattr(Evaluator, "_execute", fake_execute)
    monkeypatch.setattr(Evaluator, "warm_up", lambda self, models, problem: None)
    for cap, success, tried in ((20, True, 3), (2, False, 2)):
        executed.clear()
        evaluator = Evaluator({"probabilistic_oracle": None, "probabilistic": None},
                              er.EvalConfig(progress=False, oracle_max_plans=cap))
        row = evaluator.run(problem, "probabilistic_oracle")
        assert (row["success"], row["executed_plans"], len(executed)) == (success, tried, tried)
        assert row["plan"] == [list(a) for a in executed[-1]]
        executed.clear()
        top = evaluator.run(problem, "probabilistic")  # the unverified planner executes its top plan only
        assert not top["success"] and top["executed_plans"] == 1
        assert [tuple(map(tuple, e)) for e in executed] == [ranked[0].actions]


@pytest.mark.sim
@pytest.mark.slow
def test_an_evaluation_killed_midway_resumes_without_redoing_or_losing_rows(serial, problems_file, tmp_path):
    """Killed and resumed on the set's first two problems and two of its methods (an open-loop and a closed-loop
    one): a row depends on its problem and method alone."""
    (tmp_path / "models").mkdir()
    out = tmp_path / "results"
    methods = ["deterministic", "bilevel_loop"]
    problems_file = write_problems(tmp_path / "problems.jsonl", read_problems(problems_file)[:2])
    script = ("from tests.evaluation.test_run import CONFIG, stub_models\n"
              "from evaluation.run import evaluate\n"
              f"evaluate({str(tmp_path / 'models')!r}, {str(problems_file)!r}, {str(out)!r}, {methods!r}, "
              "config=CONFIG, models=stub_models())\n")
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=ROOT)
    rows_path = out / "rows.jsonl"
    deadline = time.monotonic() + 120
    while not (rows_path.exists() and rows_path.read_bytes().count(b"\n") >= 2):
        assert proc.poll() is None and time.monotonic() < deadline, "the evaluation ended before any row"
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    before = rows_path.read_bytes()
    complete = before[:before.rfind(b"\n") + 1]
    n_before = complete.count(b"\n")
    total = 2 * len(methods)
    assert 2 <= n_before < total, "killed too late to test resumption"
    with open(rows_path, "ab") as f:  # a kill in the middle of writing a row leaves half a line
        f.write(complete.splitlines(keepends=True)[0][:40])
    evaluate(tmp_path / "models", problems_file, out, methods, config=CONFIG, models=stub_models())
    after = rows_path.read_bytes()
    assert after.startswith(complete)  # the finished rows are untouched
    rows = read_rows(rows_path)
    keys = [(r["problem"], r["method"]) for r in rows]
    assert len(keys) == len(set(keys)) == total
    assert _by_key(rows) == {k: v for k, v in _by_key(read_rows(serial)).items()
                             if k[0] in ("n2-k1-000", "n2-k2-000") and k[1] in methods}
    # running again computes nothing, also with the results and the problem set moved elsewhere
    evaluate(tmp_path / "models", problems_file, out, methods, config=CONFIG, models=stub_models())
    assert rows_path.read_bytes() == after
    moved = tmp_path / "moved"
    shutil.copytree(out, moved / "results")
    shutil.copy(problems_file, moved / "problems.jsonl")
    evaluate(tmp_path / "models", moved / "problems.jsonl", moved / "results", methods, config=CONFIG,
             models=stub_models())
    assert (moved / "results" / "rows.jsonl").read_bytes() == after
    assert json.loads((moved / "results" / "meta.json").read_text())["problems"] == str(moved / "problems.jsonl")


@pytest.mark.sim
@pytest.mark.slow
def test_two_workers_give_the_same_rows_as_one(serial, problems_file, tmp_path):
    """Two solvable problems (k = 1, 2) by two methods (an open-loop and a closed-loop one): four rows shared out
    between the workers, each of which plans and executes its rows one after another."""
    (tmp_path / "models").mkdir()
    methods = ["probabilistic_oracle", "bilevel_replan"]
    problems_file = write_problems(tmp_path / "problems.jsonl", read_problems(problems_file)[:2])
    rows = read_rows(evaluate(tmp_path / "models", problems_file, tmp_path / "results", methods,
                              config=EvalConfig(planner=PlanConfig(search=SearchConfig(max_expansions=300)),
                                                progress=False, workers=2),
                              models=stub_models()))
    assert len(rows) == 4 and _by_key(rows) == {k: v for k, v in _by_key(read_rows(serial)).items()
                                                if k[0] in ("n2-k1-000", "n2-k2-000") and k[1] in methods}


@pytest.mark.sim
def test_fast_downward_plans_like_the_in_process_search(serial, problems_file, tmp_path):
    """--symbolic-backend fd: recorded in meta.json and the rows, and the symbolic planners reach the
    same success on every problem as with the in-process search (both find shortest plans)."""
    (tmp_path / "models").mkdir()
    config = EvalConfig(planner=PlanConfig(level1=Level1Config(backend="fd"), search=SearchConfig(max_expansions=300)),
                        progress=False)
    rows = read_rows(evaluate(tmp_path / "models", problems_file, tmp_path / "results", config=config,
                              methods=["deterministic", "probabilistic"], models=stub_models()))
    assert json.loads((tmp_path / "results" / "meta.json").read_text())["config"]["level1"]["backend"] == "fd"
    python = {(r["problem"], r["method"]): r for r in read_rows(serial)}
    assert len(rows) == 8
    for r in rows:
        assert r["symbolic_backend"] == "fd"
        other = python[r["problem"], r["method"]]
        assert (r["solved"], r["success"], len(r["plan"] or [])) == \
            (other["solved"], other["success"], len(other["plan"] or []))


@pytest.mark.sim
def test_a_results_directory_refuses_other_inputs(serial, problems_file, tmp_path):
    other = tmp_path / "other.jsonl"
    write_problems(other, read_problems(problems_file)[:2])
    with pytest.raises(ValueError, match="problems_sha256: "):
        evaluate(serial.parents[1] / "models", other, serial.parent, config=CONFIG, models=stub_models())
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "dynamics.pt").write_bytes(b"other weights")
    with pytest.raises(ValueError, match="model_files.dynamics.pt: "):
        evaluate(tmp_path / "models", problems_file, serial.parent, config=CONFIG, models=stub_models())
    with pytest.raises(ValueError, match='config.fidelity: "fast" there, "full" now'):
        evaluate(serial.parents[1] / "models", problems_file, serial.parent, models=stub_models(),
                 config=EvalConfig(planner=PlanConfig(search=SearchConfig(max_expansions=300)), progress=False,
                                   fidelity="full"))


# --------------------------------------------------------------------------- the CLI, real model files

@pytest.fixture(scope="module")
def models_dir(tmp_path_factory) -> Path:
    """Untrained (seeded) networks, a domain learned from their symbols, and the optional variants."""
    torch = pytest.importorskip("torch")
    from learned import EffectModel, ModelConfig, save_checkpoint
    from learned.synthetic import generate
    from symbolic import build_domain

    out = tmp_path_factory.mktemp("models")
    (out / "variants").mkdir()
    torch.manual_seed(0)
    data = generate(300, seed=0, n_choices=(2,))
    # (dynamics file, its activation, symbolic file, its activation, domain directory)
    for dyn, dyn_act, sym_file, sym_act, domain in (
            ("dynamics.pt", "sigmoid", "symbolic.pt", "gumbel_sigmoid", "domain"),
            ("variants/dynamics_gumbel.pt", "gumbel_sigmoid", "variants/symbolic_sigmoid.pt", "sigmoid",
             "variants/domain_sigmoid")):
        save_checkpoint(out / dyn, EffectModel(ModelConfig(d_z=2, heads=1, activation=dyn_act)))
        sym = EffectModel(ModelConfig(d_z=2, heads=1, activation=sym_act)).eval()
        save_checkpoint(out / sym_file, sym)
        u0, r0 = sym.symbols_batch(data.X, data.mask)
        u1, r1 = sym.symbols_batch(data.X_next, data.mask)
        build_domain(u0, r0, data.action, u1, r1, data.n, out / domain, holdout=0.0)
    return out


@pytest.mark.sim
def test_cli_evaluates_with_model_files_and_keeps_the_rows_when_the_report_fails(models_dir, tmp_path, capsys,
                                                                               monkeypatch):
    from evaluation import cli
    from evaluation.methods import default_methods
    from tamp.app.cli import main

    assert default_methods(models_dir) == list(METHODS) + ["symbolic_sigmoid", "cfs_gumbel"]
    problems = tmp_path / "p.jsonl"
    assert main(["problems", "--out", str(problems), "--objects", "2", "--actions", "1", "--per-cell", "1",
                 "--quiet"]) == 0
    assert [p.name for p in read_problems(problems)] == ["n2-k1-000"]

    def broken_report(directory, ablation=None):
        raise RuntimeError("the report module broke")

    monkeypatch.setattr(cli, "_write_report", broken_report)
    out, config = tmp_path / "results", tmp_path / "c.toml"
    config.write_text("[search]\nmax_expansions = 50\n")
    capsys.readouterr()
    assert main(["evaluate", "--models", str(models_dir), "--problems", str(problems), "--out", str(out),
                 "--methods", "cfs_gumbel,symbolic_sigmoid,cfs", "--config", str(config), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "warning: no report" in err and "the report module broke" in err and "Traceback" not in err
    rows = read_rows(out / "rows.jsonl")
    assert [r["method"] for r in rows] == ["cfs", "symbolic_sigmoid", "cfs_gumbel"]  # the report order
    assert all(tuple(r) == ROW_KEYS for r in rows)
    meta = json.loads((out / "meta.json").read_text())
    assert meta["models_dir"] == str(models_dir.resolve()) and "variants/dynamics_gumbel.pt" in meta["model_files"]


@pytest.mark.sim
def test_cli_names_a_missing_variant_and_a_bad_method(problems_file, tmp_path, capsys):
    from tamp.app.cli import main

    models = tmp_path / "models"
    models.mkdir()
    (models / "dynamics.pt").write_bytes(b"")
    problems = problems_file
    for methods, message in (("cfs_gumbel", f"{models / 'variants' / 'dynamics_gumbel.pt'}"),
                             ("bilevel,nope", "unknown method 'nope'")):
        assert main(["evaluate", "--models", str(models), "--problems", str(problems), "--out",
                     str(tmp_path / "out"), "--methods", methods]) == 2
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and message in err


@pytest.mark.sim
@pytest.mark.slow
def test_reproduce_evaluates_given_models_under_the_paper_protocol_over_runs(models_dir, tmp_path, monkeypatch):
    """`tamp reproduce --models DIR --protocol paper --runs 2`: no collection or training, two problem
    sets of consecutive seeds kept whatever their actions did, a report with mean ± std over runs;
    a second call resumes and computes nothing."""
    import evaluation.reproduce as rep
    from tamp.app.cli import main

    monkeypatch.setitem(rep.SCALES, "quick", rep.Scale(samples=0, epochs=0, train_time_limit_s=None, ablation_runs=0,
                                                       ablation_epochs=0, per_cell=1, search_time_limit_s=0.5,
                                                       objects=(2,), actions=(1,)))
    out = tmp_path / "repro"
    args = ["reproduce", "--out", str(out), "--models", str(models_dir), "--protocol", "paper", "--runs", "2",
            "--workers", "1"]
    assert main(args) == 0
    problems = read_problems(out / "problems.jsonl")
    assert [(p.name, p.protocol, p.run) for p in problems] == [("r0-n2-k1-000", "paper", 0),
                                                               ("r1-n2-k1-000", "paper", 1)]
    stages = json.loads((out / "stages.json").read_text())
    assert set(stages["finished"]) == {"problems", "evaluate", "report"} and not (out / "data").exists()
    assert stages["setup"]["protocol"] == "paper" and stages["setup"]["runs"] == 2
    report = (out / "results" / "report.md").read_text()
    assert "| runs | 2 |" in report and "| protocol | paper |" in report and "oracle runs (%)" in report
    rows = (out / "results" / "rows.jsonl").read_bytes()
    assert main(args) == 0 and (out / "results" / "rows.jsonl").read_bytes() == rows
    assert main(args[:-4] + ["--runs", "3", "--workers", "1"]) == 2  # other settings in the same OUT: refused


def test_an_evaluation_with_a_push_resumes(tmp_path):
    """The settings compared on resuming are compared as meta.json holds them: a push's (min, max) range, a tuple
    in the configuration and a list in the file, is the same setting."""
    from evaluation.run import FORMAT, _prepare

    meta = {"format": FORMAT, "models_dir": "m", "model_files": {"dynamics.pt": "ab"}, "problems": "p",
            "problems_sha256": "cd", "n_problems": 2, "methods": ["bilevel_loop"], "versions": {"python": "3.11"},
            "started": "now", "runs": [],
            "config": {"fidelity": "fast", "faults": {"noise_m": 0.005, "push_m": (0.03, 0.05)}}}
    _prepare(tmp_path, dict(meta))
    _prepare(tmp_path, dict(meta))  # resumed: the same settings
    other = {**meta, "config": {"fidelity": "fast", "faults": {"noise_m": 0.005, "push_m": (0.03, 0.06)}}}
    with pytest.raises(UserError, match=r"config\.faults\.push_m: \[0\.03, 0\.05\] there, \[0\.03, 0\.06\] now"):
        _prepare(tmp_path, other)


def test_a_results_directory_of_another_configuration_is_refused(tmp_path):
    """The whole resolved configuration is recorded: a directory made with another one says so, naming the key."""
    from evaluation.run import FORMAT, _prepare

    meta = {"format": FORMAT, "models_dir": "m", "model_files": {"dynamics.pt": "ab"}, "problems": "p",
            "problems_sha256": "cd", "n_problems": 2, "methods": ["cfs"], "versions": {"python": "3.11"},
            "started": "now", "runs": [], "config": EvalConfig().defining()}
    _prepare(tmp_path, dict(meta))
    stalled = EvalConfig(planner=PlanConfig(search=SearchConfig(stall=300))).defining()
    with pytest.raises(UserError, match=r"rows made with another configuration \(config\.search\.stall: null there, "
                                        r"300 now\)"):
        _prepare(tmp_path, {**meta, "config": stalled})


def test_the_warm_up_builds_the_symbolic_tasks_of_level1s_sub_scenes():
    """From focus_from blocks on Level 1 plans in sub-scenes of up to 4 objects: the symbolic planner's task of each
    size (a one-off build of 0.3-1 s) is built before anything is timed, as the whole scene's is."""
    from types import SimpleNamespace

    from evaluation.run import Evaluator

    built: list[int] = []
    planner = SimpleNamespace(task=built.append)
    fake = SimpleNamespace(symbolic=SimpleNamespace(symbols=lambda X: None), domain=object(), dynamics=None,
                           symbolic_planner=lambda backend: planner)
    for n, sizes in ((6, [1, 2, 3, 4, 6]), (3, [3])):
        built.clear()
        X = np.zeros((n, 5))
        Evaluator({}, EvalConfig()).warm_up(fake, Problem(X, X))
        assert built == sizes
