"""Time parameterization of joint paths and the refined plan structures built from them.

Every motion the skill plans is a polyline in joint space that was collision-checked segment by
segment, so the trajectory follows exactly that polyline: each straight segment gets the
time-optimal profile under the joint velocity and acceleration limits, starting and ending at rest
(on a straight joint-space segment with box limits this is the trapezoid TOPPRA converges to;
tests/tamp/sim/test_refine.py compares the two). The result is piecewise quadratic and stored as a Drake
`PiecewisePolynomial` (cubic Hermite through the phase boundaries reproduces it exactly).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING

import numpy as np
from pydrake.math import RigidTransform
from pydrake.trajectories import PiecewisePolynomial

from tamp.planning.vocabulary import PickPlace
from tamp.sim.kinematics import V_MAX
from tamp.sim.world_types import StepInfo

if TYPE_CHECKING:
    from tamp.sim.skill import Scene

# Joint acceleration limits (rad/s^2): the data sheet gives none; a conservative value that the
# arm tracks closely under the PD controller with a carried block.
A_MAX = np.full(6, 3.0)
GRASP_DWELL = 0.25  # seconds still at the grasp pose while the jaws close
PLACE_DWELL = 0.25  # seconds still at the place pose before the jaws open: the arm settles onto it
RELEASE_DWELL = 0.25  # seconds still at the place pose after the jaws open
CARRY_MOTIONS = ("liftoff", "lift", "transfer", "lower")
MOTION_ORDER = ("approach", "descend", "liftoff", "lift", "transfer", "lower", "retreat")


def segment_profile(q_a: np.ndarray, q_b: np.ndarray, v_max: np.ndarray, a_max: np.ndarray):
    """Knots (t, q, qdot) of the rest-to-rest time-optimal motion along the segment q_a -> q_b."""
    d = q_b - q_a
    with np.errstate(divide="ignore"):
        v = float(np.min(np.where(np.abs(d) > 0, v_max / np.abs(d), np.inf)))  # path speed limit (1/s)
        a = float(np.min(np.where(np.abs(d) > 0, a_max / np.abs(d), np.inf)))  # path acceleration limit
    if not np.isfinite(v):
        return [(0.0, q_a, np.zeros(6))]
    if v * v / a >= 1.0:  # triangle: never reaches the speed limit
        t_half = np.sqrt(1.0 / a)
        s_dot = a * t_half
        return [(0.0, q_a, 0 * d), (t_half, q_a + 0.5 * d, s_dot * d), (2 * t_half, q_b, 0 * d)]
    t_acc = v / a
    s_acc = 0.5 * a * t_acc**2
    t_cruise = (1.0 - 2 * s_acc) / v
    return [
        (0.0, q_a, 0 * d),
        (t_acc, q_a + s_acc * d, v * d),
        (t_acc + t_cruise, q_b - s_acc * d, v * d),
        (2 * t_acc + t_cruise, q_b, 0 * d),
    ]


class TrajectoryBuilder:
    """Appends timed motions and dwells, then builds one PiecewisePolynomial."""

    def __init__(self, q0: np.ndarray, t0: float = 0.0, v_max: np.ndarray = V_MAX, a_max: np.ndarray = A_MAX):
        self.times = [t0]
        self.q = [np.asarray(q0, dtype=float)]
        self.qdot = [np.zeros(6)]
        self._v_max, self._a_max = v_max, a_max

    @property
    def t(self) -> float:
        return self.times[-1]

    def _knot(self, t: float, q: np.ndarray, qdot: np.ndarray) -> None:
        if t <= self.times[-1] + 1e-9:
            return  # zero-length: the knot is already there
        self.times.append(t)
        self.q.append(np.asarray(q, dtype=float))
        self.qdot.append(np.asarray(qdot, dtype=float))

    def add_path(self, path: np.ndarray) -> tuple[float, float]:
        """Follow a joint polyline from the current end (which must equal path[0]); returns the
        (start, end) times of the motion."""
        if np.max(np.abs(path[0] - self.q[-1])) > 1e-6:
            raise ValueError("a path must start where the trajectory ends")
        t_start = self.t
        for q_a, q_b in zip(path[:-1], path[1:]):
            t0 = self.t
            for dt, q, qdot in segment_profile(q_a, q_b, self._v_max, self._a_max)[1:]:
                self._knot(t0 + dt, q, qdot)
        return t_start, self.t

    def dwell(self, duration: float) -> None:
        self._knot(self.t + duration, self.q[-1], np.zeros(6))

    def build(self) -> PiecewisePolynomial:
        if len(self.times) == 1:
            self.dwell(1e-3)
        return PiecewisePolynomial.CubicHermite(np.array(self.times), np.array(self.q).T, np.array(self.qdot).T)


@dataclass
class RefinedAction:
    """One pick-place made concrete: waypoint configurations, checked paths and timing."""

    action: PickPlace
    q: dict[str, np.ndarray]  # waypoint name -> arm joints (rad)
    paths: dict[str, np.ndarray]  # motion name -> (m, 6) joint polyline
    grasped: int
    carried: list[int]
    X_GC: list[RigidTransform]  # carried blocks' poses in the tcp frame
    X_before: np.ndarray  # state before, and as the fast world predicts it after
    X_after: np.ndarray
    trajectory: PiecewisePolynomial  # starts at t = 0 at the action's first configuration
    motion_times: dict[str, tuple[float, float]]  # motion name -> (start, end) in trajectory time
    t_grasp: float  # jaws closed (weld on)
    t_release: float  # jaws open (weld off)
    refine_time: float = 0.0  # wall-clock seconds

    @property
    def duration(self) -> float:
        return self.trajectory.end_time()


def refined_action(action: PickPlace, info, X_before: np.ndarray, X_after: np.ndarray,
                   q_start: np.ndarray) -> RefinedAction:
    """Time-parameterize the motions of a successful StepInfo (see World.step)."""
    builder = TrajectoryBuilder(q_start)
    times = {}
    for name in MOTION_ORDER:
        times[name] = builder.add_path(info.paths[name])
        if name == "descend":
            builder.dwell(GRASP_DWELL)
            t_grasp = builder.t
        if name == "lower":
            builder.dwell(PLACE_DWELL)
            t_release = builder.t
            builder.dwell(RELEASE_DWELL)
    return RefinedAction(
        action=action, q=dict(info.q_waypoints), paths=dict(info.paths), grasped=info.grasped,
        carried=list(info.carried), X_GC=list(info.X_GC), X_before=X_before, X_after=X_after,
        trajectory=builder.build(), motion_times=times, t_grasp=t_grasp, t_release=t_release,
    )


class FailureStage(StrEnum):
    """The stage at which an action could not be refined."""

    IK = "ik"  # a waypoint has no IK solution on the skill's branch
    MOTION = "motion"  # no collision-free path for a motion (or the retreat after release)
    GRASP = "grasp"  # the jaws closed on nothing


@dataclass
class RefinementFailure:
    """Why a plan could not be refined: which action, which waypoint or motion, and why."""

    action_index: int
    action: PickPlace
    stage: FailureStage
    where: str  # waypoint or motion name
    reason: str

    def record(self) -> dict:
        """As an evaluation row and `tamp.planning.causes` store it."""
        return {"action": int(self.action_index), "stage": str(self.stage), "where": self.where, "reason": self.reason}

    def __str__(self) -> str:
        a = self.action
        return (f"action {self.action_index} (pick {a.pick} at {a.grasp_offset:+d}, place on {a.place} at "
                f"{a.release_offset:+d}) failed at {self.stage} [{self.where}]: {self.reason}")


@dataclass
class RefinedPlan:
    """A plan refined action by action from an initial scene. `trajectory` is the whole plan's
    joint trajectory (actions back to back) and exists only when every action was refined."""

    X_init: np.ndarray
    actions: list[PickPlace]
    scene_init: Scene  # the exact initial scene (block poses with orientation)
    q_init: np.ndarray  # arm joints at the start
    steps: list[RefinedAction] = field(default_factory=list)
    infos: list[StepInfo] = field(default_factory=list)  # per action tried: what the skill did (IK, motions)
    failure: RefinementFailure | None = None
    trajectory: PiecewisePolynomial | None = None
    start_times: list[float] = field(default_factory=list)  # each action's start in `trajectory`
    refine_time: float = 0.0

    @property
    def success(self) -> bool:
        return self.failure is None and len(self.steps) == len(self.actions)

    @property
    def X_predicted(self) -> np.ndarray:
        return self.steps[-1].X_after if self.steps else self.X_init


def concatenate(steps: list[RefinedAction]) -> tuple[PiecewisePolynomial, list[float]]:
    """One trajectory for actions executed back to back."""
    builder = TrajectoryBuilder(steps[0].trajectory.value(0.0).ravel())
    starts = []
    for step in steps:
        traj = step.trajectory
        starts.append(builder.t)
        breaks = traj.get_segment_times()
        for t in breaks[1:]:
            builder._knot(starts[-1] + t, traj.value(t).ravel(), traj.EvalDerivative(t, 1).ravel())
    return builder.build(), starts
