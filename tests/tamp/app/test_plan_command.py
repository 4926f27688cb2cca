"""Problem files and `tamp plan`: clear errors naming the field; planning, refinement and execution."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from tamp.app.cli import main
from tamp.app.problem import Problem, load_problem, pick_problem, problem_from_dict, save_problem
from tests.browser import CHROMIUM, Browser

X = [[0.6, 0.15, 0.025, 1, 0], [0.7, -0.1, 0.025, 0, 1]]
GOAL = [[0.7, -0.1, 0.075, 1, 0], [0.7, -0.1, 0.025, 0, 1]]


def test_problem_round_trip(tmp_path):
    p = Problem(np.array(X, float), np.array(GOAL, float), k=2, seed=5)
    save_problem(tmp_path / "p.json", p)
    q = load_problem(tmp_path / "p.json")
    assert np.array_equal(q.X_init, p.X_init) and np.array_equal(q.X_goal, p.X_goal)
    assert (q.k, q.seed, q.n) == (2, 5, 2)
    assert problem_from_dict({"X_init": X, "X_goal": GOAL}).seed == 0


@pytest.mark.parametrize("data, field", [
    ({"X_goal": GOAL}, "'X_init'"),
    ({"X_init": X}, "'X_goal'"),
    ({"X_init": X, "X_goal": [[0.7, -0.1, 0.075, 1, 0]]}, "'X_goal' has 1 objects"),
    ({"X_init": X, "X_goal": [[0.7, -0.1, 0.075, 1], [0.7, -0.1, 0.025, 0, 1]]},
     "X_goal[0]: expected at least 5 items, got 4"),
    ({"X_init": [[0.6, 0.15, 0.025, 1, 1], X[1]], "X_goal": GOAL}, "'X_init' row 0: the type must be one-hot"),
    ({"X_init": X, "X_goal": [GOAL[0][:3] + [0, 1], GOAL[1]]}, "'X_goal' row 0 has another block type"),
    ({"X_init": X, "X_goal": GOAL, "k": 0}, "k: expected a value >= 1, got 0"),
    ({"X_init": X, "X_goal": GOAL, "seed": "7"}, "seed: expected an integer, got \"7\""),
    ({"X_init": X, "X_goal": GOAL, "goal": GOAL}, "unknown field 'goal'"),
    ({"X_init": "abc", "X_goal": GOAL}, "X_init: expected a list, got \"abc\""),
])
def test_malformed_problem_names_the_field(tmp_path, data, field):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(ValueError, match=str(path)) as info:
        load_problem(path)
    assert field in str(info.value)


def test_cli_reports_a_malformed_problem_in_one_line(tmp_path, capsys):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"X_init": X}))
    assert main(["plan", "--problem", str(path), "--models", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "missing field 'X_goal'" in err and "Traceback" not in err
    path.write_text("{not json")
    assert main(["plan", "--problem", str(path), "--models", str(tmp_path)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


def test_a_problem_is_picked_from_a_problem_set_by_name(tmp_path, capsys):
    named = [dict(name=f"n2-k1-00{i}", X_init=X, X_goal=GOAL, k=1, seed=i) for i in range(3)]
    path = tmp_path / "set.jsonl"
    path.write_text("".join(json.dumps(p) + "\n" for p in named))
    assert pick_problem(path, "n2-k1-002").seed == 2
    with pytest.raises(ValueError, match=r"problem set of 3 problems: pick one with --name \(e.g. n2-k1-000"):
        pick_problem(path)
    with pytest.raises(ValueError, match="no problem named 'n9'"):
        pick_problem(path, "n9")
    one = tmp_path / "one.jsonl"
    one.write_text(json.dumps(named[1]) + "\n")
    assert pick_problem(one).seed == 1  # a set of one needs no name
    one.write_text(json.dumps(named[1]) + "\n" + json.dumps(named[1]) + "\n")
    with pytest.raises(ValueError, match="line 2: duplicate problem name 'n2-k1-001'"):
        pick_problem(one)  # a faulty set says what is wrong with it, not that it is not one problem
    single = tmp_path / "p.json"
    save_problem(single, Problem(np.array(X, float), np.array(GOAL, float), k=2, seed=5))
    assert pick_problem(single).seed == 5
    # the command says so in one line; a malformed single file still names its own fault
    assert main(["plan", "--problem", str(path), "--models", str(tmp_path)]) == 2
    assert "pick one with --name" in capsys.readouterr().err
    assert main(["plan", "--problem", str(path), "--name", "n9", "--models", str(tmp_path)]) == 2
    assert "no problem named 'n9' among its 3" in capsys.readouterr().err
    single.write_text("{not json")
    assert main(["plan", "--problem", str(single), "--models", str(tmp_path)]) == 2
    assert "not valid JSON" in capsys.readouterr().err


@pytest.fixture(scope="module")
def models_dir(tmp_path_factory):
    """Untrained (seeded) networks and a domain learned from their own symbols on toy transitions."""
    torch = pytest.importorskip("torch")
    from learned import EffectModel, ModelConfig, save_checkpoint
    from learned.synthetic import generate
    from symbolic import build_domain

    out = tmp_path_factory.mktemp("models")
    torch.manual_seed(0)
    save_checkpoint(out / "dynamics.pt", EffectModel(ModelConfig(d_z=2, heads=1)))
    sym = EffectModel(ModelConfig(d_z=2, heads=1, activation="gumbel_sigmoid")).eval()
    save_checkpoint(out / "symbolic.pt", sym)
    data = generate(400, seed=0, n_choices=(2,))
    u0, r0 = sym.symbols_batch(data.X, data.mask)
    u1, r1 = sym.symbols_batch(data.X_next, data.mask)
    build_domain(u0, r0, data.action, u1, r1, data.n, out / "domain", holdout=0.0)
    return out


def _problem_reachable_by_the_model(models_dir, tmp_path):
    from tamp.planning.models import load_models
    from tamp.planning.verify import rollout

    model = load_models(models_dir).dynamics
    X_init = np.array([[0.6, 0.15, 0.025, 1, 0], [0.7, -0.1, 0.025, 1, 0]])
    # (0, 0, 1, 1): the untrained network's prediction is a scene that passes tamp.planning.validate (for
    # (0, 0, 1, 0) it puts both blocks in one place, which `tamp plan` refuses)
    X_goal = rollout(model, X_init, [(0, 0, 1, 1)])[-1]
    path = tmp_path / "p.json"
    save_problem(path, Problem(X_init, X_goal, k=1))
    return path


def test_the_object_limit_is_the_one_the_models_were_trained_for(models_dir, tmp_path, capsys):
    """Models trained on scenes of up to 4 blocks refuse a fifth in one line naming 4; the bundled
    models take the world's MAX_OBJECTS, 8 (PROVENANCE.md: trained on 2-4 and 2-6, checked at 7 and 8), and a
    ninth block is refused in one line naming the world's limit."""
    from tamp.planning.models import load_models, pretrained_dir
    from tamp.planning.validate import MAX_OBJECTS

    five = [[0.5 + 0.08 * i, 0.2, 0.025, 1, 0] for i in range(5)]
    path = tmp_path / "five.json"
    path.write_text(json.dumps({"X_init": five, "X_goal": five}))
    assert main(["plan", "--problem", str(path), "--models", str(models_dir), "--execute", "none"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "5 objects, but the models were trained for at most 4" in err
    bundled = load_models(pretrained_dir())
    assert bundled.n_max == MAX_OBJECTS == 8
    bundled.require_objects(8, "an eight-block problem")
    nine = [[0.40 + 0.05 * (i % 5), -0.2 + 0.1 * (i // 5), 0.025, 1, 0] for i in range(9)]
    path.write_text(json.dumps({"X_init": nine, "X_goal": nine}))
    assert main(["plan", "--problem", str(path), "--execute", "none"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "has 9 blocks, but the world holds 1..8" in err


@pytest.mark.sim
def test_cli_plans_without_execution(models_dir, tmp_path, capsys):
    path = _problem_reachable_by_the_model(models_dir, tmp_path)
    for method in ("bilevel", "cfs"):
        assert main(["plan", "--problem", str(path), "--models", str(models_dir), "--method", method,
                     "--execute", "none"]) == 0
        out = capsys.readouterr().out
        assert f"{method}: plan of" in out and "timings:" in out and "predicted final error" in out
    # without --models: the bundled (pretrained) set, as `tamp demo`
    assert main(["plan", "--problem", str(path), "--execute", "none"]) == 0
    assert "bilevel: plan of" in capsys.readouterr().out
    (models_dir / "missing").mkdir()
    assert main(["plan", "--problem", str(path), "--models", str(models_dir / "missing")]) == 2
    assert "missing model file(s)" in capsys.readouterr().err


@pytest.mark.sim
def test_cli_plans_with_fast_downward_and_algorithm_1(models_dir, tmp_path, capsys):
    path = _problem_reachable_by_the_model(models_dir, tmp_path)
    lengths = {}
    for backend in ("python", "fd"):
        (tmp_path / f"{backend}.toml").write_text(f'[level1]\nbackend = "{backend}"\n')
        assert main(["plan", "--problem", str(path), "--models", str(models_dir), "--method", "deterministic",
                     "--config", str(tmp_path / f"{backend}.toml"), "--execute", "none"]) == 0
        out = capsys.readouterr().out
        assert f"symbolic planner {backend}" in out
        lengths[backend] = out.split("deterministic: plan of ")[1].split(" ")[0]
    assert lengths["python"] == lengths["fd"]  # both search for a shortest plan
    assert main(["plan", "--problem", str(path), "--models", str(models_dir), "--method", "bilevel_alg1",
                 "--execute", "none"]) == 0
    out = capsys.readouterr().out
    assert "bilevel_alg1: plan of" in out


@pytest.mark.sim
def test_the_shown_configuration_plans_as_its_preset(models_dir, tmp_path, capsys):
    """`tamp config show --preset P > c.toml`, then `tamp plan --config c.toml` gives the preset's plan; the paper
    preset with `bilevel` is `bilevel_alg1`."""
    path = _problem_reachable_by_the_model(models_dir, tmp_path)

    def planned(*flags: str) -> list[str]:
        assert main(["plan", "--problem", str(path), "--models", str(models_dir), "--execute", "none", *flags]) == 0
        return [line.replace("bilevel_alg1", "bilevel") for line in capsys.readouterr().out.splitlines()
                if "timings:" not in line]

    for preset in ("default", "paper"):
        assert main(["config", "show", "--preset", preset]) == 0
        (tmp_path / "c.toml").write_text(capsys.readouterr().out)
        assert planned("--config", str(tmp_path / "c.toml")) == planned("--preset", preset)
    assert planned("--preset", "paper") == planned("--method", "bilevel_alg1")
    assert planned() == planned("--preset", "default") != planned("--preset", "paper")


@pytest.mark.sim
def test_cli_executes_and_writes_the_replay_whose_panel_follows_the_step(models_dir, tmp_path, capsys):
    """`tamp plan --replay`; in headless Chromium, the replay's panel shows the step named in the page's #step=N."""
    replay, steps = _plan_with_replay(models_dir, tmp_path, capsys)
    if CHROMIUM is None:
        pytest.skip("the replay's panel in a browser needs Chromium (Debian: apt-get install chromium)")
    # the panel's entry once the page has set it from the fragment (or after 10 s)
    panel = ("new Promise(done => { const t0 = Date.now(); (function poll() {"
             " const p = document.getElementById('tamp-steps');"
             " if ((p && p.dataset.entry === '%d') || Date.now() - t0 > 10000)"
             " done(p && [p.dataset.entry, p.innerText]);"
             " else setTimeout(poll, 20); })(); })")
    with Browser() as browser:
        for step in range(steps + 1):
            browser.open(replay, f"step={step}")
            shown = browser.eval(panel % step)
            assert shown is not None and int(shown[0]) == step
            assert (f"step {step} of {steps}" if step else "before step 1") in shown[1]
        assert not browser.errors()


def _plan_with_replay(models_dir, tmp_path, capsys):
    """`tamp plan --replay`: checks the output, the replay and the per-step view; (replay, steps)."""
    path = _problem_reachable_by_the_model(models_dir, tmp_path)
    replay = tmp_path / "out.html"
    code = main(["plan", "--problem", str(path), "--models", str(models_dir), "--method", "cfs",
                 "--execute", "fast", "--replay", str(replay)])
    out = capsys.readouterr().out
    assert "refinement:" in out and "execution (fast): final error" in out
    assert code == (0 if "-> success" in out else 1)
    assert replay.is_file() and replay.stat().st_size > 10_000
    # the per-step view: printed, written beside the replay, and in the replay's panel
    document = json.loads((tmp_path / "out.steps.json").read_text())
    steps, recorded = document["steps"], document["configuration"]
    assert recorded["format"] == "tamp-config/1" and recorded["search"]["max_expansions"] == 1500  # what planned it
    executed = int(re.search(r"refinement: (?:ok, )?(\d+) action", out).group(1)) if "refinement: ok" in out else None
    assert steps and (executed is None or len(steps) == executed)
    for k, step in enumerate(steps):
        assert f"step {k + 1}: pick" in out
        motion = step["motion"]
        assert set(motion["ik_solver"].values()) <= {"closed form", "numerical"}
        assert all(m["planner"] in ("direct", "rrtconnect", "") for m in motion["motions"].values())
        assert step["symbols"]["before"]["unary"] and "match" in step["symbols"]
        assert step["t_start"] is not None and step["t_start"] >= 0
    page = replay.read_text()
    assert 'id="tamp-steps"' in page and f"step {len(steps)} of {len(steps)}" in page
    return replay, len(steps)
