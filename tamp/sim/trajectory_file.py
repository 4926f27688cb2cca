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

Reading goes through the guarded reader (`guarded`) and `SCHEMA`; writing and reading then run the
same checks (`tamp.sim.trajectory_checks`): limits read from drake_models/ur10e.urdf (acceleration:
A_MAX, the model gives none), velocities and accelerations consistent with the positions, continuity,
segments and gripper events where they belong, blocks of the scene, a bounded duration. A bad file is
one `TrajectoryError` (or `guarded.InputError`) line. `execute_trajectory` runs a file with the full
arm under physics.
"""
from __future__ import annotations

import json
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

from guarded import Schema, parse_json, read_json
from tamp.inputs import ACTION, BLOCK
from tamp.planning.vocabulary import TYPE_NAMES, PickPlace
from tamp.records import atomic_write_text
from tamp.sim.execute import ExecutionResult, Executor
from tamp.sim.observer import WorldObserver
from tamp.sim.plants import ARM_FILE, ARM_JOINTS
from tamp.sim.skill import Scene
from tamp.sim.trajectory import A_MAX, MOTION_ORDER, RefinedAction, RefinedPlan
from tamp.sim.trajectory_checks import MAX_ACTION_S, SEGMENT_ORDER, TOLERANCE, TrajectoryError, check
from tamp.sim.world_types import FIDELITIES, WorldConfig

FORMAT = "tamp-trajectory"
VERSION = 1  # bumped when a reader of the old version would misread a new file
ROBOT = "UR10e"
SAMPLE_PERIOD = 0.02  # s between samples inside a segment, besides the knots of the time parameterization
DECIMALS = 9  # positions, velocities, accelerations, block positions rounded to 1e-9 (rad, rad/s, ..., m)
ROUND_TRIP_TOLERANCE = 0.002  # m: a file recorded in the full world, executed again, ends this close to the record
DWELLS = {"descend": "grasp", "lower": "release"}  # a still segment follows these motions: jaws close / open
ACCELERATION_NOTE = ("the model file gives no acceleration limits: these are tamp's A_MAX "
                     "(tamp/sim/trajectory.py), the limit of the time parameterization")


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
    configuration: dict = field(default_factory=dict)  # the planner's resolved configuration (`tamp config show`)

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
        "format": FORMAT, "version": VERSION, "source": plan.source, "configuration": plan.configuration,
        "robot": {"name": ROBOT, "model": f"drake_models/{ARM_FILE.name}", "joint_names": names,
                  "limits": plan.limits.to_dict()},
        "units": {"time": "s", "position": "rad", "velocity": "rad/s", "acceleration": "rad/s^2", "length": "m"},
        "recorded_world": plan.world,
        "scene": {"blocks": [{"type": TYPE_NAMES[int(t)], **_pose(X)} for t, X in zip(scene.types, scene.X_WB)],
                  "arm_positions": np.asarray(plan.q_init, dtype=float).tolist()},
        "actions": [action(a) for a in plan.actions],
        "skipped": plan.skipped,
    }


# every number of a file is far inside these bounds (metres, radians, rad/s, rad/s^2); beyond them the
# checks' arithmetic would overflow before it could say what is wrong
_BOUNDED = {"type": "number", "minimum": -1e6, "maximum": 1e6}
_NUMBERS = {n: {"type": "array", "minItems": n, "maxItems": n, "items": _BOUNDED} for n in (3, 4, 6)}
_POSE = {"type": "object", "required": ["position", "quaternion_wxyz"],
         "properties": {"position": _NUMBERS[3], "quaternion_wxyz": _NUMBERS[4]}}
_TIME = {"type": "number", "minimum": 0, "maximum": MAX_ACTION_S}
_POINT = {"type": "object", "required": ["positions", "velocities", "accelerations", "time_from_start"],
          "properties": {"positions": _NUMBERS[6], "velocities": _NUMBERS[6], "accelerations": _NUMBERS[6],
                         "time_from_start": {"type": "object", "required": ["sec", "nanosec"], "properties": {
                             "sec": {"type": "integer", "minimum": 0, "maximum": int(MAX_ACTION_S)},
                             "nanosec": {"type": "integer", "minimum": 0, "maximum": 999_999_999}}}}}
_SEGMENT = {"type": "object", "required": ["name", "start_time", "trajectory"], "properties": {
    "name": {"enum": list(SEGMENT_ORDER)}, "start_time": _TIME,
    "trajectory": {"type": "object", "required": ["joint_names", "points"], "properties": {
        "joint_names": {"enum": [list(ARM_JOINTS)]}, "points": {"type": "array", "minItems": 2, "items": _POINT}}}}}
_CLOSE = {"type": "object", "required": ["event", "time", "block", "carried", "block_in_tcp"], "properties": {
    "event": {"enum": ["close"]}, "time": _TIME, "block": BLOCK,
    "carried": {"type": "array", "minItems": 1, "items": BLOCK}, "block_in_tcp": _POSE}}
_OPEN = {"type": "object", "required": ["event", "time"], "properties": {"event": {"enum": ["open"]}, "time": _TIME}}
_ACTION = {"type": "object", "required": ["index", "action", "duration", "segments", "gripper", "blocks_after"],
           "properties": {"index": {"type": "integer", "minimum": 0}, "action": ACTION, "duration": _TIME,
                          "segments": {"type": "array", "minItems": 2, "maxItems": len(SEGMENT_ORDER),
                                       "items": _SEGMENT},
                          "gripper": {"type": "array", "minItems": 2, "maxItems": 2, "items": [_CLOSE, _OPEN]},
                          "blocks_after": {"type": "array", "items": _NUMBERS[3]}}}
# the structure of a version-1 file (docs/trajectories.md), checked after its format, version and robot
SCHEMA = Schema({"type": "object", "required": ["robot", "recorded_world", "scene", "actions"], "properties": {
    "source": {"type": "string"}, "configuration": {"type": "object"}, "recorded_world": {"enum": list(FIDELITIES)},
    "scene": {"type": "object", "required": ["blocks", "arm_positions"], "properties": {
        "blocks": {"type": "array", "minItems": 1, "items": {
            "type": "object", "required": ["type", "position", "quaternion_wxyz"],
            "properties": {"type": {"enum": list(TYPE_NAMES)}, "position": _NUMBERS[3],
                           "quaternion_wxyz": _NUMBERS[4]}}},
        "arm_positions": _NUMBERS[6]}},
    "actions": {"type": "array", "items": _ACTION},
    "skipped": {"type": "array", "items": {"type": "object", "required": ["index", "action", "reason"], "properties": {
        "index": {"type": "integer", "minimum": 0}, "action": ACTION, "reason": {"type": "string"}}}}}})


def _read_pose(obj: dict, where: str) -> RigidTransform:
    w = np.array(obj["quaternion_wxyz"], dtype=float)
    if abs(np.linalg.norm(w) - 1.0) > 1e-6:
        raise TrajectoryError(f"{where}.quaternion_wxyz: expected a unit quaternion, got {obj['quaternion_wxyz']}")
    return RigidTransform(RotationMatrix(Quaternion(w / np.linalg.norm(w))), obj["position"])


def from_document(doc: Any, where: str) -> PlanTrajectory:
    """A PlanTrajectory of a parsed file: its format, version and robot, then `SCHEMA` (not yet its
    motion: `check`)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise TrajectoryError(f"{where}: not a tamp trajectory file (no \"format\": \"{FORMAT}\")")
    if doc.get("version") != VERSION:
        raise TrajectoryError(f"{where}: trajectory format version {_short(doc.get('version'))}; this tamp reads "
                              f"version {VERSION}")
    robot = doc.get("robot")
    name, joints = (robot.get("name"), robot.get("joint_names")) if isinstance(robot, dict) else (None, None)
    if name != ROBOT or joints != list(ARM_JOINTS):
        raise TrajectoryError(f"{where}: a trajectory for robot {_short(name)} with joints {_short(joints)}; this is "
                              f"the {ROBOT} model with joints {list(ARM_JOINTS)}")
    SCHEMA.check(doc, where)
    blocks = doc["scene"]["blocks"]
    scene = Scene(np.array([TYPE_NAMES.index(b["type"]) for b in blocks]),
                  [_read_pose(b, f"{where}: scene.blocks[{i}]") for i, b in enumerate(blocks)])
    actions = [_action(a, f"{where}: actions[{k}]", scene) for k, a in enumerate(doc["actions"])]
    return PlanTrajectory(scene, np.array(doc["scene"]["arm_positions"], dtype=float), actions,
                          doc["recorded_world"], doc.get("source", ""), doc.get("skipped", []),
                          configuration=doc.get("configuration", {}))


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _action(obj: dict, where: str, scene: Scene) -> ActionMotion:
    segments = []
    for seg in obj["segments"]:
        points = seg["trajectory"]["points"]
        t = np.array([p["time_from_start"]["sec"] + p["time_from_start"]["nanosec"] * 1e-9 for p in points])
        q, qdot, qddot = (np.array([p[key] for p in points], dtype=float)
                          for key in ("positions", "velocities", "accelerations"))
        segments.append(Segment(seg["name"], float(seg["start_time"]), t, q, qdot, qddot))
    if len(obj["blocks_after"]) != scene.n:
        raise TrajectoryError(f"{where}.blocks_after: expected {scene.n} positions (one per block), "
                              f"got {len(obj['blocks_after'])}")
    X_after = scene.X()
    X_after[:, :3] = obj["blocks_after"]
    close, open_ = obj["gripper"]
    motion = ActionMotion(obj["index"], PickPlace(*obj["action"]), segments, float(close["time"]),
                          float(open_["time"]), close["block"], list(close["carried"]),
                          _read_pose(close["block_in_tcp"], f"{where}.gripper[0].block_in_tcp"), X_after)
    if abs(motion.duration - obj["duration"]) > TOLERANCE:
        raise TrajectoryError(f"{where}.duration: {obj['duration']} s, but the segments end at {motion.duration:.9f} s")
    return motion


def write_trajectory(path: str | Path, plan: PlanTrajectory) -> Path:
    """Check `plan` as the file will read back (rounded), then write it atomically; returns the path."""
    text = json.dumps(to_document(plan), separators=(",", ":")) + "\n"
    where = f"{path} (being written)"
    check(from_document(parse_json(text, where), where), model_limits(), where)
    return atomic_write_text(path, text)


def read_trajectory(path: str | Path) -> PlanTrajectory:
    """Read a trajectory file through the guarded reader and check it against the UR10e model
    (`tamp.sim.trajectory_checks`); TrajectoryError or InputError (one line) if it fails."""
    plan = from_document(read_json(path, "trajectory file"), str(path))
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
