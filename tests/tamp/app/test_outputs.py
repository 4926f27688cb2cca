"""Issue 81 for the commands that need the simulator: a full disk is one line naming the path with exit status 2
and leaves the disk as it was, outputs come after every check (models included), and a trajectory file
whose grasps are not where its scene's blocks are is refused, saying by how much."""
from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from tamp.app.cli import main
from tamp.planning.models import pretrained_dir
from tests import test_no_data_loss as shared
from tests.test_no_data_loss import refused_on_full_disk, tree

pytestmark = pytest.mark.sim
full_disk, dataset = shared.full_disk, shared.dataset  # the fixtures of the Drake-free half

INIT = [[0.60, 0.15, 0.025, 1, 0], [0.70, -0.10, 0.025, 0, 1]]
GOAL = [[0.70, -0.10, 0.075, 1, 0], [0.70, -0.10, 0.025, 0, 1]]


@pytest.fixture(scope="module")
def problem(tmp_path_factory) -> Path:
    """A one-action problem (the cube onto the bar) the bundled models plan."""
    path = tmp_path_factory.mktemp("problem") / "p.json"
    path.write_text(json.dumps({"name": "stack", "X_init": INIT, "X_goal": GOAL, "seed": 0, "k": 1}) + "\n")
    return path


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory) -> Path:
    from tamp.app.runner import execute_plan, executed_trajectory
    from tamp.sim.trajectory_file import write_trajectory

    ex = execute_plan([(0, 0, 1, 0)], np.array(INIT, float), np.array(GOAL, float), "fast")
    return write_trajectory(tmp_path_factory.mktemp("trajectory") / "t.json", executed_trajectory(ex, "test"))


@pytest.fixture(scope="module")
def results(tmp_path_factory, problem) -> Path:
    """An evaluation's results directory (one row)."""
    out = tmp_path_factory.mktemp("results") / "ev"
    assert main(["evaluate", "--models", "pretrained", "--problems", str(problem), "--out", str(out), "--methods",
                 "cfs", "--quiet", "--no-report"]) == 0
    return out


def test_full_disk_plan_outputs(capsys, full_disk, problem):
    for flag, name in (("--replay", "new/r.html"), ("--trajectory", "t.json"), ("--steps", "s.json")):
        refused_on_full_disk(capsys, full_disk, ["plan", "--problem", str(problem), flag, str(full_disk / name)])


def test_full_disk_view_and_simulate(capsys, full_disk, trajectory):
    refused_on_full_disk(capsys, full_disk, ["view", "--trajectory", str(trajectory), "--out",
                                             str(full_disk / "v.html")])
    refused_on_full_disk(capsys, full_disk, ["simulate", "--objects", "2", "--steps", "1", "--replay",
                                             str(full_disk / "s.html")])


def test_full_disk_problems_and_evaluate(capsys, full_disk, problem):
    refused_on_full_disk(capsys, full_disk, ["problems", "--objects", "2", "--actions", "1", "--per-cell", "1",
                                             "--out", str(full_disk / "p.jsonl")])
    refused_on_full_disk(capsys, full_disk, ["evaluate", "--models", "pretrained", "--problems", str(problem),
                                             "--out", str(full_disk / "ev"), "--methods", "cfs", "--quiet"])


def test_full_disk_collect(capsys, full_disk):
    refused_on_full_disk(capsys, full_disk, ["collect", "--samples", "10", "--out", str(full_disk / "c"),
                                             "--workers", "1", "--quiet"])


def test_full_disk_report(capsys, tmp_path, results):
    """The report writes into the results directory: fill a copy of it on a small disk."""
    with shared.tmpfs(tmp_path / "disk") as mount:
        shutil.copytree(results, mount / "ev")
        shared.fill(mount)
        refused_on_full_disk(capsys, mount, ["report", str(mount / "ev")])


@pytest.mark.slow
def test_full_disk_practice_and_demo(capsys, full_disk, dataset):
    refused_on_full_disk(capsys, full_disk, ["practice", "--data", str(dataset), "--out", str(full_disk / "pr"),
                                             "--rounds", "1", "--per-cell", "1", "--objects", "2", "--quiet"])
    refused_on_full_disk(capsys, full_disk, ["demo", "--objects", "2", "--actions", "1", "--replay",
                                             str(full_disk / "d.html")])


def test_plan_replay_into_a_new_folder_checks_the_models_first(tmp_path, capsys, problem):
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "dynamics.pt").write_text("not a model")
    assert main(["plan", "--problem", str(problem), "--models", str(tmp_path / "models"), "--replay",
                 str(tmp_path / "NEW" / "r.html")]) == 2
    assert "models" in capsys.readouterr().err
    assert not (tmp_path / "NEW").exists()


def test_evaluate_refuses_nan_models_before_writing(tmp_path, capsys, problem):
    models = tmp_path / "models"
    shutil.copytree(pretrained_dir(), models, ignore=shutil.ignore_patterns(
        "paper", "pairwise", "spatial", "regions", "random", "practised"))
    payload = torch.load(models / "dynamics.pt", weights_only=True)
    next(v for k, v in payload["state_dict"].items() if k.endswith("weight")).fill_(math.nan)
    torch.save(payload, models / "dynamics.pt")
    out = tmp_path / "ev"
    assert main(["evaluate", "--models", str(models), "--problems", str(problem), "--out", str(out), "--methods",
                 "cfs", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert f"{models / 'dynamics.pt'}: the model's weights are not finite" in err
    assert not out.exists()
    assert main(["plan", "--problem", str(problem), "--models", str(models), "--method", "cfs"]) == 2
    assert "not finite" in capsys.readouterr().err


@pytest.mark.parametrize(("field", "by", "said"), [("scene", 0.01, "10.0 mm"), ("scene", 0.0005, None),
                                                   ("after", 0.003, None)])
def test_a_trajectory_whose_grasp_misses_its_block_is_refused(tmp_path, capsys, trajectory, field, by, said):
    from tamp.sim.trajectory_checks import TrajectoryError
    from tamp.sim.trajectory_file import read_trajectory

    doc = json.loads(trajectory.read_text())
    if field == "scene":
        doc["scene"]["blocks"][0]["position"][0] += by  # the cube the one action grasps
    else:  # the scene after the action moves; nothing grasps it later: still a valid file
        doc["actions"][0]["blocks_after"][0][1] += by
    path = tmp_path / "moved.json"
    path.write_text(json.dumps(doc))
    if said is None:
        read_trajectory(path)
        return
    with pytest.raises(TrajectoryError, match=rf"action 0: the jaws close on block 0 {said} from where the scene"):
        read_trajectory(path)
    assert main(["view", "--trajectory", str(path), "--out", str(tmp_path / "v.html")]) == 2
    assert said in capsys.readouterr().err and not (tmp_path / "v.html").exists()
    assert tree(tmp_path) == [("moved.json", path.read_bytes())]
