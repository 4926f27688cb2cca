"""The closed loop observing through the camera rig (`perception.observe = "cameras"`): it reaches the goal from
what the cameras see, a block not seen is said and looked at again, and the planner, the kinematic check and the
skill take the perceived poses, not the true ones."""
from __future__ import annotations

import base64
import dataclasses
import re

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix

from tamp.app.faults import Faults
from tamp.app.observation import CameraObserver
from tamp.app.problem import random_problem
from tamp.app.runner import run_closed_loop
from tamp.planning.config import LoopConfig, PlanConfig
from tamp.planning.planners import plan
from tamp.planning.vocabulary import LARGE, SMALL, PickPlace
from tamp.sim.box_fit import orientation_error
from tamp.sim.cameras import CameraRig
from tamp.sim.kinematic_checker import FeasibilityChecker
from tamp.sim.perception_config import PerceptionConfig
from tamp.sim.replay import Timeline
from tamp.sim.skill import Scene, boxes_overlap
from tamp.sim.world import World

pytestmark = pytest.mark.sim  # every test here renders with Drake


@pytest.fixture(scope="module")
def rig():
    return CameraRig(PerceptionConfig(observe="cameras"))


@pytest.fixture(scope="module")
def models():
    import torch

    from tamp.planning.models import load_models, pretrained_dir

    torch.set_num_threads(1)
    return load_models(pretrained_dir())


def loop_config(seed: int, max_actions: int = 30) -> PlanConfig:
    """The default planner, its loop as the cameras set it (`Faults.known_to`), for a problem of `seed`."""
    cfg = PlanConfig().with_seed(seed)
    loop = Faults().known_to(dataclasses.replace(cfg.loop, max_actions=max_actions), cameras=True)
    return dataclasses.replace(cfg, loop=loop)


class Offset:
    """The rig with every camera believed `shift_m` (x, metres) from where it is: every perceived block is that far
    off its true place, as a rig calibrated wrong would see it."""

    def __init__(self, rig: CameraRig, shift_m: float) -> None:
        self.rig, self.config, self.shift_m = rig, rig.config, shift_m

    def observe(self, scene, rng):
        views = self.rig.observe(scene, rng)
        return [dataclasses.replace(v, X_WC=v.X_WC + np.pad([[self.shift_m]], ((0, 3), (3, 0)))) for v in views]


class Hiding:
    """The rig with block `block` taken out of the scene for its next `times` renderings (a block no camera sees)."""

    def __init__(self, rig: CameraRig, block: int, times: int) -> None:
        self.rig, self.config, self.block, self.times = rig, rig.config, block, times

    def observe(self, scene: Scene, rng):
        if self.times > 0:
            self.times -= 1
            keep = [k for k in range(scene.n) if k != self.block]
            scene = Scene(scene.types[keep], [scene.X_WB[k] for k in keep])
        return self.rig.observe(scene, rng)


@pytest.mark.slow  # a whole loop of 3 blocks and its replay: about 30 s
def test_the_loop_with_cameras_reaches_the_goal_and_the_replay_shows_what_was_seen(rig, models, tmp_path):
    problem = random_problem(3, 2, seed=1)
    timeline = Timeline()
    run = run_closed_loop("bilevel", models, problem.X_init, problem.X_goal, None, loop_config(problem.seed),
                          kinematics=FeasibilityChecker(), timeline=timeline, cameras=rig)
    assert run.loop.executed and run.error < 0.05, run.loop.reason  # judged by the world's truth
    assert all(o.scene is not None for o in run.observations)  # every observation perceived
    record = run.perception_record()
    assert record is not None and 0 < record["sigma_m"] < 0.002  # learned from its own observations
    assert record["error_max_m"] < 0.01
    # one observation at the start (looked at twice) and one after each action, each with its cloud and boxes
    assert len(timeline.seen) == len(run.loop.executed) + 1
    assert all(len(s.cloud) > 100 and len(s.boxes) == 3 for s in timeline.seen)
    page = timeline.write_html(tmp_path / "replay.html")
    commands = b"".join(base64.b64decode(b) for b in re.findall(r'base64,([A-Za-z0-9+/=]+)"', page.read_text()))
    assert b"/perception/0/cloud" in commands and b"/perception/0/block_2" in commands


def test_a_missing_block_is_said_and_looked_at_again(rig):
    X_init = np.array([[0.6, 0.15, 0.025, 1, 0], [0.75, -0.1, 0.025, 0, 1]], dtype=float)
    world = World()
    world.reset(X=X_init)
    hidden_once = CameraObserver(Hiding(rig, 0, times=1), np.random.default_rng(0), X_init)
    seen = hidden_once.again(world.scene)
    assert seen.looks == 2 and "block 0 (small" in seen.said[0] and "not seen" in seen.said[0]
    assert len(seen.said) == 1 and np.abs(seen.X[:, :3] - world.X[:, :3]).max() < 0.005  # the second look saw it
    hidden = CameraObserver(Hiding(rig, 0, times=10), np.random.default_rng(0), X_init)
    seen = hidden.again(world.scene)
    assert seen.looks == 3 and len(seen.X) == 2  # never a wrong number of blocks, and said so
    assert "planned with every block: block 0 (small) not seen, taken at (0.600, 0.150, 0.025) m" in seen.said[-1]


def test_the_planner_the_check_and_the_skill_take_the_perceived_poses(rig, models):
    X_init = np.array([[0.6, 0.15, 0.025, 1, 0], [0.75, -0.1, 0.025, 0, 1]], dtype=float)
    X_goal = X_init.copy()
    X_goal[0, :3] = [0.75, -0.1, 0.075]  # the cube on the bar
    given: list[np.ndarray] = []

    def spy(method, models_, X, goal, config, **extra):
        given.append(np.array(X))
        return plan(method, models_, X, goal, config, **extra)

    kinematics = FeasibilityChecker()
    steps = []
    run = run_closed_loop("bilevel", models, X_init, X_goal, None, loop_config(0, max_actions=1),
                          kinematics=kinematics, planner=spy, cameras=Offset(rig, 0.004),
                          on_step=lambda action, X, info, s: steps.append(info))
    truth = run.scene_init.X()
    assert np.abs(given[0][:, 0] - truth[:, 0] - 0.004).max() < 0.0015  # the perceived x, 4 mm off the truth
    assert np.abs(given[0][:, 1:3] - truth[:, 1:3]).max() < 0.0015
    perceived = [p.translation() for p in kinematics.scene.X_WB]  # the check observed the perceived scene
    assert np.abs(np.array(perceived)[:, 0] - run.X_after[-1][:, 0] - 0.004).max() < 0.0015
    (info,) = steps
    assert info.status == "ok" and run.loop.executed[0].pick == 0 and info.grasped == 0
    # the jaws were aimed at the cube seen 4 mm off: they hold the true cube 4 mm off their centre
    assert np.linalg.norm(info.X_GC[0].translation()[:2]) == pytest.approx(0.004, abs=0.0015)


def test_the_skill_aimed_at_the_seen_scene_carries_the_true_block():
    truth = Scene(np.array([SMALL, LARGE]), [RigidTransform([0.6, 0.15, 0.025]), RigidTransform([0.75, -0.1, 0.025])])
    seen = Scene(truth.types, [RigidTransform([0.603, 0.15, 0.025]), RigidTransform([0.75, -0.1, 0.025])])
    world = World()
    world.reset(X=truth.X())
    X, info = world.step(PickPlace(0, 0, 1, 0), seen=seen)
    assert info.status == "ok" and info.grasped == 0
    assert abs(np.linalg.norm(info.X_GC[0].translation()[:2]) - 0.003) < 0.0005  # held 3 mm off the jaws' centre
    assert X[0, 2] == pytest.approx(0.075, abs=0.003)  # on the bar


def test_the_cameras_refuse_added_noise_and_leave_the_margin_to_be_learned():
    loop = Faults().known_to(LoopConfig(), cameras=True)
    assert loop.stop_margin is None and loop.looks == 2
    with pytest.raises(ValueError, match="camera rig, whose noise is its own"):
        Faults(noise_m=0.005).known_to(LoopConfig(), cameras=True)


def test_a_block_seen_far_from_the_prediction_is_said_and_kept_where_it_is_seen(rig):
    X_init = np.array([[0.6, 0.15, 0.025, 1, 0], [0.75, -0.1, 0.025, 0, 1]], dtype=float)
    world = World()
    world.reset(X=X_init)

    def predict(X, action):  # a Dynamics Model that missed by 12 cm: the world put the cube elsewhere
        out = np.array(X)
        out[0, 1] -= 0.12
        return out

    observer = CameraObserver(rig, np.random.default_rng(0), X_init, predict)
    seen = observer.after(world.scene, PickPlace(0, 0, 0, 0))
    assert seen.looks == 3 and all("block 0 seen at (0.600, 0.150" in s and "12 cm from where it was expected" in s
                                   for s in seen.said)
    assert np.abs(seen.X[:, :3] - world.X[:, :3]).max() < 0.005  # no points where it was expected: kept as seen


def test_a_cube_seen_with_its_axes_named_otherwise_keeps_the_names_it_had(rig):
    """A cube's box fits its points with its axes named any of 24 ways; the skill turns a bar placed beside it by
    the cube's yaw, so the observer keeps the naming nearest the last one (axis-aligned at first)."""
    observer = CameraObserver(rig, np.random.default_rng(0), np.array([[0.6, 0.15, 0.025, 1, 0]], dtype=float))
    swapped = np.eye(4)
    swapped[:3, :3] = RotationMatrix.MakeZRotation(np.radians(90.4)).matrix()  # x and y swapped, 0.4 degrees off
    kept = observer._turned_as_before(0, swapped)
    assert np.degrees(np.arctan2(kept[1, 0], kept[0, 0])) == pytest.approx(0.4, abs=1e-6)
    assert Scene(np.array([SMALL]), [RigidTransform(RotationMatrix(kept[:3, :3]), [0.6, 0.15, 0.025])]).yaw(0) == \
        pytest.approx(np.radians(0.4), abs=1e-6)


def test_a_bar_leaning_on_a_cube_taken_where_the_action_should_have_left_it_keeps_its_tilt(rig):
    """A bar set down on a cube's end leans with its far end on the table. When the loop takes the prediction's
    split of the points (`_as_expected`: here the bar seen 25 cm off, where a wrong split puts it), the bar is
    fitted leaning as the points show, not upright, which the kinematic check would find inside the cube."""
    tilt = np.arcsin(0.05 / 0.2)  # the bar's underside rests on the cube's top edge 20 cm from its low end
    bar = RigidTransform(RollPitchYaw(tilt, 0.0, 0.0), [0.6, 0.125 * np.cos(tilt) - 0.025 * np.sin(tilt),
                                                         0.125 * np.sin(tilt) + 0.025 * np.cos(tilt)])
    truth = Scene(np.array([SMALL, LARGE]), [RigidTransform([0.6, 0.2 * np.cos(tilt) + 0.025, 0.025]), bar])
    X_true = truth.X()
    observer = CameraObserver(rig, np.random.default_rng(0), X_true)
    views = rig.observe(truth, np.random.default_rng(0))
    X = X_true.copy()
    X[1, :3] = [0.6, -0.125, 0.025]  # the bar seen upright, 25 cm off
    poses = [truth.X_WB[0].GetAsMatrix4(), RigidTransform(X[1, :3]).GetAsMatrix4()]
    taken = observer._as_expected(views, X, poses, set(), X_true)
    assert taken is not None and "blocks 1 taken where the action should have left them" in taken[3][0]
    X_taken, poses_taken = taken[0], taken[1]
    assert np.abs(X_taken[:, :3] - X_true[:, :3]).max() < 0.003
    assert np.degrees(orientation_error(poses_taken[1][:3, :3], bar.rotation().matrix(), LARGE)) < 2.0


def test_a_cube_and_a_bar_end_to_end_are_planned_as_the_action_split_them_and_not_in_each_other(rig):
    """A cube touching a bar's end looks like a bar and a cube the other way round, and the bar's fit may reach into
    the cube: perception says what it could not explain, and the loop takes the prediction's split, the blocks
    fitted jointly (each point to its nearest box), touching without overlap: the kinematic check would take any
    overlap for a collision of every action."""
    truth = Scene(np.array([SMALL, LARGE]), [RigidTransform([0.64, 0.227, 0.025]),
                                             RigidTransform([0.64, 0.377, 0.025])])  # touching: the cube ends at 0.252
    X_true = truth.X()
    before = X_true.copy()
    before[1, :3] = [0.64, 0.2, 0.075]  # the bar on the cube, before the action put it down beside it
    observer = CameraObserver(rig, np.random.default_rng(0), before, lambda X, action: X_true)
    seen = observer.after(truth, PickPlace(1, -1, 0, 1))
    assert seen.looks == 3 and "blocks 0, 1 taken where the action should have left them" in seen.said[-1]
    assert np.abs(seen.X[:, :3] - X_true[:, :3]).max() < 0.002
    assert seen.scene is not None and not boxes_overlap(seen.scene.X_WB[0], truth.size(0), seen.scene.X_WB[1],
                                                        truth.size(1))


def test_blocks_seen_a_millimetre_in_each_other_are_planned_apart():
    """Blocks that touch are each fitted within a millimetre or so; the kinematic check would take their overlap for
    a collision of every action. Side by side, each moves half; one on the other, the upper one moves up."""
    from tamp.app.observation import _apart

    types = np.array([SMALL, LARGE, SMALL])
    poses = [RigidTransform(p).GetAsMatrix4() for p in ([0.6, 0.0, 0.025], [0.6, 0.149, 0.025], [0.6, 0.0, 0.0745])]
    apart = _apart(types, poses)
    sizes = [np.array([0.05, 0.05, 0.05]), np.array([0.05, 0.25, 0.05]), np.array([0.05, 0.05, 0.05])]
    assert not any(boxes_overlap(RigidTransform(apart[a]), sizes[a], RigidTransform(apart[b]), sizes[b], margin=0.0)
                   for a, b in [(0, 1), (0, 2), (1, 2)])
    assert apart[0][1, 3] == pytest.approx(-0.0006, abs=1e-4) and apart[1][1, 3] == pytest.approx(0.1496, abs=1e-4)
    assert apart[2][2, 3] == pytest.approx(0.0752, abs=1e-4)  # lifted: the table holds the cube under it
    far = [RigidTransform(p).GetAsMatrix4() for p in ([0.6, 0.0, 0.025], [0.6, 0.14, 0.025])]  # 1 cm: no fitting noise
    assert all(np.array_equal(a, b) for a, b in zip(_apart(types[:2], far), far))


def test_identities_follow_the_action_a_block_carried_far_is_not_taken_for_a_neighbour_pushed_a_little(rig):
    """Each perception is assigned to where the blocks are expected after the action: to the estimates from before
    it, cube 0 carried 47 cm and cube 1 pushed 5 cm would be nearer swapped (0.44 m in all against 0.51 m)."""
    before = np.array([[0.49, -0.25, 0.025, 1, 0], [0.68, -0.10, 0.025, 1, 0]], dtype=float)
    after = np.array([[0.80, 0.10, 0.025, 1, 0], [0.67, -0.145, 0.025, 1, 0]], dtype=float)
    truth = Scene(np.array([SMALL, SMALL]), [RigidTransform(p) for p in after[:, :3]])

    def predict(X, action):  # cube 0 where the action put it; the push, no model foresees
        out = np.array(X)
        out[0, :3] = after[0, :3]
        return out

    seen = CameraObserver(rig, np.random.default_rng(0), before, predict).after(truth, PickPlace(0, 0, 0, 0))
    assert np.abs(seen.X[:, :3] - after[:, :3]).max() < 0.003 and not seen.said


def test_a_bar_fitted_into_the_cube_it_lies_end_to_end_with_is_refitted_beside_it(rig):
    """A bar and a cube lying end to end on the table show one top face; the bar fitted to its part alone reaches
    millimetres into the cube (the kinematic check would take that for a collision of every action). The loop refits
    the two jointly from where they were seen, each point to its nearest box (`tamp demo --seed 14 --preset cameras`
    after its first action)."""
    truth = Scene(np.array([LARGE, SMALL]), [RigidTransform([0.749, -0.412, 0.025]),
                                             RigidTransform([0.749, -0.262, 0.025])])
    seen = CameraObserver(rig, np.random.default_rng(0), truth.X()).first(truth)
    assert seen.scene is not None
    assert np.abs(seen.X[:, :3] - truth.X()[:, :3]).max() < 0.002
    assert not boxes_overlap(seen.scene.X_WB[0], truth.size(0), seen.scene.X_WB[1], truth.size(1))
