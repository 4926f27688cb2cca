"""UR10e inverse kinematics: closed form (ur-analytic-ik) on a fixed branch, Drake IK as fallback.

Top-down grasps are solved on one branch, elbow up and wrist down, and each joint is wrapped by
multiples of 2 pi to the value nearest the current configuration: choosing among all eight
solutions by joint distance alone can flip the elbow or wrist between waypoints.
"""
from __future__ import annotations

import functools
from typing import Callable

import numpy as np
import ur_analytic_ik
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.inverse_kinematics import InverseKinematics
from pydrake.multibody.plant import MultibodyPlant
from pydrake.solvers import Solve

from tamp.sim.plants import X_FlangeTcp, X_WBase

# Joint limits (radians) and velocity limits (rad/s) of drake_models/ur10e.urdf.
Q_LOWER = np.array([-2 * np.pi, -2 * np.pi, -np.pi, -2 * np.pi, -2 * np.pi, -2 * np.pi])
Q_UPPER = -Q_LOWER
V_MAX = np.array([2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416])
# How a waypoint's configuration was found: the closed form on the branch, or Drake's numerical IK
# (constrained to the same branch) where the closed form has none.
IK_SOLVERS = ("closed form", "numerical")
BRANCH = "elbow up, wrist down"  # the one IK branch of every top-down grasp (`on_branch`)
# Home: upper arm up, forearm forward, tool pointing down over the table.
Q_HOME = np.array([0.0, -np.pi / 2, np.pi / 2, -np.pi / 2, -np.pi / 2, 0.0])

_X_BaseW = X_WBase.inverse()
_X_TcpFlange = X_FlangeTcp.inverse()


def flange_pose_in_base(X_WTcp: RigidTransform) -> np.ndarray:
    """4x4 pose of the flange (DH frame 6) in the arm's base frame for a tcp pose in the world."""
    return (_X_BaseW @ X_WTcp @ _X_TcpFlange).GetAsMatrix4()


def tcp_pose(q: np.ndarray) -> RigidTransform:
    """Forward kinematics of the tcp in the world frame (closed form)."""
    T = ur_analytic_ik.ur10e.forward_kinematics(*np.asarray(q, dtype=float))
    return X_WBase @ RigidTransform(T) @ X_FlangeTcp


def on_branch(q: np.ndarray) -> bool:
    """Elbow up and wrist down, the branch of Q_HOME, with the shoulder facing the table."""
    return bool(np.sin(q[2]) > 0.0 and np.sin(q[4]) < 0.0)


def _wrap_near(q: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    """Rows of q (m, 6) shifted per joint by multiples of 2 pi to be nearest q_ref, then into the
    limits where a shift of 2 pi allows; rows still outside the limits are NaN."""
    q = q_ref + (q - q_ref + np.pi) % (2 * np.pi) - np.pi
    q = np.where(q > Q_UPPER, q - 2 * np.pi, q)
    q = np.where(q < Q_LOWER, q + 2 * np.pi, q)
    outside = np.any((q < Q_LOWER - 1e-9) | (q > Q_UPPER + 1e-9), axis=1)
    q[outside] = np.nan
    return q


def analytic_ik(X_WTcp: RigidTransform, q_ref: np.ndarray) -> np.ndarray | None:
    """The on-branch closed-form solution nearest q_ref, or None when there is none (all eight
    solutions filtered at once: this runs inside the planners' feasibility check). Answers are
    remembered per (pose, q_ref): the search checks the same pick from the same arm configuration
    for every place of a grasp, and four in ten of its calls repeat one made before."""
    q_ref = np.asarray(q_ref, dtype=float)
    q = _analytic_ik_memo(flange_pose_in_base(X_WTcp).tobytes() + q_ref.tobytes())
    return None if q is None else q.copy()


def forget_ik_answers() -> None:
    """Empty `analytic_ik`'s memory (benchmarks, so that a timed call starts as a fresh process would)."""
    _analytic_ik_memo.cache_clear()


@functools.lru_cache(maxsize=1 << 16)
def _analytic_ik_memo(key: bytes) -> np.ndarray | None:
    """`analytic_ik` of a key made of the flange pose in the base frame (4x4) and q_ref (6), as bytes."""
    values = np.frombuffer(key, dtype=float)
    T, q_ref = values[:16].reshape(4, 4), values[16:]
    solutions = np.asarray(ur_analytic_ik.ur10e.inverse_kinematics(T), dtype=float)
    if solutions.size == 0:
        return None
    solutions = solutions.reshape(-1, 6)
    keep = np.all(np.isfinite(solutions), axis=1) & (np.sin(solutions[:, 2]) > 0.0) & (np.sin(solutions[:, 4]) < 0.0)
    if not keep.any():
        return None
    q = _wrap_near(solutions[keep], q_ref)
    dist = np.linalg.norm(q - q_ref, axis=1)
    dist[np.isnan(dist)] = np.inf  # wrapped out of the joint limits
    best = int(np.argmin(dist))
    return None if np.isinf(dist[best]) else q[best]


def solve_chain(
    waypoints: list[tuple[str, RigidTransform]],
    q_start: np.ndarray,
    fallback: Callable[[RigidTransform, np.ndarray], np.ndarray | None] | None = None,
    solvers: dict[str, str] | None = None,
) -> tuple[dict[str, np.ndarray], str | None]:
    """Joint configurations of tcp poses solved in order, each on the branch and nearest the one
    before (the first nearest q_start); `fallback(X_WTcp, q_ref)` (e.g. numerical IK) is tried when
    the closed form has no solution. Returns (configurations found, name of the first pose without
    a solution or None); `solvers`, if given, gets which solver found each pose (IK_SOLVERS).
    Shared by the skill (`World.step`) and the feasibility check."""
    qs: dict[str, np.ndarray] = {}
    q_prev = q_start
    for name, X_WTcp in waypoints:
        q, solver = analytic_ik(X_WTcp, q_prev), IK_SOLVERS[0]
        if q is None and fallback is not None:
            q, solver = fallback(X_WTcp, q_prev), IK_SOLVERS[1]
        if q is None:
            return qs, name
        qs[name] = q_prev = q
        if solvers is not None:
            solvers[name] = solver
    return qs, None


def drake_ik(
    plant: MultibodyPlant,
    arm_position_indices: np.ndarray,
    X_WTcp: RigidTransform,
    q_seed_full: np.ndarray,
    tcp_frame,
    position_tolerance: float = 1e-3,
    angle_tolerance: float = 1e-2,
) -> np.ndarray | None:
    """Numerical IK on the motion plant, seeded at q_seed_full, for poses the branch cannot reach
    exactly (e.g. near a singularity). Returns the 6 arm joints or None."""
    ik = InverseKinematics(plant)
    p = X_WTcp.translation()
    tol = np.full(3, position_tolerance)
    # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
    ik.AddPositionConstraint(tcp_frame, np.zeros(3), plant.world_frame(), p - tol, p + tol)  # type: ignore[arg-type]
    ik.AddOrientationConstraint(
        plant.world_frame(), X_WTcp.rotation(), tcp_frame, RotationMatrix(), angle_tolerance
    )
    q_vars = ik.q()
    prog = ik.prog()
    # Other bodies (free blocks) stay where they are.
    others = np.setdiff1d(np.arange(plant.num_positions()), arm_position_indices)
    prog.AddBoundingBoxConstraint(q_seed_full[others], q_seed_full[others], q_vars[others])
    prog.AddQuadraticErrorCost(np.eye(len(arm_position_indices)),  # type: ignore[arg-type]  # pydrake stubs, as above
                               q_seed_full[arm_position_indices], q_vars[arm_position_indices])
    prog.SetInitialGuess(q_vars, q_seed_full)  # type: ignore[arg-type]  # pydrake stubs, as above
    result = Solve(prog)
    if not result.is_success():
        return None
    q = result.GetSolution(q_vars)[arm_position_indices]
    if np.any(q < Q_LOWER) or np.any(q > Q_UPPER) or not on_branch(q):
        return None
    return q

