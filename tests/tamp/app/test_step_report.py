"""The per-step view of a plan: each step's symbols, operator and what execution made of
them; the bits' names; the refinability table and the abstraction fidelity recomputed from rows."""
import json

import numpy as np
import pytest

from evaluation import refinability
from learned.interpret import BitNames, interpret_symbols
from tamp.app.step_report import format_steps, step_panel_html, step_records
from tamp.planning.models import Models, load_bit_names
from tamp.planning.steps import symbolic_steps
from tests.planning_stubs import StubModel, two_block_domain, world_step

# the two blocks of `two_block_domain` on the table, and block 0 on block 1
X0 = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
ON = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
UNDER = np.array([[0.7, 0.1, 0.025, 1, 0], [0.7, 0.1, 0.075, 1, 0]])  # block 1 ended on block 0
PUT_ON = (0, 0, 1, 1)  # the domain's operator: 'on' with p = 0.9, nothing with p = 0.1


@pytest.fixture(scope="module")
def models():
    stub = StubModel()
    return Models(stub, stub, two_block_domain())


def names_of(models) -> BitNames:
    """The stub's bits read on scenes with and without a stack: u0 ~ on the table, r0 ~ i on j."""
    return BitNames.from_report(interpret_symbols(models.symbolic.symbols, [X0, ON, UNDER, X0]))


def test_a_step_that_produces_its_expected_effect_matches(models):
    (step,) = symbolic_steps(models, [X0, ON], [PUT_ON])
    assert step.operator is not None and step.binding == (0, 1)
    assert step.effect == 0 and step.probability == pytest.approx(0.9) and step.n_effects == 2
    assert step.match is True and step.mismatches() == [] and step.observed_effect == 0
    predicted = world_step(X0, PUT_ON)  # the stub Dynamics Model predicts the toy world's outcome
    assert step.dynamics_error_m == pytest.approx(np.linalg.norm(predicted[:, :3] - ON[:, :3], axis=1).mean())


def test_a_step_that_changes_a_different_bit_than_predicted_is_a_mismatch(models):
    names = names_of(models)
    (step,) = symbolic_steps(models, [X0, UNDER], [PUT_ON])
    assert step.match is False and step.observed_effect is None  # no learned effect gives these symbols
    # expected: block 0 leaves the table and lies on block 1; observed: block 1 lies on block 0
    assert sorted(step.mismatches(), key=str) == sorted(
        [("r", 0, 0, 1, 1, 0), ("r", 0, 1, 0, 0, 1), ("u", 0, 0, None, 0, 1), ("u", 0, 1, None, 1, 0)], key=str)
    record = step.to_dict(names)
    assert record["match"] is False
    assert {m["bit"]: (m["expected"], m["observed"]) for m in record["mismatches"]} == {
        "u0(o0)": (0, 1), "u0(o1)": (1, 0), "r0(o0,o1)": (1, 0), "r0(o1,o0)": (0, 1)}
    meaning = {m["bit"]: m["meaning_observed"] for m in record["mismatches"]}
    assert meaning["r0(o1,o0)"] == "o1 on o0" and meaning["u0(o1)"] == "o1 elevated"
    text = "\n".join(format_steps(step_records([step], [], names)))
    assert "MISMATCH in 4 bit(s)" in text and "r0(o1,o0)=1 (expected 0) ~ o1 on o0" in text


def test_an_outcome_the_operator_allows_but_did_not_expect_is_a_mismatch_of_an_allowed_effect(models):
    (step,) = symbolic_steps(models, [X0, X0], [PUT_ON])  # nothing happened: the operator's effect 2
    assert step.match is False and step.observed_effect == 1
    assert "(the operator's effect 2, not the expected one)" in "\n".join(format_steps(step_records([step], [],
                                                                                                     BitNames.none())))


def test_a_step_that_did_not_run_is_not_judged_and_the_plan_states_choose_the_effect(models):
    from symbolic.atoms import pack_state

    # the plan counted on 'nothing' (effect 2): expected is the state before
    plan = (pack_state(*models.symbolic.symbols(X0)), pack_state(*models.symbolic.symbols(X0)))
    (step,) = symbolic_steps(models, [X0], [PUT_ON], plan)
    assert step.on_plan is True and step.effect == 1 and step.probability == pytest.approx(0.1)
    assert step.observed is None and step.match is None and step.dynamics_error_m is None
    assert "  observed: not executed" in format_steps(step_records([step], [], BitNames.none()))
    # an action no operator grounds in these symbols (the domain has none with these offsets)
    (other,) = symbolic_steps(models, [X0, X0], [(0, 1, 1, -1)])
    assert other.operator is None and other.match is None
    assert "none of the learned operators" in "\n".join(format_steps(step_records([other], [], BitNames.none())))


@pytest.mark.parametrize("method", ["deterministic", "probabilistic"])
def test_the_symbolic_planners_steps_are_judged_against_the_effects_their_plan_counted_on(models, method):
    """The symbolic planners take their top plan unverified; its symbolic states still reach the per-step
    view, which then expects the effect the plan counted on, not the action's most probable one."""
    from symbolic.atoms import pack_state
    from tamp.planning.planners import plan_deterministic, plan_probabilistic

    plan = {"deterministic": plan_deterministic, "probabilistic": plan_probabilistic}[method]
    result = plan(models, X0, ON)
    assert result.level == 1 and [tuple(a) for a in result.plan] == [PUT_ON]
    assert result.plan_states == (pack_state(*models.symbolic.symbols(X0)), pack_state(*models.symbolic.symbols(ON)))
    result.candidates[0].verified = False  # taken whether or not the Dynamics Model verified it
    assert result.plan_states is not None
    (step,) = symbolic_steps(models, [X0, ON], result.plan, result.plan_states)
    assert step.on_plan is True and step.match is True


def test_a_plan_of_a_sub_scene_is_read_in_that_sub_scene_and_named_by_the_whole_scenes_objects(models):
    """A Level-1 plan made in the sub-scene of blocks 2 and 3 of a four-block scene (`PlanResult.plan_scene`):
    its steps read the symbols of those two blocks only, as the plan's symbolic states do, so the plan's
    effect is recognised; the records name the blocks o2 and o3."""
    from symbolic.atoms import pack_state

    far = np.array([[0.45, -0.3, 0.025, 1, 0], [0.45, -0.18, 0.025, 1, 0]])
    X = np.vstack([far, X0])  # blocks 2 and 3 are `two_block_domain`'s pair
    after = np.vstack([far, ON])
    plan = (pack_state(*models.symbolic.symbols(X0)), pack_state(*models.symbolic.symbols(ON)))
    (step,) = symbolic_steps(models, [X, after], [(2, 0, 3, 1)], plan, objects=(2, 3))
    assert step.objects == (2, 3) and step.before.n == 2 and step.on_plan is True and step.match is True
    assert step.action == (2, 0, 3, 1) and step.binding == (0, 1)
    record = step.to_dict(names_of(models))
    assert record["objects"] == ["o2", "o3"] and record["binding"] == ["o2", "o3"]
    assert {c["bit"] for c in record["expected_changes"]} == {"u0(o2)", "r0(o2,o3)"}
    assert "o2 on o3" in record["expected"]["facts"]
    text = "\n".join(format_steps(step_records([step], [], names_of(models))))
    assert "symbols before (of o2, o3: the plan's sub-scene)" in text and "the plan's symbols" in text
    # the same plan states without the sub-scene describe two objects of a four-object scene: not on plan
    (whole,) = symbolic_steps(models, [X, after], [(2, 0, 3, 1)])
    assert whole.objects is None and whole.before.n == 4 and whole.to_dict(names_of(models))["objects"] is None
    # an action outside the sub-scene: read in the whole scene, without the plan's states
    (beyond,) = symbolic_steps(models, [X, X], [(0, 0, 1, 1)], plan, objects=(2, 3))
    assert beyond.objects is None and beyond.on_plan is None


def test_bit_names_come_from_the_symbols_table(tmp_path):
    """`tamp symbols --json` is what names the bits: a bit with a strong agreement by its fact, the
    others by their raw name; a models directory without the file gives raw names, a bad file is an error."""
    rng = np.random.default_rng(0)
    stub = StubModel()

    def symbols(X):  # the stub's two bits and a relation r1 that means nothing
        u, r = stub.symbols(X)
        return u, np.concatenate([r, rng.integers(0, 2, r.shape).astype(np.uint8)])

    scenes = [X0, ON, UNDER] * 20
    report = interpret_symbols(symbols, scenes)
    (tmp_path / "symbols.json").write_text(json.dumps([b.to_dict() for b in report]))
    names = load_bit_names(tmp_path)
    strong = {b.name for b in report if abs(b.phi[b.best]) >= 0.7}
    assert set(names.facts) == strong and {"u0", "r0"} <= strong and "r1" not in strong
    assert names.facts["u0"] == (report[0].best, report[0].negated[report[0].best])
    assert names.describe("u", 0, 0, "o2") == "u0(o2)=0 ~ o2 elevated"
    assert names.describe("u", 0, 1, "o2") == "u0(o2)=1 ~ o2 not elevated"
    assert names.describe("r", 0, 1, "o1", "o0") == "r0(o1,o0)=1 ~ o1 on o0"
    assert names.describe("r", 1, 1, "o1", "o0") == "r1(o1,o0)=1"  # no strong meaning: the raw bit
    assert load_bit_names(tmp_path / "nowhere").facts == {}
    (tmp_path / "symbols.json").write_text('{"not": "a table"}')
    with pytest.raises(ValueError, match=r"symbols.json \(a symbols table of `tamp symbols --json`\): expected a list"):
        load_bit_names(tmp_path)


def _step(op, kinematic="ok", refined=True, match=True, allowed=True, error=0.01, on_plan=None):
    return {"operator": op, "probability": 0.5, "on_plan": on_plan, "kinematic": kinematic, "refined": refined,
            "match": match if refined else None, "mismatched_bits": (0 if match else 2) if refined else None,
            "allowed": allowed if refined else None, "error_m": error if refined else None}


def test_the_refinability_table_and_the_fidelity_are_recomputed_from_rows(tmp_path):
    rows = [
        {"problem": "p1", "method": "cfs", "success": True, "plan": [[0, 0, 1, 0], [1, 0, 0, 0]],
         "steps": [_step("a"), _step("b", match=False, allowed=True, error=0.03)]},
        {"problem": "p2", "method": "cfs", "success": False, "plan": [[0, 0, 1, 1]],
         "steps": [_step("a", kinematic="collision", refined=False)]},
        {"problem": "p1", "method": "bilevel", "success": True, "plan": [[0, 0, 1, 0], [1, 0, 0, 0], [1, 1, 0, 1]],
         "steps": [_step("a", on_plan=True, error=0.004), _step("b", match=False, allowed=False, on_plan=True),
                   _step(None, match=None)]},
        {"problem": "p3", "method": "bilevel", "success": True, "plan": [], "steps": []},
        {"problem": "p4", "method": "bilevel", "success": False, "plan": None, "steps": None},
    ]
    table = {t["operator"]: t for t in refinability.operator_table(rows)}
    assert set(table) == {"a", "b"}
    a, b = table["a"], table["b"]
    assert (a["uses"], a["executed"], a["kinematic_pct"], a["refined_pct"], a["as_expected_pct"]) == \
        (3, 2, pytest.approx(200 / 3), pytest.approx(200 / 3), 100.0)
    assert (b["uses"], b["executed"], b["as_expected_pct"], b["allowed_pct"]) == (2, 2, 0.0, 50.0)
    assert b["error_cm"] == pytest.approx(2.0) and b["methods"] == "bilevel,cfs"
    assert b["example"] == {"problem": "p1", "method": "cfs", "step": 2, "action": [1, 0, 0, 0], "mismatched_bits": 2}
    assert [t["operator"] for t in refinability.least_faithful(list(table.values()), min_executed=2)] == ["b", "a"]
    fidelity = {f["method"]: f for f in refinability.fidelity_by_method(rows)}
    cfs, bilevel = fidelity["cfs"], fidelity["bilevel"]
    assert (cfs["problems"], cfs["steps"], cfs["judged"], cfs["as_expected_pct"]) == (2, 3, 2, 50.0)
    assert (cfs["broken_problems"], cfs["broken_success_pct"], cfs["faithful_problems"]) == (1, 100.0, 0)
    assert (bilevel["problems"], bilevel["judged"], bilevel["no_operator"], bilevel["on_plan_as_expected_pct"]) == \
        (2, 2, 1, 50.0)
    # steps the Dynamics Model predicted within 1 cm: bilevel's first one only (errors of 1 and 3 cm are not)
    assert (bilevel["accurate"], bilevel["accurate_as_expected_pct"], bilevel["accurate_allowed_pct"]) == \
        (1, 100.0, 100.0)
    assert (cfs["accurate"], cfs["accurate_as_expected_pct"]) == (0, None)
    assert "No operator was executed 3 times or more." in refinability.markdown(rows)
    paths = refinability.write(rows, tmp_path, min_executed=2)
    csv_lines = (tmp_path / "refinability.csv").read_text().splitlines()
    assert csv_lines[0].split(",")[:2] == ["operator", "uses"] and len(csv_lines) == 3
    md = (tmp_path / "refinability.md").read_text()
    assert "| b | 2 | 0.0 | 50.0 | p1, cfs, step 2, [1, 0, 0, 0], 2 |" in md
    assert (tmp_path / "figures" / "refinability.png") in paths


def test_tamp_refinability_studies_only_the_methods_asked_for(tmp_path, monkeypatch, capsys):
    """The rows of a `tamp evaluate` directory hold every method evaluated; `--methods` picks the ones studied."""
    import evaluation.run
    from tamp.app.cli import main

    rows = [{"problem": "p1", "method": m, "outcome": "success", "success": True, "plan": [[0, 0, 1, 0]],
             "steps": [_step(op)]} for m, op in (("cfs", "a"), ("bilevel", "b"))]
    (tmp_path / "rows.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    monkeypatch.setattr(evaluation.run, "evaluate", lambda *args, **kwargs: tmp_path / "rows.jsonl")
    assert main(["refinability", "--models", "m", "--problems", "p", "--out", str(tmp_path), "--methods", "cfs"]) == 0
    out = capsys.readouterr().out
    assert "cfs: 1 executed steps" in out and "bilevel" not in out
    table = (tmp_path / "refinability.csv").read_text().splitlines()
    assert [line.split(",")[0] for line in table[1:]] == ["a"]


def test_closed_loop_steps_name_their_round_and_how_it_got_its_plan(models):
    from tamp.app.runner import ClosedLoopRun
    from tamp.app.step_report import loop_steps
    from tamp.planning.closed_loop import ClosedLoopResult
    from tamp.planning.results import PlanResult
    from tamp.planning.vocabulary import PickPlace

    a, b, c = PickPlace(0, 0, 1, 1), PickPlace(1, 0, 0, 0), PickPlace(0, 1, 1, 0)
    rounds = [PlanResult("bilevel", [a, b, c], level=2), PlanResult("bilevel", [b, c], level=2, kept_by="on course"),
              PlanResult("bilevel", [c], level=2)]
    run = ClosedLoopRun(ClosedLoopResult(rounds, [a, b, c], [X0, ON, ON, ON], ON, 0.05))
    steps = list(loop_steps(run))
    assert [(s.index, s.round, s.plan) for s in steps] == [(0, 0, "planned"), (1, 1, "kept on course"),
                                                           (2, 2, "planned")]
    (step,) = symbolic_steps(models, steps[1].states, [steps[1].action])
    records = step_records([step], [], BitNames.none())
    records[0].update(round=steps[1].round, plan=steps[1].plan)
    assert "step 1: pick 1 at +0, place on 0 at +0 (round 1: kept on course)" in format_steps(records)[0]
    assert "(round 1: kept on course)" in step_panel_html(records[0], 3)  # the replay's panel says it too


class _HeightBits:
    """Symbols of the test below: u0 = on the table, no relation."""

    def symbols(self, X):
        X = np.asarray(X, dtype=float)
        return (X[:, 2] < 0.04).astype(np.uint8)[:, None], np.zeros((1, len(X), len(X)), np.uint8)


def test_a_step_is_judged_against_every_operator_of_its_action_in_a_domain_of_involved_objects():
    """A domain learned on the objects each transition involved has, for one action, an operator of the
    action's two objects (the picked block leaves the table: 7 of 10 transitions) and one with a bystander
    that also left the table (3 of 10). The step's expected outcome is the heavier one, whichever operator
    has more parameters, and an outcome of the other operator is one the action allows."""
    from symbolic.dataset import make_dataset, restrict_to_involved
    from symbolic.operators import learn_operators

    bits = _HeightBits()
    X0 = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0], [0.5, -0.2, 0.025, 1, 0]])
    lifted, both = X0.copy(), X0.copy()
    lifted[0, 2] = both[0, 2] = both[2, 2] = 0.075
    action = (0, 0, 1, 0)
    u0, r0 = bits.symbols(X0)
    after = [bits.symbols(lifted)] * 7 + [bits.symbols(both)] * 3
    data = make_dataset(np.repeat(u0[None], 10, 0), np.repeat(r0[None], 10, 0), np.array([action] * 10),
                        np.stack([u for u, _ in after]), np.stack([r for _, r in after]), np.full(10, 3))
    domain = learn_operators(restrict_to_involved(data))
    assert sorted(op.arity for op in domain.operators) == [2, 3]
    models = Models(StubModel(), bits, domain)
    (alone,) = symbolic_steps(models, [X0, lifted], [action])
    assert alone.binding == (0, 1) and alone.match is True and alone.observed_effect == 0
    (with_bystander,) = symbolic_steps(models, [X0, both], [action])
    assert with_bystander.binding == (0, 1) and with_bystander.match is False
    assert with_bystander.observed_operator is not None and with_bystander.observed_operator != with_bystander.operator
    record = step_records([with_bystander], [], BitNames.none())
    assert "another operator of the action" in "\n".join(format_steps(record))
    (neither,) = symbolic_steps(models, [X0, X0], [action])  # nothing left the table: no operator learned that
    assert neither.match is False and neither.observed_effect is None and neither.observed_operator is None
