"""`tamp demo`, the pretrained models shipped in the package, and replays with ghost blocks."""
from __future__ import annotations

import base64
import re
from pathlib import Path

import numpy as np
import pytest

from symbolic import operators_file
from tamp.app.cli import main
from tamp.planning.models import DOMAIN_DIR, DYNAMICS_FILE, SYMBOLIC_FILE, load_models, pretrained_dir


def _scene_paths(html_file) -> bytes:
    """The Meshcat commands embedded in a static replay (base64 msgpack), concatenated."""
    blobs = re.findall(r'base64,([A-Za-z0-9+/=]+)"', html_file.read_text())
    return b"".join(base64.b64decode(b) for b in blobs)


@pytest.mark.sim
@pytest.mark.parametrize("name", ["pretrained", "paper", "pairwise", "spatial", "regions", "random", "practised"])
def test_the_shipped_models_are_small_load_by_name_and_plan(name):
    import torch

    from tamp.app.args import BUNDLED_MODELS, models_directory
    from tamp.app.problem import random_problem
    from tamp.planning.config import PlanConfig
    from tamp.planning.planners import plan

    torch.set_num_threads(1)
    directory = models_directory(name)
    assert directory == pretrained_dir() / ("" if name == "pretrained" else name)
    files = [directory / SYMBOLIC_FILE, directory / DYNAMICS_FILE, operators_file(directory / DOMAIN_DIR)]
    assert all(f.is_file() for f in files), [str(f) for f in files if not f.is_file()]
    assert (pretrained_dir() / "PROVENANCE.md").is_file()
    others = set(BUNDLED_MODELS.values()) - {""} if name == "pretrained" else set()  # the other sets: subfolders
    own = [f for f in directory.rglob("*") if f.is_file() and not others & set(f.parts)]
    assert sum(f.stat().st_size for f in own) < 4e6  # "a few MB at most", each set
    models = load_models(directory)
    assert models.symbolic is not None and models.symbolic.config.relations == ("attention" if name == "paper"
                                                                                 else "pairwise")
    problem = random_problem(2, 1, seed=0)
    result = plan("bilevel", models, problem.X_init, problem.X_goal, PlanConfig().with_seed(0))
    assert result.solved, result.reasons
    assert result.predicted.shape == (len(result.plan) + 1, 2, 5)
    assert result.predicted_error < PlanConfig().verify.tau_verify


@pytest.mark.sim
@pytest.mark.slow
@pytest.mark.parametrize("fidelity, candidates, loop, objects", [("fast", 1, "open", 3), ("fast", 0, "closed", 3),
                                                               ("full", 0, "closed", 2)])
def test_demo_prints_the_summary_and_writes_replays_with_ghosts(tmp_path, capsys, fidelity, candidates, loop,
                                                                objects):
    """The demo's summary and replays; in the full world (the default), also the round trip of its trajectory:
    `tamp view --trajectory` executes it again from the recorded initial scene, every block ending within 2 mm
    of the demo's final scene."""
    replay, trajectory = tmp_path / "demo.html", tmp_path / "demo.json"
    code = main(["demo", "--seed", "0", "--objects", str(objects), "--fidelity", fidelity, "--replay", str(replay),
                 "--candidates", str(candidates)] + (["--open-loop"] if loop == "open" else [])
                + (["--trajectory", str(trajectory)] if fidelity == "full" else []))
    out = capsys.readouterr().out
    summary = f"summary (seed 0, {fidelity} execution)" if loop == "open" else \
        f"summary (seed 0, {fidelity} execution, closed loop)"
    for part in (f"problem (seed 0): {objects} blocks", "goal (", "symbolic candidates", summary,
                 "  plan" + (" " if loop == "open" else "s "), "planning ", "final error", "outcome "):
        assert part in out, part
    if loop == "closed":  # every executed action is reported, and the summary lists the same actions
        executed = re.findall(r"  executed (pick \d at [+-]\d, place on \d at [+-]\d)", out)
        listed = re.search(r"  plans +\d+ round\(s\): [^;]+; (\d+) action\(s\) executed", out)
        assert executed and listed is not None and int(listed.group(1)) == len(executed)
    outcome = re.search(r"outcome +(\w+)", out).group(1)
    assert code == (0 if outcome == "success" else 1)
    assert replay.is_file()
    scene = _scene_paths(replay)
    for j in range(objects):
        assert f"/ghosts/goal/block_{j}".encode() in scene
    if "no plan" not in out:
        assert b"/ghosts/predicted/block_0" in scene
    assert "Dynamics Model&#x27;s prediction" in replay.read_text()  # the legend
    # The first candidate that failed verification was executed into its own replay.
    rejected = re.search(r"candidate (\d+) \[", out)
    if candidates and "unverified" in out:
        assert rejected is not None
        candidate = tmp_path / f"demo.candidate{rejected.group(1)}.html"
        assert candidate.is_file() and b"/ghosts/predicted/block_0" in _scene_paths(candidate)
    if fidelity == "full":
        _assert_the_trajectory_runs_again(trajectory, out, tmp_path, capsys)


def _assert_the_trajectory_runs_again(path, out, tmp_path, capsys):
    from tamp.sim.trajectory_file import read_trajectory

    assert f"trajectory written to {path}" in out
    plan = read_trajectory(path)
    executed = re.findall(r"  executed (pick \d at [+-]\d, place on \d at [+-]\d)", out)
    assert plan.world == "full" and len(plan.actions) + len(plan.skipped) == len(executed)
    assert len(plan.actions) >= 2  # the second action starts where the first ended
    assert main(["view", "--trajectory", str(path), "--out", str(tmp_path / "view.html")]) == 0
    again = capsys.readouterr().out
    deviation = float(re.search(r"final scene: every block within ([\d.]+) mm of the recorded one", again).group(1))
    assert deviation <= 2.0
    assert (tmp_path / "view.html").is_file()


def test_demo_plans_with_the_configuration(tmp_path, capsys, monkeypatch):
    """`tamp demo` is a random problem, then the plan command's planner: the configuration file and --max-actions
    reach the demo's PlanConfig, and --max-actions with --open-loop is a one-line error."""
    import tamp.app.demo as demo
    from tamp.planning.config import PlanConfig

    seen = []
    monkeypatch.setattr(demo, "run_demo", lambda cfg: seen.append(cfg) or demo.DemoResult(None, None, None, 0.05))
    monkeypatch.setattr(demo.DemoResult, "success", True)
    replay = str(tmp_path / "r.html")
    config = tmp_path / "c.toml"
    config.write_text("[search]\nmax_expansions = 11\n[level1]\nbudget = 9\n")
    flags = ["--config", str(config), "--max-actions", "4"]
    assert main(["demo", "--replay", replay, *flags]) == 0
    planner = seen[0].planner
    assert (planner.search.max_expansions, planner.level1.budget, planner.loop.max_actions) == (11, 9, 4)
    assert main(["demo", "--replay", replay]) == 0 and seen[1].planner == PlanConfig()
    assert main(["demo", "--replay", replay, "--open-loop", "--max-actions", "4"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tamp demo: error:") and "--max-actions" in err and "\n" not in err and len(seen) == 2


@pytest.mark.sim  # `tamp demo` loads the simulator before it reads the models
def test_demo_with_a_bad_models_directory_is_a_one_line_error(tmp_path, capsys):
    missing = tmp_path / "no-such-models"
    assert main(["demo", "--models", str(missing), "--replay", str(tmp_path / "r.html")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tamp demo: error:") and str(missing) in err and "\n" not in err
    (tmp_path / "partial").mkdir()
    (tmp_path / "partial" / DYNAMICS_FILE).write_bytes(b"not a checkpoint")
    assert main(["demo", "--models", str(tmp_path / "partial")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tamp demo: error:") and SYMBOLIC_FILE in err and "\n" not in err
    assert not (tmp_path / "r.html").exists()


@pytest.mark.sim
def test_predictions_are_tied_to_the_start_of_each_action():
    from tamp.sim.replay import Timeline  # loads Drake: here, not when a session without sim tests collects

    timeline = Timeline()
    for t in (0.0, 1.0, 2.0):  # action 0 starts at 0 s, action 1 at 1 s; action 2 never starts
        timeline._add(t, np.zeros(6), np.zeros((2, 7)))
        if t < 2.0:
            timeline.action_started()
    predicted = np.arange(4 * 2 * 5, dtype=float).reshape(4, 2, 5)  # X_init and after each of 3 actions
    timeline.show_goal(predicted[-1])
    timeline.show_predictions(predicted)
    goal, shown = timeline.ghosts
    assert goal.times == [0.0] and np.array_equal(goal.states[0], predicted[-1])
    assert shown.times == [0.0, 1.0]  # the state after action i from the start of action i
    assert np.array_equal(shown.states, predicted[1:3])
    with pytest.raises(ValueError, match="one \\(n, 5\\) state per time"):
        type(goal)("bad", predicted, [0.0], goal.rgba)


def test_a_local_folder_named_like_a_bundled_set_wins(tmp_path, monkeypatch):
    from tamp.app.args import models_directory

    monkeypatch.chdir(tmp_path)
    assert models_directory("pairwise") == pretrained_dir() / "pairwise"
    (tmp_path / "pairwise").mkdir()
    assert models_directory("pairwise") == Path("pairwise")
    assert models_directory("elsewhere") == Path("elsewhere")  # not a bundled name: left to the command's check
