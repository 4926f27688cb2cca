"""Trajectory files (`tamp plan/demo --trajectory`, `tamp view --trajectory`): the format, the UR10e's
limits read from the model file and one-line errors for bad files (the round trip of a demo's trajectory through
the full world: tests/tamp/app/test_demo.py)."""
from __future__ import annotations

import copy
import dataclasses
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from tamp.app.cli import main

X = np.array([[0.6, 0.15, 0.025, 1, 0], [0.7, -0.1, 0.025, 0, 1]])
PLAN = [(0, 0, 1, 0), (0, 0, 0, 1)]  # the cube onto the bar, then back onto the table beside it
POINT_FIELDS = {"positions", "velocities", "accelerations", "time_from_start"}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """A two-action plan refined and executed in the fast world, its trajectory written:
    (Execution, path of the file)."""
    from tamp.app.runner import execute_plan, executed_trajectory
    from tamp.sim.trajectory_file import write_trajectory

    ex = execute_plan(PLAN, X, X, "fast")
    assert ex.refined.success, ex.refined.failure
    path = write_trajectory(tmp_path_factory.mktemp("trajectory") / "plan.json", executed_trajectory(ex, "test"))
    return ex, path


def _urdf_limits():
    """Joint names and limits of drake_models/ur10e.urdf, read with ElementTree (not Drake)."""
    from tamp.sim.plants import ARM_FILE

    joints = [j for j in ET.parse(ARM_FILE).getroot().iter("joint") if j.get("type") == "revolute"]
    limits = [j.find("limit") for j in joints]
    return ([j.get("name") for j in joints], *(np.array([float(lim.get(key)) for lim in limits])
                                              for key in ("lower", "upper", "velocity")))


def _points(doc):
    for action in doc["actions"]:
        for segment in action["segments"]:
            yield from segment["trajectory"]["points"]


@pytest.mark.sim
def test_every_exported_sample_is_within_the_limits_of_the_model_file(exported):
    from tamp.sim.trajectory import A_MAX

    _, path = exported
    doc = json.loads(path.read_text())
    names, lower, upper, velocity = _urdf_limits()
    assert doc["format"] == "tamp-trajectory" and doc["version"] == 1
    assert doc["robot"]["name"] == "UR10e" and doc["robot"]["joint_names"] == names  # the model's order
    limits = doc["robot"]["limits"]
    assert np.allclose(limits["position_lower"], lower) and np.allclose(limits["position_upper"], upper)
    assert np.allclose(limits["velocity"], velocity) and np.allclose(limits["acceleration"], A_MAX)
    assert "A_MAX" in limits["acceleration_note"]  # the model gives none: the file says whose they are
    points = list(_points(doc))
    assert len(points) > 100
    for point in points:
        assert set(point) == POINT_FIELDS  # trajectory_msgs/JointTrajectoryPoint (no effort)
        assert set(point["time_from_start"]) == {"sec", "nanosec"}
        q, v, a = (np.array(point[key]) for key in ("positions", "velocities", "accelerations"))
        assert q.shape == v.shape == a.shape == (6,)
        assert np.all(q >= lower - 1e-9) and np.all(q <= upper + 1e-9)
        assert np.all(np.abs(v) <= velocity + 1e-9)
        assert np.all(np.abs(a) <= A_MAX + 1e-9)
    # the motion reaches the acceleration limit (the time-optimal profile): the check is not vacuous
    assert max(np.max(np.abs(p["accelerations"]) / A_MAX) for p in points) > 0.99


@pytest.mark.sim
def test_the_file_reproduces_the_executed_motion(exported):
    from tamp.sim.trajectory_file import DWELLS, SAMPLE_PERIOD, read_trajectory

    ex, path = exported
    plan = read_trajectory(path)
    assert plan.world == "fast" and plan.source == "test" and plan.skipped == []
    assert np.allclose(plan.q_init, ex.refined.q_init)
    for X_file, X_scene in zip(plan.scene_init.X_WB, ex.refined.scene_init.X_WB):
        assert X_file.IsNearlyEqualTo(X_scene, 1e-12)
    assert [a.action for a in plan.actions] == [tuple(a) for a in PLAN]
    for motion, step, X_after in zip(plan.actions, ex.refined.steps, ex.X_after):
        names = [s.name for s in motion.segments]
        assert names == ["approach", "descend", DWELLS["descend"], "liftoff", "lift", "transfer", "lower",
                         DWELLS["lower"], "retreat"]
        for segment in motion.segments:
            assert np.all(np.diff(segment.t) <= SAMPLE_PERIOD + 1e-8)  # dense: at least every SAMPLE_PERIOD
            assert np.allclose(segment.qdot[[0, -1]], 0.0)  # every motion starts and ends at rest
        assert abs(motion.t_close - step.t_grasp) < 1e-9 and abs(motion.t_open - step.t_release) < 1e-9
        assert motion.block == step.grasped and motion.X_GC.IsNearlyEqualTo(step.X_GC[0], 1e-9)
        assert np.allclose(motion.X_after[:, :3], X_after[:, :3], atol=1e-6)
        original, rebuilt = step.trajectory, motion.trajectory()
        assert abs(original.end_time() - rebuilt.end_time()) < 1e-8
        for t in np.linspace(0.0, original.end_time(), 2001):
            assert np.max(np.abs(original.value(t) - rebuilt.value(t))) < 1e-5  # rad: the samples' rounding
            assert np.max(np.abs(original.EvalDerivative(t, 1) - rebuilt.EvalDerivative(t, 1))) < 1e-3


def _edit(doc, how):
    """A broken copy of a valid trajectory document."""
    doc = copy.deepcopy(doc)
    point = doc["actions"][0]["segments"][2]["trajectory"]["points"][1]
    if how == "five positions":
        point["positions"] = point["positions"][:5]
    elif how == "missing velocities":
        del point["velocities"]
    elif how == "text time":
        point["time_from_start"] = "0.5"
    elif how == "another robot":
        doc["robot"]["name"] = "UR5e"
    elif how == "other joints":
        doc["robot"]["joint_names"] = [f"joint_{i}" for i in range(1, 7)]
    elif how == "newer version":
        doc["version"] = 2
    elif how == "not a trajectory":
        doc = {"X": [[0.6, 0.15, 0.025, 1, 0]], "actions": [[0, 0, 0, 0]]}
    elif how == "too fast":
        transfer = doc["actions"][0]["segments"][5]["trajectory"]["points"]
        transfer[len(transfer) // 2]["velocities"][0] = 2.5  # shoulder_pan_joint: 2.0944 rad/s at most
    elif how == "jump":
        for p in doc["actions"][1]["segments"][0]["trajectory"]["points"]:
            p["positions"][2] += 0.01
    return doc


@pytest.mark.sim
@pytest.mark.parametrize("how, message", [
    ("truncated", "not valid JSON"),
    ("empty", "not valid JSON"),
    ("five positions", "points[1].positions: expected at least 6 items, got 5"),
    ("missing velocities", "points[1]: missing field 'velocities'"),
    ("text time", "points[1].time_from_start: expected an object"),
    ("another robot", "a trajectory for robot 'UR5e'"),
    ("other joints", "joints ['joint_1'"),
    ("newer version", "format version 2; this tamp reads version 1"),
    ("not a trajectory", "not a tamp trajectory file"),
    ("too fast", "shoulder_pan_joint velocity 2.5 rad/s is outside the UR10e's limits"),
    ("jump", "starts 0.01 away in position from where action 0 ended"),
])
def test_a_bad_file_is_a_one_line_error_and_nothing_is_written(exported, tmp_path, capsys, how, message):
    _, path = exported
    text = path.read_text()
    bad = tmp_path / "bad.json"
    if how == "truncated":
        bad.write_text(text[: len(text) // 2])
    elif how == "empty":
        bad.write_text("")
    else:
        bad.write_text(json.dumps(_edit(json.loads(text), how)))
    out = tmp_path / "replay.html"
    assert main(["view", "--trajectory", str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("tamp view: error: ") and str(bad) in err, err
    assert message in err, err
    assert not out.exists() and list(tmp_path.iterdir()) == [bad]


@pytest.mark.sim
def test_writing_checks_the_motion_and_leaves_no_file_when_it_fails(exported, tmp_path):
    from tamp.sim.trajectory_file import TrajectoryError, read_trajectory, write_trajectory

    _, path = exported
    plan = read_trajectory(path)
    segment = plan.actions[0].segments[0]
    fast = dataclasses.replace(segment, qdot=segment.qdot * 2.0)  # twice the planned speed
    plan.actions[0].segments[0] = fast
    target = tmp_path / "out.json"
    with pytest.raises(TrajectoryError, match="velocity .* outside the UR10e's limits"):
        write_trajectory(target, plan)
    assert list(tmp_path.iterdir()) == []  # not even a temporary file
    still = dataclasses.replace(segment, qdot=np.zeros_like(segment.qdot))  # moving positions, no velocity
    plan.actions[0].segments[0] = still
    with pytest.raises(TrajectoryError, match=r"points \d+-\d+: .* velocities and positions disagree"):
        write_trajectory(target, plan)
    plan.actions[0].segments[0] = segment
    plan.actions[0] = dataclasses.replace(plan.actions[0], action=(0, 0, 99, 0))
    with pytest.raises(TrajectoryError, match=r"names a block beyond the scene's 2 \(0..1\)"):
        write_trajectory(target, plan)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.sim
def test_the_closed_loop_exports_what_it_executed_in_order(tmp_path):
    """Actions that moved nothing are listed as skipped; an arm put home without a motion (the fast
    world's blocked retreat) is refused: the run is not one continuous trajectory."""
    from tamp.app.runner import ClosedLoopRun, executed_trajectory, executing_world
    from tamp.planning.closed_loop import ClosedLoopResult
    from tamp.planning.vocabulary import PickPlace
    from tamp.sim.trajectory_file import TrajectoryError, read_trajectory, write_trajectory
    from tamp.sim.world_types import StepInfo, StepStatus

    world = executing_world("fast")
    X0 = world.reset(X=X)
    scene, q = world.scene, world.q.copy()
    X1, first = world.step(PLAN[0])
    failed = StepInfo(PickPlace(1, 0, 0, 0), status=StepStatus.IK_FAILURE, reason="no IK solution for the grasp pose")
    X3, last = world.step(PLAN[1])
    assert first.status == last.status == StepStatus.OK
    loop = ClosedLoopResult([], [PickPlace(*PLAN[0]), failed.action, PickPlace(*PLAN[1])], [X0, X1, X1, X3], X, 0.05)
    run = ClosedLoopRun(loop, [first, failed, last], scene_init=scene, q_init=q, X_after=[X1, X1, X3])
    plan = read_trajectory(write_trajectory(tmp_path / "loop.json", executed_trajectory(run, "loop")))
    assert [a.index for a in plan.actions] == [0, 2] and [a.action for a in plan.actions] == [PLAN[0], PLAN[1]]
    assert plan.skipped == [{"index": 1, "action": [1, 0, 0, 0], "reason": "no IK solution for the grasp pose"}]
    assert np.allclose(plan.X_final, X3)
    blocked = dataclasses.replace(last, paths={k: v for k, v in last.paths.items() if k != "retreat"},
                                  reason="released, but the retreat was blocked; the arm was reset home")
    run.infos[2] = blocked
    with pytest.raises(TrajectoryError, match="executed action 2: released, but the retreat was blocked"):
        executed_trajectory(run)


def test_the_commands_offer_the_trajectory(capsys):
    for command in ("plan", "demo", "view"):
        with pytest.raises(SystemExit):
            main([command, "--help"])
        assert "--trajectory" in capsys.readouterr().out
    assert main(["view"]) == 2
    assert "give a plan file, --trajectory FILE or --search FILE" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--trajectory", "out.txt"])
    assert "ending in .json" in capsys.readouterr().err
