"""The UR10e model's kinematics agree with the closed-form solver it is paired with."""
import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from tamp.sim.kinematics import Q_HOME, Q_LOWER, Q_UPPER, analytic_ik, on_branch, tcp_pose
from tamp.sim.plants import build_motion_scene

pytestmark = pytest.mark.sim  # every test here builds Drake plants


@pytest.fixture(scope="module")
def scene():
    return build_motion_scene(np.array([0]), padding=0.0)


def test_drake_forward_kinematics_matches_analytic(scene):
    plant = scene.plant
    ctx = plant.CreateDefaultContext()
    tcp = plant.GetFrameByName("tcp")
    rng = np.random.default_rng(0)
    for _ in range(50):
        q_arm = rng.uniform(-np.pi, np.pi, 6)
        q = np.zeros(plant.num_positions())
        q[:6] = q_arm
        q[6] = 1.0  # block quaternion
        plant.SetPositions(ctx, q)
        X_drake = plant.CalcRelativeTransform(ctx, plant.world_frame(), tcp)
        np.testing.assert_allclose(X_drake.GetAsMatrix4(), tcp_pose(q_arm).GetAsMatrix4(), atol=1e-9)


def test_denavit_hartenberg_lengths():
    # At q = 0 the arm is stretched out along world +x (the base is yawed by pi): the flange is
    # at x = -(a2 + a3), y = d4 + d6, z = d1 - d5. The tcp is 0.125 m beyond it along flange z.
    X = tcp_pose(np.zeros(6))
    flange = X.translation() - X.rotation().matrix()[:, 2] * 0.125
    np.testing.assert_allclose(flange, [0.6127 + 0.57155, 0.17415 + 0.11655, 0.1807 - 0.11985], atol=1e-9)


def test_topdown_ik_round_trip_on_branch():
    rng = np.random.default_rng(1)
    for _ in range(100):
        p = [rng.uniform(0.4, 0.95), rng.uniform(-0.45, 0.45), rng.uniform(0.0, 0.4)]
        R = RotationMatrix.MakeZRotation(rng.uniform(-np.pi, np.pi)) @ RotationMatrix.MakeXRotation(np.pi)
        X = RigidTransform(R, p)
        q = analytic_ik(X, Q_HOME)
        assert q is not None, p
        assert on_branch(q)
        assert np.all(q >= Q_LOWER) and np.all(q <= Q_UPPER)
        np.testing.assert_allclose(tcp_pose(q).GetAsMatrix4(), X.GetAsMatrix4(), atol=1e-8)


def test_ik_out_of_reach_is_none():
    X = RigidTransform(RotationMatrix.MakeXRotation(np.pi), [1.6, 0.0, 0.05])
    assert analytic_ik(X, Q_HOME) is None


def test_remembered_ik_answers_depend_on_pose_and_reference_and_cannot_be_corrupted():
    """analytic_ik remembers its answers: the same pose from another reference configuration still gets the
    solution nearest that reference (wrapped by 2 pi), and a caller changing a returned array changes no later
    answer."""
    X = tcp_pose(Q_HOME + 0.2)
    q = analytic_ik(X, Q_HOME)
    assert q is not None
    q_first = q.copy()
    q[:] = 0.0  # a caller writes into its answer
    np.testing.assert_array_equal(analytic_ik(X, Q_HOME), q_first)
    shifted = Q_HOME - np.array([0.0, 0.0, 0.0, 0.0, 0.0, 2 * np.pi])  # the wrist within its limits either way
    q_shifted = analytic_ik(X, shifted)
    assert q_shifted is not None
    np.testing.assert_allclose(q_shifted, q_first - [0, 0, 0, 0, 0, 2 * np.pi], atol=1e-12)
