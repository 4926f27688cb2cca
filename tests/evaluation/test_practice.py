"""`tamp practice`: rounds of the robot's own problems, planned and executed, learned from; resumable."""
import json

import numpy as np
import pytest

from evaluation.practice import PracticeConfig, practise, write_transitions
from learned import load_transitions
from learned.ensemble import EffectEnsemble, load_dynamics
from learned.synthetic import write_synthetic_dataset
from tamp.app.cli import main
from tamp.errors import UserError
from tamp.planning.models import pretrained_dir

pytestmark = [pytest.mark.sim, pytest.mark.slow]
TINY = PracticeConfig(rounds=1, per_cell=1, objects=(2,), actions=(1,), members=2, epochs=2, patience=2,
                      explore=4, workers=1)


@pytest.fixture(scope="module")
def practised(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("practice")
    data = write_synthetic_dataset(tmp / "random", 300, seed=0)
    out = tmp / "out"
    curve = practise(pretrained_dir(), [data], out, TINY, progress=False)
    return tmp, data, out, curve


def test_each_round_plans_executes_records_and_learns(practised):
    _, _, out, curve = practised
    assert [p["round"] for p in curve] == [0, 1]
    for p in curve:  # two protocols x 1 problem
        assert p["problems"] == 2 and p["seed"] == TINY.seed + p["round"]
        assert p["steps"]["steps"] == p["transitions"] > 0
    # the transitions are the executed steps of the rows, in the dataset format
    rows = [json.loads(line) for line in (out / "round-0" / "eval" / "rows.jsonl").read_text().splitlines()]
    data = load_transitions(out / "round-0" / "data")
    assert len(data) == sum(r["executed_actions"] for r in rows) == curve[0]["transitions"]
    first = next(r for r in rows if r["transitions"])
    t = first["transitions"][0]
    assert np.allclose(data.X[0, :len(t["X"])], t["X"], atol=1e-5) and list(data.action[0]) == t["action"]
    assert [p["class"] for p in first["predictions"]] and first["predictions"][0]["miss_m"] >= 0
    # beside the plans: from round 0's visited states, other goal-oriented actions, in the collection's format
    beside = load_transitions(out / "round-0" / "explore")
    assert len(beside) == curve[0]["explored"] > curve[0]["transitions"] and curve[1]["explored"] == 0
    assert beside.meta["collection"]["per_state"] == TINY.explore
    # round 1 plans with an ensemble trained on the random data and round 0's practice
    model = load_dynamics(out / "round-1" / "models" / "dynamics.pt")
    assert isinstance(model, EffectEnsemble) and len(model) == 2
    assert (out / "round-1" / "models" / "domain").is_dir() and (out / "models").resolve() == \
        (out / "round-1" / "models").resolve()
    assert "| 1 | 2 |" in (out / "curve.md").read_text()


def test_a_rerun_resumes_and_other_settings_are_refused(practised):
    _, data, out, curve = practised
    stamp = (out / "round-1" / "models" / "dynamics.pt").stat().st_mtime_ns
    again = practise(pretrained_dir(), [data], out, TINY, progress=False)
    assert [p["transitions"] for p in again] == [p["transitions"] for p in curve]
    assert (out / "round-1" / "models" / "dynamics.pt").stat().st_mtime_ns == stamp  # nothing trained again
    for changed in ({"extra_share": 0.5}, {"effect_loss": "distance"}):
        with pytest.raises(UserError, match="other config"):
            practise(pretrained_dir(), [data], out, PracticeConfig(**{**TINY.__dict__, **changed}), progress=False)


def test_recorded_steps_name_the_world_that_executed_them(practised, tmp_path):
    _, _, out, curve = practised
    rows = out / "round-0" / "eval" / "rows.jsonl"
    assert load_transitions(out / "round-0" / "data").meta["world_config"]["fidelity"] == "fast"
    assert write_transitions(rows, tmp_path / "full", 7, "full") == curve[0]["transitions"]
    meta = load_transitions(tmp_path / "full").meta
    assert meta["world_config"]["fidelity"] == "full" and meta["world_config"]["simplify_paths"] is True


def test_the_effect_loss_is_a_setting_only_when_not_the_papers():
    """Runs begun before the effect loss was a setting resume: the default is left out of the state."""
    assert "effect_loss" not in TINY.defining()
    assert PracticeConfig(effect_loss="distance").defining()["effect_loss"] == "distance"
    with pytest.raises(UserError, match="--effect-loss"):
        PracticeConfig(effect_loss="huber")


def test_practice_flags_are_checked(tmp_path, capsys):
    assert main(["practice", "--data", str(tmp_path), "--out", str(tmp_path / "o"), "--extra-share", "0"]) == 2
    assert "--extra-share" in capsys.readouterr().err
    assert main(["practice", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o").exists()


def test_members_learn_from_the_moving_steps_alone_when_asked():
    """`--only-moved` reaches each member's training, and is a setting only when on (older runs resume)."""
    from evaluation.practice import member_training

    assert "only_moved" not in TINY.defining() and member_training(TINY).only_moved is False
    moved = PracticeConfig(only_moved=True)
    assert moved.defining()["only_moved"] is True and member_training(moved).only_moved is True
