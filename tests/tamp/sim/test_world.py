"""The block world: the pick-place skill's outcomes, its motions, its determinism and its errors."""
import numpy as np
import pytest

from tamp.planning import vocabulary
from tamp.planning.validate import MAX_OBJECTS, check_scene
from tamp.planning.vocabulary import BLOCK_SIZES, PickPlace
from tamp.sim import World, WorldConfig
from tamp.sim.kinematics import Q_LOWER, Q_UPPER, tcp_pose
from tamp.sim.motion import MotionPlanner
from tamp.sim.plants import X_FlangeTcp, build_motion_scene

pytestmark = pytest.mark.sim  # every test here builds Drake plants

SMALL, LARGE = [1.0, 0.0], [0.0, 1.0]
BAR_HEIGHT = BLOCK_SIZES[1][2]


@pytest.fixture(scope="module")
def world():
    return World(WorldConfig(), seed=0)


def scene(*blocks):
    return np.array([list(p) + t for p, t in blocks], dtype=float)


def test_cube_released_centred_on_bar_ends_on_top(world):
    X0 = world.reset(X=scene(((0.6, 0.15, 0.025), SMALL), ((0.7, -0.1, 0.025), LARGE)))
    X1, info = world.step(PickPlace(0, 0, 1, 0))
    assert info.status == "ok" and info.grasped == 0
    assert X1[0, 2] == pytest.approx(X0[0, 2] + BAR_HEIGHT, abs=0.01)
    np.testing.assert_allclose(X1[0, :2], X0[1, :2], atol=0.01)
    np.testing.assert_allclose(X1[1, :3], X0[1, :3], atol=0.005)  # the bar did not move


def test_cube_released_off_centre_on_cube_falls_to_table(world):
    X0 = world.reset(X=scene(((0.6, 0.15, 0.025), SMALL), ((0.7, -0.1, 0.025), SMALL)))
    X1, info = world.step(PickPlace(0, 0, 1, 1))
    assert info.status == "ok"
    assert X1[0, 2] == pytest.approx(X0[0, 2], abs=0.01)  # on the table, not on the cube
    assert abs(X1[0, 1] - X0[1, 1]) > 0.05  # beside the other cube


def test_pick_and_place_on_itself_shifts_along_y(world):
    X0 = world.reset(X=scene(((0.6, 0.1, 0.025), SMALL), ((0.7, -0.15, 0.025), LARGE)))
    X1, info = world.step(PickPlace(0, 0, 0, 1))
    assert info.status == "ok"
    np.testing.assert_allclose(X1[0, :3] - X0[0, :3], [0.0, 0.075, 0.0], atol=0.01)
    # The bar picked at +1 and released on itself at 0 moves the other way.
    X2, info = world.step(PickPlace(1, 1, 1, 0))
    assert info.status == "ok"
    np.testing.assert_allclose(X2[1, :3] - X1[1, :3], [0.0, -0.075, 0.0], atol=0.01)


@pytest.mark.parametrize("yaw, block", [(0.0, "small"), (np.pi, "small"), (np.pi / 2, "small"), (-np.pi / 2, "small"),
                                        (0.0, "large"), (np.pi, "large"), (0.05 + np.pi, "large")])
def test_offsets_move_toward_world_y_whatever_the_sign_of_the_block_axes(yaw, block):
    """The state has no yaw, so an offset must mean the same for the same X: +1 is +7.5 cm along
    world +y for a cube turned by any multiple of 90 degrees and for a bar turned by 180 degrees."""
    from pydrake.math import RigidTransform, RotationMatrix

    from tamp.sim.skill import Scene, grasp_pose

    t = vocabulary.SMALL if block == "small" else vocabulary.LARGE
    scene_ = Scene(np.array([t]), [RigidTransform(RotationMatrix.MakeZRotation(yaw), [0.6, 0.1, 0.025])])
    axis = scene_.offset_axis_xy(0)
    assert axis[1] > 0.99
    p = grasp_pose(scene_, PickPlace(0, 1, 0, 0), WorldConfig()).translation()
    np.testing.assert_allclose(p[:2], [0.6 + 0.075 * axis[0], 0.1 + 0.075 * axis[1]], atol=1e-9)
    assert abs(p[1] - 0.175) < 0.075 * (1 - np.cos(0.05)) + 1e-9


def test_a_bar_across_y_offsets_toward_world_x():
    from pydrake.math import RigidTransform, RotationMatrix

    from tamp.sim.skill import Scene

    for yaw in (np.pi / 2, -np.pi / 2):
        X_WB = RigidTransform(RotationMatrix.MakeZRotation(yaw), [0.6, 0.0, 0.025])
        bar = Scene(np.array([vocabulary.LARGE]), [X_WB])
        np.testing.assert_allclose(bar.offset_axis_xy(0), [1.0, 0.0], atol=1e-9)


@pytest.mark.parametrize("block", ["small", "large"])
def test_a_tipped_block_is_gripped_across_the_faces_that_stand(block):
    """A block tipped onto its side (its y axis standing) is gripped and offset along an axis that lies on the
    table: not along the few-millimetre projection of the standing one, which turned the jaws across a cube's
    corners so that the descent collided."""
    from pydrake.math import RigidTransform, RollPitchYaw

    from tamp.sim.skill import Scene

    t = vocabulary.SMALL if block == "small" else vocabulary.LARGE
    for roll, heading in ((-np.pi / 2, 0.3), (np.pi / 2 - 1e-3, -0.2)):
        pose = RigidTransform(RollPitchYaw(roll, 0.0, heading), [0.6, 0.1, 0.025])
        tipped = Scene(np.array([t]), [pose])
        jaws = tipped.yaw(0)
        assert abs(np.sin(2 * (jaws - heading))) < 1e-6  # the jaws square to the faces (a quarter turn either way)
        axis = tipped.offset_axis_xy(0)
        assert np.linalg.norm(axis) == pytest.approx(1.0)
        assert abs(np.sin(2 * (np.arctan2(axis[1], axis[0]) - heading))) < 1e-6  # along a face normal


def test_a_cube_tipped_on_its_side_is_picked(world):
    from pydrake.math import RigidTransform, RollPitchYaw

    from tamp.sim.kinematics import Q_HOME
    from tamp.sim.skill import Scene

    world.reset(X=scene(((0.45, -0.08, 0.025), SMALL), ((0.7, 0.2, 0.025), LARGE)))
    tipped = RigidTransform(RollPitchYaw(-np.pi / 2, 0.0, 0.007), [0.452, -0.083, 0.025])
    world.set_scene(Scene(np.array([vocabulary.SMALL, vocabulary.LARGE]), [tipped, world.scene.X_WB[1]]), Q_HOME)
    X1, info = world.step(PickPlace(0, 0, 0, 1))
    assert info.status == "ok" and info.grasped == 0, info.reason
    assert X1[0, 1] == pytest.approx(-0.083 + 0.075, abs=0.01)


def test_grasp_beside_a_cube_grasps_nothing(world):
    X0 = world.reset(X=scene(((0.6, 0.1, 0.025), SMALL), ((0.7, -0.15, 0.025), LARGE)))
    X1, info = world.step(PickPlace(0, 1, 1, 0))
    assert info.status == "nothing_grasped" and info.grasped == -1
    assert "nothing" in info.reason
    np.testing.assert_array_equal(X1, X0)


def test_target_out_of_reach_is_an_ik_failure_and_changes_nothing(world):
    X0 = world.reset(X=scene(((0.6, 0.1, 0.025), SMALL), ((1.6, -0.1, 0.025), SMALL)))
    X1, info = world.step(PickPlace(0, 0, 1, 0))
    assert info.status == "ik_failure"
    assert False in info.ik_success.values()
    assert "IK" in info.reason
    np.testing.assert_array_equal(X1, X0)
    # Picking the unreachable block fails the same way.
    X2, info = world.step(PickPlace(1, 0, 0, 0))
    assert info.status == "ik_failure" and info.ik_success["pregrasp"] is False
    np.testing.assert_array_equal(X2, X0)


def test_grasp_blocked_by_a_block_on_top_changes_nothing(world):
    world.reset(X=scene(((0.6, 0.1, 0.025), SMALL), ((0.7, -0.15, 0.025), LARGE)))
    X1, info = world.step(PickPlace(0, 0, 1, 0))  # cube onto the bar's centre
    assert info.status == "ok"
    X2, info = world.step(PickPlace(1, 0, 0, 0))  # the bar under the cube
    assert info.status == "motion_failure"
    assert "collision" in info.reason
    np.testing.assert_array_equal(X2, X1)


def test_block_resting_on_the_picked_bar_is_carried_along(world):
    world.reset(X=scene(((0.6, 0.1, 0.025), SMALL), ((0.7, -0.15, 0.025), LARGE), ((0.5, -0.2, 0.025), LARGE)))
    X1, _ = world.step(PickPlace(0, 0, 1, -1))  # cube on the bar's -y end
    X2, info = world.step(PickPlace(1, 1, 2, 0))  # bar held at its +y end onto the other bar
    assert info.status == "ok" and info.carried == [1, 0]
    np.testing.assert_allclose(X2[0, :2] - X2[1, :2], X1[0, :2] - X1[1, :2], atol=0.01)
    assert X2[0, 2] == pytest.approx(X1[0, 2] + BAR_HEIGHT, abs=0.01)


def test_a_bar_placed_end_to_end_against_a_cube_can_be_picked_again(world):
    """The skill leaves the bar's end face on the cube's face; lifting it straight up slides past the
    cube (the carried box is narrowed by `carried_inset`), and so does lifting the cube."""
    world.reset(X=scene(((0.834, 0.066, 0.025), LARGE), ((0.47, 0.295, 0.025), SMALL)))
    X1, info = world.step(PickPlace(0, 1, 1, -1))  # bar held 7.5 cm off centre, released 7.5 cm off the cube
    assert info.status == "ok"
    assert X1[1, 1] - X1[0, 1] == pytest.approx((BLOCK_SIZES[0][1] + BLOCK_SIZES[1][1]) / 2, abs=0.004)  # touching
    for action in (PickPlace(0, 1, 0, 0), PickPlace(1, 0, 1, 1)):
        world.reset(X=X1)
        X2, info = world.step(action)
        assert info.status == "ok", info.reason
        assert np.linalg.norm(X2[action.pick, :2] - X1[action.pick, :2]) > 0.05  # it moved


def _check_path(checker_planner, path, joint_step=1e-3):
    assert np.all(path >= Q_LOWER) and np.all(path <= Q_UPPER)
    return checker_planner.path_is_valid(path, joint_step)


def test_every_planned_motion_is_collision_free_at_fine_resolution():
    """Replays each motion of random actions against a separate, unpadded checker."""
    world = World(WorldConfig(), seed=3)
    rng = np.random.default_rng(3)
    world.reset(n_objects=3)
    checker = MotionPlanner(build_motion_scene(world.scene.types, padding=0.0), joint_step=1e-3, padding=0.0)
    checked = 0
    for _ in range(8):
        actions = world.actions()
        before = list(world.scene.X_WB)
        X, info = world.step(actions[rng.integers(len(actions))])
        if info.status != "ok":
            continue
        after = list(world.scene.X_WB)
        X_WGrasp = tcp_pose(info.paths["descend"][-1])
        carried = tuple(info.carried)
        attached = [(BLOCK_SIZES[int(world.scene.types[c])], X_FlangeTcp @ X_WGrasp.inverse() @ before[c])
                    for c in carried]
        checker.detach()
        checker.set_block_poses(before)
        for m in ("approach", "descend"):
            assert _check_path(checker, info.paths[m]), m
        checker.set_block_poses(before, parked=carried)
        assert _check_path(checker, info.paths["liftoff"])
        checker.attach(attached)
        for m in ("lift", "transfer", "lower"):
            assert _check_path(checker, info.paths[m]), m
        checker.detach()
        checker.set_block_poses(after, parked=carried)
        assert _check_path(checker, info.paths["retreat"])
        checked += 1
    assert checked >= 2


def test_same_seed_same_outcomes():
    def rollout(seed):
        world = World(WorldConfig(), seed=seed)
        rng = np.random.default_rng(seed)
        states = [world.reset(n_objects=3)]
        statuses = []
        for _ in range(4):
            actions = world.actions()
            X, info = world.step(actions[rng.integers(len(actions))])
            states.append(X)
            statuses.append(info.status)
        return np.array(states), statuses

    a, sa = rollout(11)
    b, sb = rollout(11)
    np.testing.assert_array_equal(a, b)
    assert sa == sb
    c, _ = rollout(12)
    assert not np.array_equal(a[0], c[0])


def test_random_scene_and_actions(world):
    X = world.reset(n_objects=4)
    assert X.shape == (4, 5)
    assert np.all(X[:, 3:].sum(axis=1) == 1)
    assert np.all((X[:, 0] >= 0.44) & (X[:, 0] <= 0.86))
    actions = world.actions()
    assert len(actions) == 9 * 4**2 == len(set(actions))


def test_layouts_of_the_most_blocks_fit_the_workspace_within_reach():
    """MAX_OBJECTS blocks, mixed and all bars (the most crowded case, which takes a few layouts): every random
    layout is a scene the world accepts as given (on the table, within reach, no two footprints overlapping)."""
    for p_large, seeds in ((0.5, 100), (1.0, 10)):
        world = World(WorldConfig(p_large=p_large), seed=0)
        for seed in range(seeds):
            world.rng = np.random.default_rng(seed)
            types, positions = world._random_layout(MAX_OBJECTS)
            check_scene(np.concatenate([positions, np.eye(2)[types]], axis=1), upright=True,
                        where=f"layout {seed}")


def test_scenes_of_the_most_blocks_rest_and_random_actions_keep_them_valid():
    """Reset at MAX_OBJECTS blocks settles to resting, upright blocks; random actions from there leave valid
    scenes (on the table or on a block, within reach) and some of them move a block."""
    world = World(WorldConfig(), seed=0)
    rng = np.random.default_rng(0)
    statuses = []
    for seed in range(2):
        X = world.reset(n_objects=MAX_OBJECTS, seed=seed)
        assert X.shape == (MAX_OBJECTS, 5)
        check_scene(X, upright=True, where=f"reset {seed}")
        actions = world.actions()
        assert len(actions) == 9 * MAX_OBJECTS**2
        for step in range(5):
            X_next, info = world.step(actions[rng.integers(len(actions))])
            check_scene(X_next, where=f"reset {seed} step {step}")
            statuses.append(info.status)
    assert "ok" in statuses


@pytest.mark.parametrize(
    "action, message",
    [
        ((5, 0, 1, 0), "pick object index 5"),
        ((0, 0, -1, 0), "place object index -1"),
        ((0, 2, 1, 0), "grasp_offset"),
        ((0, 0, 1, -2), "release_offset"),
        ((0, 0, 1), "4 integers"),
        (("a", 0, 1, 0), "4 integers"),
        ((0.5, 0, 1, 0), "4 integers"),
    ],
)
def test_bad_actions_raise_clear_errors(world, action, message):
    world.reset(n_objects=2)
    with pytest.raises(ValueError, match=message):
        world.step(action)


@pytest.mark.parametrize(
    "X, message",
    [
        (np.zeros((3, 4)), "shape"),
        (np.array([[0.6, 0.1, 0.025, 1.0, 1.0]]), "one-hot"),
        (np.array([[0.6, 0.1, np.nan, 1.0, 0.0]]), "NaN"),
        (np.array([[5.0, 0.1, 0.025, 1.0, 0.0]]), "off the table"),
        (np.array([[0.6, 0.1, 0.025, 1.0, 0.0], [0.61, 0.1, 0.025, 1.0, 0.0]]), "overlap"),
        (np.array([[0.6, 0.1, -0.2, 1.0, 0.0]]), "inside the table"),
    ],
)
def test_malformed_scenes_raise_clear_errors(world, X, message):
    with pytest.raises(ValueError, match=message):
        world.reset(X=X)


def test_reset_argument_errors(world):
    with pytest.raises(ValueError, match="exactly one"):
        world.reset()
    with pytest.raises(ValueError, match="n_objects"):
        world.reset(n_objects=0)
    with pytest.raises(ValueError, match="fidelity"):
        WorldConfig(fidelity="slow")
