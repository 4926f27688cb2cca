"""Plain data of the simulated world: its configuration and what one step did.

Lengths are metres, angles radians, times seconds.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

from tamp.errors import UserError
from tamp.planning.vocabulary import PickPlace


class Fidelity(StrEnum):
    """How a World executes a step."""

    FAST = "fast"  # the refinement's own world: kinematic carry, physics settles the released blocks
    FULL = "full"  # the arm follows the timed trajectory under physics


FIDELITIES = tuple(f.value for f in Fidelity)  # as command lines and files spell them


def fidelity_of(value: str, what: str = "fidelity") -> Fidelity:
    """`value` as a Fidelity; a UserError naming `what` otherwise."""
    try:
        return Fidelity(value)
    except ValueError:
        raise UserError(f"{what} must be one of {', '.join(Fidelity)}, got {value!r}") from None


@dataclass(frozen=True)
class WorldConfig:
    """Configuration of the block world. All lengths in metres, times in seconds."""

    # "fast": planned and checked arm motion, kinematic carry, physics after release;
    # "full": the arm follows the time-parameterized plan under physics (tamp/execute.py)
    fidelity: str = "fast"
    workspace_x: tuple[float, float] = (0.45, 0.85)  # random scenes: block centres in this box
    workspace_y: tuple[float, float] = (-0.30, 0.30)
    min_separation: float = 0.04  # gap between random blocks' footprints (the jaws need 2.7 cm)
    p_large: float = 0.5  # probability that a random block is a large bar
    approach_height: float = 0.12  # pre-grasp and retreat: above the grasp / release pose
    carry_clearance: float = 0.10  # lift: carried block's bottom this far above the tallest block
    release_clearance: float = 0.005  # released block's bottom above the support surface
    grasp_depth: float = 0.025  # tcp below the grasped block's top
    lift_off: float = 0.01  # first, straight-up part of the lift that frees the block from its support
    time_step: float = 0.002  # physics step
    settle_speed: float = 0.005  # m/s: a block moving slower than this (and turning slower than
    settle_angular_speed: float = 0.05  # rad/s this) is at rest
    settle_window: float = 0.03  # all blocks at rest this long means the scene settled
    settle_max_time: float = 2.0  # cap on simulated settling time
    planning_checks: int = 20_000  # RRTConnect's budget of collision checks per motion (deterministic)
    planning_time: float = 5.0  # wall-clock cap per motion, a safety net behind the check budget
    direct_motions: bool = True  # try the straight joint-space segment before RRTConnect
    simplify_paths: bool = False  # OMPL path simplification (costly; for executed motions)
    joint_step: float = 0.005  # radians between collision checks along a motion
    padding: float = 0.002  # collision padding of the motion checker
    # A carried block's collision box is this much narrower on each side (not in height), so a block
    # standing against another one (the skill places blocks face to face) lifts straight up past it.
    carried_inset: float = 0.003

    def __post_init__(self) -> None:
        fidelity_of(self.fidelity, "WorldConfig.fidelity")
        if not 0.0 <= self.carried_inset < 0.02:
            raise UserError(f"WorldConfig.carried_inset must be in [0, 0.02) metres, got {self.carried_inset}")
        for name in ("workspace_x", "workspace_y"):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise UserError(f"WorldConfig.{name} must be (low, high) with low < high, got {(lo, hi)}")
        if not 0.0 <= self.p_large <= 1.0:
            raise UserError(f"WorldConfig.p_large must be in [0, 1], got {self.p_large}")
        if self.time_step <= 0 or self.settle_max_time <= 0:
            raise UserError("WorldConfig.time_step and settle_max_time must be positive")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


class StepStatus(StrEnum):
    """What one `World.step` did. Datasets store the index in STATUSES (stable across versions)."""

    OK = "ok"  # the action was carried out
    IK_FAILURE = "ik_failure"  # a waypoint has no IK solution: nothing moved
    MOTION_FAILURE = "motion_failure"  # a motion found no collision-free path: nothing moved
    NOTHING_GRASPED = "nothing_grasped"  # the jaws closed on nothing: nothing moved


# Outcome codes, stable across versions (datasets store the integer).
STATUSES = tuple(s.value for s in StepStatus)


@dataclass
class ExecutedAction:
    """What one action did under full physics."""

    index: int
    X_before: np.ndarray
    X_after: np.ndarray  # at rest after the action
    X_predicted: np.ndarray  # what refinement (the fast world) predicted
    grasped: bool  # the weld engaged
    max_tracking_error: float  # radians, max over joints and time
    settle_time: float  # simulated seconds after the trajectory until at rest
    settled: bool
    sim_time: float  # simulated seconds, trajectory plus settling
    wall_time: float  # seconds
    note: str = ""

    @property
    def prediction_error(self) -> float:
        """Largest per-object distance between executed and predicted positions (metres)."""
        return float(np.max(np.linalg.norm(self.X_after[:, :3] - self.X_predicted[:, :3], axis=1)))

    def to_dict(self) -> dict:
        return {"index": self.index, "grasped": self.grasped, "note": self.note,
                "prediction_error_m": round(self.prediction_error, 4),
                "max_tracking_error_rad": round(self.max_tracking_error, 5),
                "settle_time_s": round(self.settle_time, 3), "settled": self.settled,
                "sim_time_s": round(self.sim_time, 3), "wall_time_s": round(self.wall_time, 3),
                "X_after": np.round(self.X_after, 4).tolist()}


@dataclass
class StepInfo:
    """What happened during one `World.step`.

    `reason` says in words why an action changed nothing.
    """

    action: PickPlace
    status: StepStatus = StepStatus.OK
    reason: str = ""
    ik_success: dict[str, bool] = field(default_factory=dict)  # waypoint name -> IK found
    motion_success: dict[str, bool] = field(default_factory=dict)  # motion name -> path found
    ik_solver: dict[str, str] = field(default_factory=dict)  # waypoint -> kinematics.IK_SOLVERS entry
    motion_planner: dict[str, str] = field(default_factory=dict)  # motion -> "direct" (straight) or "rrtconnect"
    motion_seconds: dict[str, float] = field(default_factory=dict)  # motion -> wall-clock planning seconds
    grasped: int = -1  # object actually carried (-1: none)
    carried: list[int] = field(default_factory=list)  # grasped object and blocks resting on it
    settle_time: float = 0.0  # simulated seconds until the scene was at rest
    settled: bool = True  # False if the settle cap was hit
    timings: dict[str, float] = field(default_factory=dict)  # wall-clock seconds per stage
    paths: dict[str, np.ndarray] = field(default_factory=dict)  # motion name -> (m, 6) joint path
    q_waypoints: dict[str, np.ndarray] = field(default_factory=dict)  # waypoint name -> arm joints
    X_GC: list = field(default_factory=list)  # carried blocks' poses in the tcp frame (RigidTransform)
    X_release: np.ndarray | None = None  # scene at the moment of release (before physics)
    X_predicted: np.ndarray | None = None  # full fidelity: the fast world's outcome of the same plan
    execution: ExecutedAction | None = None  # full fidelity: what the action did under physics

    @property
    def changed(self) -> bool:
        return self.status == StepStatus.OK

    def to_dict(self) -> dict:
        record = {
            "action": list(self.action),
            "status": self.status.value if isinstance(self.status, StepStatus) else self.status,
            "reason": self.reason,
            "ik_success": dict(self.ik_success),
            "motion_success": dict(self.motion_success),
            "ik_solver": dict(self.ik_solver),
            "motion_planner": dict(self.motion_planner),
            "grasped": self.grasped,
            "carried": list(self.carried),
            "settle_time": round(self.settle_time, 4),
            "settled": self.settled,
            "timings": {**{k: round(v, 5) for k, v in self.timings.items()},
                        **{f"motion_{k}": round(v, 5) for k, v in self.motion_seconds.items()}},
        }
        if self.execution is not None:
            record["execution"] = self.execution.to_dict()
        return record
