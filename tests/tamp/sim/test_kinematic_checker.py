"""The kinematic feasibility check on predicted scenes (Drake): grasp contact, IK, waypoint collisions,
and its agreement with the skill on the cases it must catch."""
from __future__ import annotations

import numpy as np
import pytest

from tamp.planning.vocabulary import Infeasible, PickPlace
from tamp.sim.kinematic_checker import FeasibilityChecker

pytestmark = pytest.mark.sim  # every test here builds Drake plants

CUBE, BAR = [1, 0], [0, 1]


@pytest.fixture(scope="module")
def checker():
    return FeasibilityChecker()


def test_an_action_whose_grasp_point_misses_its_block_is_rejected(checker):
    X = np.array([[0.6, -0.1, 0.025, *CUBE], [0.7, 0.15, 0.025, *BAR]])
    checker.reset(X)
    # a cube picked 7.5 cm off its centre: the jaws close on nothing
    assert checker.check(X, [(0, 1, 1, 0), (0, -1, 1, 0)]) == [Infeasible.NO_GRASP] * 2
    # the same cube at its centre, and the bar at either end, are held
    assert checker.check(X, [(0, 0, 1, 0), (1, 1, 0, 0), (1, -1, 1, 1)]) == [None] * 3
    # the skill agrees: the jaws close on nothing and nothing changes
    X_after, info = checker.world.step(PickPlace(0, 1, 1, 0))
    assert info.status == "nothing_grasped"


def test_graspable_says_which_grasps_can_never_hold_a_block(checker):
    """The search leaves out, before predicting them, the actions `graspable` forbids: each must be one that
    every check rejects with NO_GRASP, here in a scene where the cube stands beside and on the bar."""
    from tamp.planning.search import all_actions

    X = np.array([[0.6, -0.1, 0.025, *CUBE], [0.7, 0.15, 0.025, *BAR], [0.7, 0.225, 0.075, *CUBE]])
    mask = checker.graspable(X)
    assert mask.tolist() == [[False, True, False], [True, True, True], [False, True, False]]
    checker.reset(X)
    actions = all_actions(3)
    forbidden = actions[~mask[actions[:, 0], actions[:, 1] + 1]]
    assert len(forbidden) == 2 * 2 * 9
    assert set(checker.check(X, forbidden)) == {Infeasible.NO_GRASP}


def test_stand_ins_collide_as_boxes_added_to_the_gripper():
    """The carrying checker poses stand-in bodies instead of adding shapes to Drake's checker: the same
    verdicts, for one box and for a stack of two, and for more boxes than it has stand-ins (shapes then)."""
    from pydrake.math import RigidTransform

    from tamp.sim.kinematics import Q_HOME
    from tamp.sim.motion import MotionPlanner
    from tamp.sim.plants import build_motion_scene
    from tamp.sim.skill import carried_size
    from tamp.sim.world_types import WorldConfig

    cfg = WorldConfig()
    types = np.array([0, 1])
    X_WB = [RigidTransform([0.6, -0.1, 0.025]), RigidTransform([0.7, 0.15, 0.025])]
    shapes_of = {"cube": [(carried_size(0, cfg), RigidTransform([0.0, 0.0, 0.13]))],
                 "stack": [(carried_size(1, cfg), RigidTransform([0.0, 0.075, 0.13])),
                           (carried_size(0, cfg), RigidTransform([0.0, 0.03, 0.18]))],
                 "three": [(carried_size(0, cfg), RigidTransform([0.0, 0.0, 0.13 + 0.05 * k])) for k in range(3)]}
    stand_ins = MotionPlanner(build_motion_scene(types, cfg.padding, stand_ins=[carried_size(t, cfg) for t in types]),
                              cfg.joint_step, cfg.padding)
    shapes = MotionPlanner(build_motion_scene(types, cfg.padding), cfg.joint_step, cfg.padding)
    rng = np.random.default_rng(0)
    from tamp.sim.kinematics import analytic_ik
    from tamp.sim.skill import topdown

    qs = [q for q in (analytic_ik(topdown(np.array([x, y, z]), 0.0), Q_HOME)
                      for x, y, z in rng.uniform([0.55, -0.15, 0.0], [0.75, 0.2, 0.2], size=(80, 3))) if q is not None]
    for planner in (stand_ins, shapes):
        planner.set_block_poses(X_WB)
    for name, boxes in shapes_of.items():
        verdicts = []
        for planner in (stand_ins, shapes):
            planner.attach(boxes)
            verdicts.append([planner.is_valid(q) for q in qs])
        assert verdicts[0] == verdicts[1], name
        assert True in verdicts[0] and False in verdicts[0], name  # both kinds of configuration are asked
    stand_ins.detach()
    shapes.detach()
    assert [stand_ins.is_valid(q) for q in qs] == [shapes.is_valid(q) for q in qs]


def test_the_check_uses_the_predicted_positions_not_the_observed_ones(checker):
    X = np.array([[0.6, -0.1, 0.025, *CUBE], [0.7, 0.15, 0.025, *BAR]])
    checker.reset(X)
    predicted = X.copy()
    predicted[0, :3] = [0.7, 0.15, 0.075]  # the Dynamics Model says: the cube is now on the bar's centre
    # picking the bar at its centre would close the jaws around the cube on top: the gripper collides
    assert checker.check(predicted, [(1, 0, 0, 0)]) == [Infeasible.COLLISION]
    assert checker.check(X, [(1, 0, 0, 0)]) == [None]
    # the cube on top is held (its grasp point lies on it)
    assert checker.check(predicted, [(0, 0, 1, 1)]) == [None]


def test_a_target_out_of_reach_fails_ik(checker):
    X = np.array([[0.6, 0.0, 0.025, *CUBE], [1.75, 0.0, 0.025, *CUBE]])
    checker.reset(X)
    assert checker.check(X, [(0, 0, 1, 0)]) == [Infeasible.IK]


def test_refine_reports_the_failing_action(checker):
    X = np.array([[0.6, -0.1, 0.025, *CUBE], [0.7, 0.15, 0.025, *BAR]])
    checker.reset(X)
    assert checker.refine([(0, 0, 1, 0)]).success
    out = checker.refine([(1, 0, 1, 1), (0, 1, 1, 0)])  # the second picks the cube 7.5 cm off: nothing
    assert (out.action_index, out.reason) in ((1, Infeasible.REFINE_GRASP), (1, Infeasible.REFINE_MOTION))


def test_an_action_that_failed_to_refine_fails_again_at_once_in_the_same_scene(checker, monkeypatch):
    """A closed loop's rounds offer the same failing first action again, each refinement of it a second of
    motion planning: in the same scene (on the search's grid) and at the same place of a plan it fails without a motion
    planned, after `observe` as well; another scene, another place in the plan or a `reset` plans it again."""
    X = np.array([[0.6, 0.0, 0.025, *CUBE], [1.75, 0.0, 0.025, *CUBE]])  # the second cube out of reach
    checker.reset(X)
    steps = []
    step = checker.world.step
    monkeypatch.setattr(checker.world, "step", lambda *a, **k: steps.append(a[0]) or step(*a, **k))
    first = checker.refine([(1, 0, 0, 0)])
    assert (first.action_index, first.reason) == (0, Infeasible.REFINE_IK) and len(steps) == 1
    checker.observe(checker.scene, checker.q)  # a new round in the same scene
    again = checker.refine([(1, 0, 0, 0)])
    assert (again.action_index, again.reason, again.message) == (0, first.reason, first.message)
    assert len(steps) == 1  # nothing planned
    assert checker.refine([(0, 0, 0, 0), (1, 0, 0, 0)]).action_index == 1 and len(steps) == 3  # second place
    moved = X.copy()
    moved[1, 1] = 0.05
    checker.reset(moved)
    assert checker.refine([(1, 0, 0, 0)]).action_index == 0 and len(steps) == 4
    checker.reset(X)
    assert checker.refine([(1, 0, 0, 0)]).action_index == 0 and len(steps) == 5


def test_the_memo_of_failed_refinements_counts_scenes_on_the_grid_it_is_given(checker, monkeypatch):
    """The memo's scenes are the planner's states: a scene 1.5 cm away is the same on a 4 cm grid, another on 1 cm."""
    X = np.array([[0.6, 0.0, 0.025, *CUBE], [1.75, 0.0, 0.025, *CUBE]])  # the second cube out of reach
    checker.reset(X)
    steps = []
    step = checker.world.step
    monkeypatch.setattr(checker.world, "step", lambda *a, **k: steps.append(a[0]) or step(*a, **k))
    assert checker.refine([(1, 0, 0, 0)], grid_m=0.04).reason == Infeasible.REFINE_IK and len(steps) == 1
    near = X.copy()
    near[1, 1] = 0.015
    checker.observe(checker.predicted_scene(near), checker.q)
    assert checker.refine([(1, 0, 0, 0)], grid_m=0.04).reason == Infeasible.REFINE_IK and len(steps) == 1
    assert checker.refine([(1, 0, 0, 0)], grid_m=0.01).reason == Infeasible.REFINE_IK and len(steps) == 2


def test_refinement_plans_each_action_in_the_predicted_scene_without_physics(checker):
    # After the first action the Dynamics Model predicts the cube out of the arm's reach: the second
    # action, which picks it, must fail its IK there, whatever the simulator would have done.
    X = np.array([[0.6, -0.1, 0.025, *CUBE], [0.7, 0.15, 0.025, *BAR]])
    checker.reset(X)
    after = X.copy()
    after[0, :3] = (1.75, 0.0, 0.025)
    trajectory = np.stack([X, after, after])
    plan = [(0, 0, 1, 0), (0, 0, 1, 1)]
    assert checker.refine(plan[:1], trajectory[:2]).success
    out = checker.refine(plan, trajectory)
    assert (out.action_index, out.reason) == (1, Infeasible.REFINE_IK)


def test_reused_pick_halves_and_attached_boxes_give_the_verdicts_of_checks_from_scratch(checker):
    """The search checks the places of one grasp one at a time, in any order and between other states: the
    pick half kept for them, and the boxes left attached in the carrying checker, must never change a verdict,
    whatever was checked (and attached) before."""
    from tamp.planning.search import all_actions

    scratch = FeasibilityChecker(world=checker.world, shortcuts=False)
    X = np.array([[0.6, -0.1, 0.025, *CUBE], [0.7, 0.15, 0.025, *BAR], [0.62, -0.04, 0.025, *CUBE],
                  [0.8, -0.2, 0.025, *CUBE]])
    stacked = X.copy()
    stacked[0, :3] = [0.7, 0.15, 0.075]  # the cube predicted on the bar's centre
    near = X.copy()
    near[3, :3] = [0.66, -0.1, 0.025]  # a cube predicted beside another: grasps collide
    checker.reset(X)
    scratch.reset(X)
    rng = np.random.default_rng(0)
    actions = all_actions(4)
    queries = [(S, a) for S in (X, stacked, near) for a in actions]
    order = rng.permutation(len(queries))  # states and grasps interleaved, as the search pops them
    remembered = [checker.check(queries[k][0], [queries[k][1]])[0] for k in order]
    fresh = [scratch.check(queries[k][0], [queries[k][1]])[0] for k in order]
    assert [r is None for r in remembered] == [r is None for r in fresh]
    verdicts = set(remembered)
    assert None in verdicts and Infeasible.NO_GRASP in verdicts and Infeasible.COLLISION in verdicts
    # a new observation forgets what the last scene's grasps gave
    checker.reset(stacked)
    assert checker.check(stacked, [(1, 0, 0, 0)]) == [Infeasible.COLLISION]


def test_the_box_test_says_overlap_only_where_the_boxes_interpenetrate():
    from pydrake.math import RigidTransform, RotationMatrix

    from tamp.sim.skill import boxes_overlap

    cube, bar = (0.05, 0.05, 0.05), (0.05, 0.25, 0.05)
    at = RigidTransform([0.6, 0.0, 0.025])
    assert boxes_overlap(at, cube, RigidTransform([0.62, 0.01, 0.03]), cube)  # 3 cm deep
    assert not boxes_overlap(at, cube, RigidTransform([0.65, 0.0, 0.025]), cube)  # face to face: touching
    assert not boxes_overlap(at, cube, RigidTransform([0.6, 0.0, 0.0755]), cube)  # stacked, 0.5 mm apart
    # a bar turned 45 degrees whose bounding box covers the cube's corner region but whose body misses it
    turned = RigidTransform(RotationMatrix.MakeZRotation(np.pi / 4), [0.6 + 0.09, 0.09, 0.025])
    assert not boxes_overlap(at, cube, turned, bar)
    assert boxes_overlap(at, cube, RigidTransform(RotationMatrix.MakeZRotation(np.pi / 4), [0.63, 0.03, 0.025]), bar)


def test_a_block_predicted_millimetres_into_its_support_is_checked_resting_on_it():
    """A bar predicted 2.4 mm low on another bar's centre (a regression's mean): where X puts it, the jaws reach
    the lower bar's end under it past its top face; resting on the lower bar, as the world has it, they strike it.
    A block farther off its support (leaning, falling) and a block beside it stay where predicted."""
    X = np.array([[0.686, 0.182, 0.025, *BAR], [0.686, 0.182, 0.0726, *BAR], [0.5, -0.2, 0.058, *CUBE],
                  [0.5, 0.2, 0.031, *CUBE]])
    pick_end_under_the_stack = [(0, -1, 0, 1)]
    resting, as_predicted = FeasibilityChecker(), FeasibilityChecker(rest_within=None)
    for checker in (resting, as_predicted):
        checker.reset(np.array([[0.686, 0.182, 0.025, *BAR], [0.5, -0.4, 0.025, *BAR], [0.5, -0.2, 0.025, *CUBE],
                                [0.5, 0.2, 0.025, *CUBE]]))
    assert as_predicted.check(X, pick_end_under_the_stack) == [None]
    assert resting.check(X, pick_end_under_the_stack) == [Infeasible.COLLISION]
    z = [pose.translation()[2] for pose in resting.predicted_scene(X).X_WB]
    assert z == pytest.approx([0.025, 0.075, 0.058, 0.025])
