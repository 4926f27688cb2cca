"""Trajectory files: the executed plan's joint motion as versioned JSON, to take to a real arm.

A file holds the UR10e's joint names (in the model's order) and the limits they were checked
against, the exact initial scene, and per executed action its motion segments (approach, descend,
the grasp dwell, liftoff, lift, transfer, lower, the release dwell, retreat), each shaped as a ROS
`trajectory_msgs/JointTrajectory` (`joint_names`, `points` with `positions` rad, `velocities`
rad/s, `accelerations` rad/s^2 and `time_from_start` {sec, nanosec}) in plain JSON, and the
gripper's close and open events. Samples lie every SAMPLE_PERIOD and on every knot of the
piecewise-quadratic time parameterization (tamp/sim/trajectory.py), so cubic Hermite interpolation
of positions and velocities between samples reproduces the planned motion exactly. Every motion
starts and ends at rest. docs/trajectories.md describes the format.

Writing and reading check the same things: every sample within the model's position and velocity
limits (read from drake_models/ur10e.urdf) and the acceleration limit A_MAX (the model gives none),
segments and actions continuous in position and velocity where they join; a bad file is one
`TrajectoryError` line. `execute_trajectory` runs a file with the full arm under physics.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
from pydrake.common.eigen_geometry import Quaternion
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.trajectories import PiecewisePolynomial

from tamp.errors import UserError
from tamp.planning.structs import TYPE_NAMES, PickPlace
from tamp.records import atomic_write_text
from tamp.sim.execute import ExecutionResult, Executor
from tamp.sim.observer import WorldObserver
from tamp.sim.plants import ARM_FILE, ARM_JOINTS
from tamp.sim.skill import Scene
from tamp.sim.structs import WorldConfig
from tamp.sim.trajectory import A_MAX, MOTION_ORDER, RefinedAction, RefinedPlan

FORMAT = "tamp-trajectory"
VERSION = 1  # bumped when a reader of the old version would misread a new file
ROBOT = "UR10e"
SAMPLE_PERIOD = 0.02  # s between samples inside a segment, besides the knots of the time parameterization
DECIMALS = 9  # positions, velocities, accelerations, block positions rounded to 1e-9 (rad, rad/s, ..., m)
ROUND_TRIP_TOLERANCE = 0.002  # m: a file recorded in the full world, executed again, ends this close to the record
TOLERANCE = 1e-5  # rad, rad/s, rad/s^2 and s: slack of the limit and continuity checks (rounding)
DWELLS = {"descend": "grasp", "lower": "release"}  # a still segment follows these motions: jaws close / open
ACCELERATION_NOTE = ("the model file gives no acceleration limits: these are tamp's A_MAX "
                     "(tamp/sim/trajectory.py), the limit of the time parameterization")


class TrajectoryError(UserError):
    """A trajectory file (or an executed motion being written) that fails its checks, in one line."""


@dataclass(frozen=True)
class JointLimits:
    """Per joint, in ARM_JOINTS order: positions (rad), speed (rad/s) and acceleration (rad/s^2)."""

    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray

    def to_dict(self) -> dict:
        return {"position_lower": self.lower.tolist(), "position_upper": self.upper.tolist(),
                "velocity": self.velocity.tolist(), "acceleration": self.acceleration.tolist(),
                "acceleration_note": ACCELERATION_NOTE}


@cache
def model_limits() -> JointLimits:
    """The UR10e's limits as Drake parses them from drake_models/ur10e.urdf (acceleration: A_MAX)."""
    plant = MultibodyPlant(0.0)
    (arm,) = Parser(plant).AddModels(ARM_FILE)
    plant.Finalize()
    joints = [plant.get_joint(j) for j in plant.GetJointIndices(arm) if plant.get_joint(j).num_positions() == 1]
    if tuple(j.name() for j in joints) != ARM_JOINTS:
        raise RuntimeError(f"{ARM_FILE}: joints {[j.name() for j in joints]}, expected {list(ARM_JOINTS)}")
    return JointLimits(np.array([j.position_lower_limits()[0] for j in joints]),
                       np.array([j.position_upper_limits()[0] for j in joints]),
                       np.array([j.velocity_upper_limits()[0] for j in joints]), np.array(A_MAX, dtype=float))


@dataclass
class Segment:
    """One motion (or dwell) of an action: samples from its start, all at rest at both ends."""

    name: str
    start: float  # s on the action's clock
    t: np.ndarray  # (m,) s from the segment's start, t[0] = 0
    q: np.ndarray  # (m, 6) rad
    qdot: np.ndarray  # (m, 6) rad/s
    qddot: np.ndarray  # (m, 6) rad/s^2: of the quadratic piece a sample starts (the last sample: ends)

    @property
    def end(self) -> float:
        return self.start + float(self.t[-1])


@dataclass
class ActionMotion:
    """One executed pick-place: its segments back to back from t = 0, the jaws' events and what the
    recorded execution left. The grasp (`block` at `X_GC` in the tcp frame) is what the simulator
    welds when the jaws close; a real gripper just closes."""

    index: int  # the action's place among the run's executed actions (skipped ones included)
    action: PickPlace
    segments: list[Segment]
    t_close: float  # s on the action's clock: the jaws close (the block is held from here)
    t_open: float  # s: the jaws open
    block: int  # the grasped block
    carried: list[int]  # it and the blocks resting on it
    X_GC: RigidTransform  # the grasped block's planned pose in the tcp frame
    X_after: np.ndarray  # (n, 5) the recorded execution's scene after the action, at rest

    @property
    def duration(self) -> float:
        return self.segments[-1].end

    def trajectory(self) -> PiecewisePolynomial:
        """Cubic Hermite through every sample (positions, velocities): the planned motion exactly."""
        times = [0.0]
        q, qdot = [self.segments[0].q[0]], [self.segments[0].qdot[0]]
        for seg in self.segments:
            for k in range(1, len(seg.t)):
                times.append(seg.start + float(seg.t[k]))
                q.append(seg.q[k])
                qdot.append(seg.qdot[k])
        return PiecewisePolynomial.CubicHermite(np.array(times), np.array(q).T, np.array(qdot).T)


@dataclass
class PlanTrajectory:
    """The executed motion of a run, from its exact initial scene (see the module docstring)."""

    scene_init: Scene
    q_init: np.ndarray  # rad
    actions: list[ActionMotion]
    world: str  # fidelity of the recorded execution ("full": the arm under physics; "fast")
    source: str = ""  # what produced it, e.g. the command line
    skipped: list[dict] = field(default_factory=list)  # executed actions that moved nothing: index, action, reason
    limits: JointLimits = field(default_factory=model_limits)

    @property
    def X_final(self) -> np.ndarray:
        """The recorded execution's final scene (n, 5)."""
        return self.actions[-1].X_after if self.actions else self.scene_init.X()

    @property
    def samples(self) -> int:
        return sum(len(s.t) for a in self.actions for s in a.segments)


# --- from refined actions --------------------------------------------------------------------------
def _sample_times(a: float, b: float, knots: np.ndarray) -> np.ndarray:
    """Times in [a, b]: its knots, and between two knots equal steps of at most SAMPLE_PERIOD."""
    edges = np.concatenate([[a], knots[(knots > a + 1e-6) & (knots < b - 1e-6)], [b]])
    # (knots closer than a microsecond, a vanishing polyline piece, are one sample: the time stamps are
    # whole nanoseconds, and the motion between them is below the file's resolution)
    edges = edges[np.concatenate([np.diff(edges) > 1e-6, [True]])]
    edges[-1] = b
    parts = [np.linspace(t0, t1, int(np.ceil((t1 - t0) / SAMPLE_PERIOD - 1e-9)) + 1)[:-1]
             for t0, t1 in zip(edges[:-1], edges[1:])]
    return np.concatenate(parts + [[b]])


def segment_intervals(step: RefinedAction) -> list[tuple[str, float, float]]:
    """(name, start, end) of the action's motions and dwells, in order, zero-length ones left out."""
    out = []
    for name in MOTION_ORDER:
        out.append((name, *step.motion_times[name]))
        if name in DWELLS:
            end = step.motion_times[name][1]
            dwell_end = step.t_grasp if name == "descend" else step.motion_times["retreat"][0]
            out.append((DWELLS[name], end, dwell_end))
    return [(name, a, b) for name, a, b in out if b - a > 1e-6]


def action_motion(index: int, step: RefinedAction, X_after: np.ndarray) -> ActionMotion:
    """Sample a refined action's trajectory into segments (see the module docstring)."""
    traj = step.trajectory
    knots = np.array(traj.get_segment_times())
    mids = 0.5 * (knots[1:] + knots[:-1])
    segments = []
    for name, a, b in segment_intervals(step):
        times = _sample_times(a, b, knots)
        t_rel = np.round(times - a, 9)
        # the quadratic piece a sample starts (its last sample: the piece it ends), read at its middle
        piece = np.searchsorted(knots, times + 1e-9, side="right") - 1
        piece[-1] = np.searchsorted(knots, times[-1] - 1e-9, side="right") - 1
        piece = np.clip(piece, 0, len(mids) - 1)
        segments.append(Segment(
            name, a, t_rel, np.array([traj.value(t).ravel() for t in times]),
            np.array([traj.EvalDerivative(t, 1).ravel() for t in times]),
            np.array([traj.EvalDerivative(mids[k], 2).ravel() for k in piece])))
    return ActionMotion(index, PickPlace(*step.action), segments, step.t_grasp, step.t_release, step.grasped,
                        list(step.carried), step.X_GC[0], np.asarray(X_after, dtype=float))


# --- checks ------------------------------------------------------------------------------------------
def check(plan: PlanTrajectory, limits: JointLimits, where: str) -> None:
    """Times increasing, samples within `limits`, continuity at every join; TrajectoryError naming
    `where` (the file), the action, segment and sample otherwise."""
    q_prev, v_prev, prev = np.asarray(plan.q_init), np.zeros(6), "the initial configuration"
    for action in plan.actions:
        t_action = 0.0
        for seg in action.segments:
            at = f"{where}: action {action.index} segment {seg.name!r}"
            if abs(seg.start - t_action) > TOLERANCE:
                raise TrajectoryError(f"{at} starts at {seg.start:.6f} s, where the one before ended at "
                                      f"{t_action:.6f} s")
            if len(seg.t) < 2 or seg.t[0] != 0.0 or np.any(np.diff(seg.t) <= 0):
                raise TrajectoryError(f"{at}: time_from_start must start at 0 and increase, over 2 or more points")
            for what, before, now in (("position", q_prev, seg.q[0]), ("velocity", v_prev, seg.qdot[0])):
                jump = float(np.max(np.abs(now - before)))
                if jump > TOLERANCE:
                    raise TrajectoryError(f"{at} starts {jump:.3g} away in {what} from where {prev} ended "
                                          "(rad, rad/s): segments must join continuously")
            for what, values, lo, hi, unit in (
                    ("position", seg.q, limits.lower, limits.upper, "rad"),
                    ("velocity", seg.qdot, -limits.velocity, limits.velocity, "rad/s"),
                    ("acceleration", seg.qddot, -limits.acceleration, limits.acceleration, "rad/s^2")):
                bad = np.argwhere((values < lo - TOLERANCE) | (values > hi + TOLERANCE))
                if len(bad):
                    k, j = bad[0]
                    raise TrajectoryError(f"{at} point {k}: {ARM_JOINTS[j]} {what} {values[k, j]:.6g} {unit} is "
                                          f"outside the UR10e's limits [{lo[j]:.6g}, {hi[j]:.6g}]")
            q_prev, v_prev, prev = seg.q[-1], seg.qdot[-1], f"segment {seg.name!r}"
            t_action = seg.end
        at = f"{where}: action {action.index}"
        if not 0.0 <= action.t_close < action.t_open <= action.duration + TOLERANCE:
            raise TrajectoryError(f"{at}: the jaws must close, then open, within the action's "
                                  f"{action.duration:.3f} s (close {action.t_close:.3f} s, open {action.t_open:.3f} s)")
        n = plan.scene_init.n
        if not (0 <= action.block < n and action.block in action.carried and all(0 <= c < n for c in action.carried)):
            raise TrajectoryError(f"{at}: grasped block {action.block} (carried {action.carried}) is not one of the "
                                  f"scene's {n} blocks")
        if action.X_after.shape != (n, 5):
            raise TrajectoryError(f"{at}: blocks_after must give {n} positions")
        prev = f"action {action.index}"


# --- JSON --------------------------------------------------------------------------------------------
def _duration(t: float) -> dict[str, int]:
    """builtin_interfaces/Duration of t seconds (t >= 0)."""
    ns = int(round(t * 1e9))
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _pose(X: RigidTransform) -> dict[str, list[float]]:
    q = X.rotation().ToQuaternion()
    return {"position": X.translation().tolist(), "quaternion_wxyz": [q.w(), q.x(), q.y(), q.z()]}


def _rounded(a: np.ndarray) -> list:
    return np.round(a, DECIMALS).tolist()


def to_document(plan: PlanTrajectory) -> dict[str, Any]:
    """The file's JSON object (docs/trajectories.md)."""
    names = list(ARM_JOINTS)

    def segment(seg: Segment) -> dict:
        points = [{"positions": _rounded(seg.q[k]), "velocities": _rounded(seg.qdot[k]),
                   "accelerations": _rounded(seg.qddot[k]), "time_from_start": _duration(float(seg.t[k]))}
                  for k in range(len(seg.t))]
        return {"name": seg.name, "start_time": round(float(seg.start), 9),
                "trajectory": {"joint_names": names, "points": points}}

    def action(a: ActionMotion) -> dict:
        return {"index": a.index, "action": list(map(int, a.action)), "duration": round(float(a.duration), 9),
                "segments": [segment(s) for s in a.segments],
                "gripper": [{"event": "close", "time": round(float(a.t_close), 9), "block": a.block,
                             "carried": a.carried, "block_in_tcp": _pose(a.X_GC)},
                            {"event": "open", "time": round(float(a.t_open), 9)}],
                "blocks_after": _rounded(a.X_after[:, :3])}

    scene = plan.scene_init
    return {
        "format": FORMAT, "version": VERSION, "source": plan.source,
        "robot": {"name": ROBOT, "model": f"drake_models/{ARM_FILE.name}", "joint_names": names,
                  "limits": plan.limits.to_dict()},
        "units": {"time": "s", "position": "rad", "velocity": "rad/s", "acceleration": "rad/s^2", "length": "m"},
        "recorded_world": plan.world,
        "scene": {"blocks": [{"type": TYPE_NAMES[int(t)], **_pose(X)} for t, X in zip(scene.types, scene.X_WB)],
                  "arm_positions": np.asarray(plan.q_init, dtype=float).tolist()},
        "actions": [action(a) for a in plan.actions],
        "skipped": plan.skipped,
    }


class _Reader:
    """Typed access to a parsed document; every error names the file and the field."""

    def __init__(self, where: str) -> None:
        self.where = where

    def fail(self, path: str, expected: str) -> TrajectoryError:
        return TrajectoryError(f"{self.where}: {path}: expected {expected}")

    def get(self, obj: Any, key: str, path: str) -> Any:
        if not isinstance(obj, dict):
            raise self.fail(path, "an object")
        if key not in obj:
            raise TrajectoryError(f"{self.where}: {path}: missing field {key!r}")
        return obj[key]

    def list(self, value: Any, path: str) -> list:
        if not isinstance(value, list):
            raise self.fail(path, "a list")
        return value

    def number(self, value: Any, path: str) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise self.fail(path, "a finite number")
        return float(value)

    def integer(self, value: Any, path: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(path, "an integer")
        return value

    def vector(self, value: Any, n: int, path: str) -> np.ndarray:
        items = self.list(value, path)
        if len(items) != n:
            raise self.fail(path, f"{n} numbers, got {len(items)}")
        return np.array([self.number(v, f"{path}[{i}]") for i, v in enumerate(items)])

    def pose(self, obj: Any, path: str) -> RigidTransform:
        p = self.vector(self.get(obj, "position", path), 3, f"{path}.position")
        w = self.vector(self.get(obj, "quaternion_wxyz", path), 4, f"{path}.quaternion_wxyz")
        if abs(np.linalg.norm(w) - 1.0) > 1e-6:
            raise self.fail(f"{path}.quaternion_wxyz", "a unit quaternion")
        return RigidTransform(RotationMatrix(Quaternion(w / np.linalg.norm(w))), p)  # type: ignore[arg-type]


def from_document(doc: Any, where: str) -> PlanTrajectory:
    """A PlanTrajectory of a parsed file, its structure and robot checked (not yet its samples)."""
    r = _Reader(where)
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise TrajectoryError(f"{where}: not a tamp trajectory file (no \"format\": \"{FORMAT}\")")
    version = r.integer(r.get(doc, "version", "version"), "version")
    if version != VERSION:
        raise TrajectoryError(f"{where}: trajectory format version {version}; this tamp reads version {VERSION}")
    robot = r.get(doc, "robot", "robot")
    name, joints = r.get(robot, "name", "robot"), r.get(robot, "joint_names", "robot")
    if name != ROBOT or joints != list(ARM_JOINTS):
        raise TrajectoryError(f"{where}: a trajectory for robot {name!r} with joints {joints}; this is the "
                              f"{ROBOT} model with joints {list(ARM_JOINTS)}")
    scene = r.get(doc, "scene", "scene")
    blocks = r.list(r.get(scene, "blocks", "scene"), "scene.blocks")
    if not blocks:
        raise r.fail("scene.blocks", "one block or more")
    types, poses = [], []
    for i, b in enumerate(blocks):
        kind = r.get(b, "type", f"scene.blocks[{i}]")
        if kind not in TYPE_NAMES:
            raise r.fail(f"scene.blocks[{i}].type", f"one of {list(TYPE_NAMES)}")
        types.append(TYPE_NAMES.index(kind))
        poses.append(r.pose(b, f"scene.blocks[{i}]"))
    scene_init = Scene(np.array(types), poses)
    q_init = r.vector(r.get(scene, "arm_positions", "scene"), 6, "scene.arm_positions")
    world = r.get(doc, "recorded_world", "recorded_world")
    if world not in ("fast", "full"):
        raise r.fail("recorded_world", "'fast' or 'full'")
    actions = [_action(r, a, f"actions[{k}]", scene_init)
               for k, a in enumerate(r.list(r.get(doc, "actions", "actions"), "actions"))]
    skipped = r.list(doc.get("skipped", []), "skipped")
    if not all(isinstance(s, dict) for s in skipped):
        raise r.fail("skipped", "a list of objects (index, action, reason)")
    source = doc.get("source", "")
    return PlanTrajectory(scene_init, q_init, actions, world, source if isinstance(source, str) else "", skipped)


def _action(r: _Reader, obj: Any, path: str, scene: Scene) -> ActionMotion:
    index = r.integer(r.get(obj, "index", path), f"{path}.index")
    raw = r.list(r.get(obj, "action", path), f"{path}.action")
    if len(raw) != 4:
        raise r.fail(f"{path}.action", "4 integers [pick, grasp_offset, place, release_offset]")
    action = PickPlace(*(r.integer(v, f"{path}.action") for v in raw))
    segments = []
    for k, seg in enumerate(r.list(r.get(obj, "segments", path), f"{path}.segments")):
        at = f"{path}.segments[{k}]"
        name = r.get(seg, "name", at)
        start = r.number(r.get(seg, "start_time", at), f"{at}.start_time")
        traj = r.get(seg, "trajectory", at)
        if r.get(traj, "joint_names", f"{at}.trajectory") != list(ARM_JOINTS):
            raise r.fail(f"{at}.trajectory.joint_names", f"the {ROBOT}'s joints {list(ARM_JOINTS)}")
        points = r.list(r.get(traj, "points", f"{at}.trajectory"), f"{at}.trajectory.points")
        if len(points) < 2:
            raise r.fail(f"{at}.trajectory.points", "2 points or more")
        t, q, qdot, qddot = [], [], [], []
        for i, point in enumerate(points):
            pt = f"{at}.trajectory.points[{i}]"
            q.append(r.vector(r.get(point, "positions", pt), 6, f"{pt}.positions"))
            qdot.append(r.vector(r.get(point, "velocities", pt), 6, f"{pt}.velocities"))
            qddot.append(r.vector(r.get(point, "accelerations", pt), 6, f"{pt}.accelerations"))
            d = r.get(point, "time_from_start", pt)
            sec, ns = (r.integer(r.get(d, key, f"{pt}.time_from_start"), f"{pt}.time_from_start.{key}")
                       for key in ("sec", "nanosec"))
            t.append(sec + ns * 1e-9)
        segments.append(Segment(str(name), start, np.array(t), np.array(q), np.array(qdot), np.array(qddot)))
    if not segments:
        raise r.fail(f"{path}.segments", "one segment or more")
    gripper = r.list(r.get(obj, "gripper", path), f"{path}.gripper")
    events = {e.get("event") if isinstance(e, dict) else None: e for e in gripper}
    if set(events) != {"close", "open"} or len(gripper) != 2:
        raise r.fail(f"{path}.gripper", "one 'close' and one 'open' event")
    close = events["close"]
    at = f"{path}.gripper[close]"
    carried = [r.integer(c, f"{at}.carried") for c in r.list(r.get(close, "carried", at), f"{at}.carried")]
    positions = r.list(r.get(obj, "blocks_after", path), f"{path}.blocks_after")
    if len(positions) != scene.n:
        raise r.fail(f"{path}.blocks_after", f"{scene.n} positions (one per block)")
    X_after = scene.X()
    X_after[:, :3] = [r.vector(p, 3, f"{path}.blocks_after[{i}]") for i, p in enumerate(positions)]
    return ActionMotion(index, action, segments, r.number(r.get(close, "time", at), f"{at}.time"),
                        r.number(r.get(events["open"], "time", f"{path}.gripper[open]"), f"{path}.gripper[open].time"),
                        r.integer(r.get(close, "block", at), f"{at}.block"), carried,
                        r.pose(r.get(close, "block_in_tcp", at), f"{at}.block_in_tcp"), X_after)


def write_trajectory(path: str | Path, plan: PlanTrajectory) -> Path:
    """Check `plan` as the file will read back (rounded), then write it atomically; returns the path."""
    text = json.dumps(to_document(plan), separators=(",", ":")) + "\n"
    check(from_document(json.loads(text), str(path)), model_limits(), f"{path} (being written)")
    return atomic_write_text(path, text)


def read_trajectory(path: str | Path) -> PlanTrajectory:
    """Read and check a trajectory file against the UR10e model; TrajectoryError (one line) if it is
    missing, malformed, truncated, for another robot, off the limits or discontinuous."""
    path = Path(path)
    if not path.is_file():
        raise TrajectoryError(f"no trajectory file at {path}")
    try:
        doc = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise TrajectoryError(f"{path}: not valid JSON, malformed or truncated ({error})") from None
    plan = from_document(doc, str(path))
    check(plan, model_limits(), str(path))
    return plan


# --- execution ---------------------------------------------------------------------------------------
def refined_plan(plan: PlanTrajectory) -> RefinedPlan:
    """The file as a RefinedPlan the executor runs: each action's motion as one trajectory, its
    grasp, and the recorded scene after it as the prediction."""
    steps, X_before = [], plan.scene_init.X()
    for a in plan.actions:
        times = {s.name: (s.start, s.end) for s in a.segments}
        steps.append(RefinedAction(action=a.action, q={}, paths={}, grasped=a.block, carried=list(a.carried),
                                   X_GC=[a.X_GC], X_before=X_before, X_after=a.X_after, trajectory=a.trajectory(),
                                   motion_times=times, t_grasp=a.t_close, t_release=a.t_open))
        X_before = a.X_after
    return RefinedPlan(plan.scene_init.X(), [a.action for a in plan.actions], plan.scene_init, plan.q_init,
                       steps=steps)


def execute_trajectory(plan: PlanTrajectory, observer: WorldObserver | None = None,
                       config: WorldConfig | None = None) -> ExecutionResult:
    """Execute the file's actions back to back with the full arm under physics from its initial
    scene (the arm holds still after each action until the blocks are at rest). Each log entry's
    `prediction_error` is the distance to the recorded execution's scene after that action."""
    return Executor(plan.scene_init.types, config).run(refined_plan(plan), observer)
