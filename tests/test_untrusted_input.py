"""Files from outside are untrusted: each class of bad input a careless or hostile user can give is
refused by the command with exit status 2, one line naming the file and where in it, and nothing
written. Every file here is made by the test. (The readers' fuzz tests: tests/test_fuzz_readers.py.)"""
from __future__ import annotations

import gzip
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from tamp.app.args import BUNDLED_MODELS
from tamp.app.cli import main
from tamp.planning.models import pretrained_dir

INIT = [[0.60, 0.15, 0.025, 1, 0], [0.70, -0.10, 0.025, 0, 1]]
GOAL = [[0.70, -0.10, 0.075, 1, 0], [0.70, -0.10, 0.025, 0, 1]]


def refused(capsys, argv: list[str], folder: Path, *needles: str) -> str:
    """Run the command: exit 2, one line on stderr with `needles`, no traceback, nothing new in `folder`."""
    before = sorted(folder.rglob("*"))
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and err.count("\n") == 0 and err.startswith(f"tamp {argv[0]}: error: "), err
    for needle in needles:
        assert needle in err, err
    assert sorted(folder.rglob("*")) == before  # nothing written
    return err


def problem_text(**fields) -> str:
    return json.dumps({"X_init": INIT, "X_goal": GOAL, **fields})


@pytest.mark.parametrize("text, needles", [
    ("[" * 100_000 + "]" * 100_000, ["nested deeper than 32 levels at column 33"]),
    (problem_text(seed=1).replace('"seed": 1', '"seed": ' + "9" * 5000), ["an integer of 5,000 digits (at most 20)"]),
    (problem_text(k=1).replace('"k": 1', '"k": 1' + "0" * 400), ["an integer of 401 digits"]),
    (problem_text(X_init=[[1e400, 0.15, 0.025, 1, 0], INIT[1]]).replace("Infinity", "1e400"), ["1e400 is beyond"]),
    (problem_text(seed=-1), ["seed: expected a value >= 0, got -1"]),
    (problem_text(actions=[[0, 0, 99, 0]]), ["actions[0]: [0, 0, 99, 0] names a block beyond the scene's 2"]),
    (problem_text(X_goal="GOAL"), ["X_goal: expected a list"]),
])
def test_a_bad_problem_file(tmp_path, capsys, monkeypatch, text, needles):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "p.json").write_text(text)
    refused(capsys, ["plan", "--problem", "p.json", "--execute", "none"], tmp_path, "p.json", *needles)


def test_bytes_that_are_not_utf8_in_a_problem_file(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    text = json.dumps({"X_init": INIT, "X_goal": GOAL, "name": "café"}, ensure_ascii=False)
    (tmp_path / "p.json").write_bytes(text.encode("latin-1"))
    refused(capsys, ["plan", "--problem", "p.json", "--execute", "none"], tmp_path,
            "p.json: not UTF-8 text (byte 0xe9 at line 1, column")


@pytest.mark.parametrize("damage, needle", [
    (lambda packed: packed[:40] + bytes(b ^ 0x5A for b in packed[40:48]) + packed[48:], "damaged gzip data"),
    (lambda packed: gzip.compress(b"[" * 100_000 + b"]" * 100_000), "nested deeper than 32 levels"),
])
def test_a_damaged_gzipped_operators_file(tmp_path, capsys, monkeypatch, damage, needle):
    models = tmp_path / "models"
    other_sets = [name for name in BUNDLED_MODELS.values() if name]  # subfolders of the default set
    shutil.copytree(pretrained_dir(), models, ignore=shutil.ignore_patterns(*other_sets))
    packed = models / "domain" / "operators.json.gz"  # the bundled domain is shipped gzipped
    packed.write_bytes(damage(gzip.compress(gzip.decompress(packed.read_bytes()))))
    (tmp_path / "p.json").write_text(problem_text())
    monkeypatch.chdir(tmp_path)
    refused(capsys, ["plan", "--problem", "p.json", "--models", str(models), "--execute", "none"], tmp_path,
            str(packed), needle)


# --- flags that do not apply, and one seed range -------------------------------------------------------

@pytest.mark.parametrize("flags, needle", [
    (["--max-actions", "3"], "--max-actions sets the loop that runs until the goal; give it with --replan"),
    (["--replan", "--rounds", "2", "--max-actions", "3"], "--max-actions sets the loop that runs until the goal"),
])
def test_tamp_plan_refuses_loop_flags_without_their_loop(tmp_path, capsys, monkeypatch, flags, needle):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "p.json").write_text(problem_text())
    refused(capsys, ["plan", "--problem", "p.json", "--execute", "fast", *flags], tmp_path, needle)


@pytest.mark.parametrize("methods, flags, needle", [
    ("bilevel,cfs", ["--noise", "0.01"], "--noise/--push act on closed loops"),
    ("bilevel", ["--push", "0.03,0.05"], "--noise/--push act on closed loops"),
    ("bilevel_replan", ["--max-actions", "3"], "--max-actions sets the loop that runs until the goal (bilevel_loop)"),
])
def test_tamp_evaluate_refuses_flags_no_method_applies(tmp_path, capsys, methods, flags, needle):
    problems = tmp_path / "set.jsonl"
    problems.write_text(json.dumps({"name": "a", "X_init": INIT, "X_goal": GOAL, "k": 1}) + "\n")
    refused(capsys, ["evaluate", "--models", "pretrained", "--problems", str(problems), "--out", str(tmp_path / "out"),
                     "--methods", methods, *flags], tmp_path, needle)


def test_a_negative_seed_in_a_problem_set_is_refused_before_any_work(tmp_path, capsys):
    problems = tmp_path / "set.jsonl"
    problems.write_text(json.dumps({"name": "a", "X_init": INIT, "X_goal": GOAL, "k": 1, "seed": -1}) + "\n")
    refused(capsys, ["evaluate", "--models", "pretrained", "--problems", str(problems), "--out", str(tmp_path / "out"),
                     "--methods", "bilevel_loop"], tmp_path, "set.jsonl line 1: seed: expected a value >= 0, got -1")


# --- trajectory files: checked as motion --------------------------------------------------------------

X3 = np.array(INIT + [[0.50, 0.35, 0.025, 1, 0]])


@pytest.fixture(scope="module")
def three_blocks(tmp_path_factory) -> dict:
    """The trajectory document of one pick-place in a 3-block scene (the fast world)."""
    from tamp.app.runner import execute_plan, executed_trajectory
    from tamp.sim.trajectory_file import write_trajectory

    ex = execute_plan([(0, 0, 1, 0)], X3, X3, "fast")
    assert ex.refined.success, ex.refined.failure
    path = write_trajectory(tmp_path_factory.mktemp("valid") / "t.json", executed_trajectory(ex, "test"))
    return json.loads(path.read_text())


def _segment(doc: dict, name: str) -> dict:
    return next(s for s in doc["actions"][0]["segments"] if s["name"] == name)


def _still_for_an_hour(doc: dict) -> None:
    points = _segment(doc, "grasp")["trajectory"]["points"]
    points[-1]["time_from_start"] = {"sec": 3600, "nanosec": 0}


def _zero_velocities(doc: dict) -> None:
    for point in _segment(doc, "transfer")["trajectory"]["points"][1:-1]:
        point["velocities"] = [0.0] * 6


@pytest.mark.sim
@pytest.mark.parametrize("edit, needles", [
    (_zero_velocities, ["segment 'transfer' points", "velocities and positions disagree"]),
    (lambda doc: doc["actions"][0].update(action=[99, 0, 1, 0]),
     ["action 0: [99, 0, 1, 0] names a block beyond the scene's 3 (0..2)"]),
    (lambda doc: doc["actions"][0]["gripper"][1].update(event=["open"]),
     ["actions[0].gripper[1].event: expected one of \"open\", got [\"open\"]"]),
    (_still_for_an_hour, ["time_from_start.sec: expected a value <= 60, got 3600"]),
    (lambda doc: doc["actions"][0]["gripper"][0].update(time=2.0 * _segment(doc, "transfer")["start_time"]),
     ["the jaws close at", "outside the 'grasp' segment"]),
])
def test_a_trajectory_file_that_a_controller_must_not_get(three_blocks, tmp_path, capsys, edit, needles):
    doc = json.loads(json.dumps(three_blocks))
    edit(doc)
    (tmp_path / "t.json").write_text(json.dumps(doc))
    refused(capsys, ["view", "--trajectory", str(tmp_path / "t.json"), "--out", str(tmp_path / "v.html")], tmp_path,
            "t.json", *needles)


@pytest.mark.sim
def test_a_400_digit_integer_in_a_time_field(three_blocks, tmp_path, capsys):
    time = '"time_from_start": {"sec": '
    text = json.dumps(three_blocks).replace(time + "0", time + "1" + "0" * 399, 1)
    (tmp_path / "t.json").write_text(text)
    refused(capsys, ["view", "--trajectory", str(tmp_path / "t.json")], tmp_path, "an integer of 400 digits")
