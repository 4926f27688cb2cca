"""The checks a trajectory file passes on writing and on reading: the motion a controller would run,
not only its JSON. Each failure is a `TrajectoryError` naming the file, the action, the segment and the
sample (docs/trajectories.md, "Checks").

- Limits: every sample's positions, velocities and accelerations within the UR10e model's limits.
- Motion consistent with itself: the file's motion is piecewise quadratic with a knot at every sample
  (tamp/sim/trajectory.py), so between samples k and k+1, h apart, exactly
  q[k+1] - q[k] = (v[k] + v[k+1]) h / 2 and v[k+1] - v[k] = a[k] h.
  The residuals may be POSITION_TOLERANCE and VELOCITY_TOLERANCE (rounding to 1e-9 leaves ~1e-8);
  a file whose velocities do not move its positions (or accelerations its velocities) is refused.
- Continuity: segments back to back on the action's clock, position and velocity continuous where
  segments and actions join and from the scene's arm configuration.
- Structure: segments of known names in their order, the still ones (`grasp`, `release`) still; the
  jaws close inside `grasp` and open inside `release`; actions and grasps name blocks of the scene;
  indices increase; the scene is one the world can hold.
- Grasps where the blocks are: at each close of the jaws, the grasped block's pose in the tcp frame
  (`block_in_tcp`), carried by the arm's configuration there, lies within GRASP_TOLERANCE of that block in
  the scene before the action (the file's scene, then each action's `blocks_after`). The simulator's grasp
  snaps any block within 1.5 cm into the grip: a scene moved away from its motion would replay as if not.
- Duration: at most MAX_ACTION_S per action and MAX_TOTAL_S in all, so `tamp view` (about a third of
  real time in the full world) never runs for long.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from tamp.errors import UserError
from tamp.planning.validate import check_scene
from tamp.sim.plants import ARM_JOINTS

if TYPE_CHECKING:
    from tamp.sim.trajectory_file import ActionMotion, JointLimits, PlanTrajectory, Segment

TOLERANCE = 1e-5  # rad, rad/s, rad/s^2 and s: slack of the limit, continuity and timing checks (rounding)
POSITION_TOLERANCE = 1e-6  # rad: q[k+1] - q[k] against (v[k] + v[k+1]) h / 2
VELOCITY_TOLERANCE = 1e-4  # rad/s: v[k+1] - v[k] against a[k] h
GRASP_TOLERANCE = 0.001  # m: a grasp lies this close to its block in the scene (files written here: within 1e-6)
MAX_ACTION_S = 60.0  # one pick-place of the skill takes 3-8 s
MAX_TOTAL_S = 600.0  # all actions: `tamp view` simulates them in about a third of that
# segment names in their order; the still ones: the jaws close at the end of `grasp`, open at the start of `release`
SEGMENT_ORDER = ("approach", "descend", "grasp", "liftoff", "lift", "transfer", "lower", "release", "retreat")
STILL = ("grasp", "release")


class TrajectoryError(UserError):
    """A trajectory file (or an executed motion being written) that fails its checks, in one line."""


def _check_limits(seg: Segment, limits: JointLimits, at: str) -> None:
    for what, values, lo, hi, unit in (
            ("position", seg.q, limits.lower, limits.upper, "rad"),
            ("velocity", seg.qdot, -limits.velocity, limits.velocity, "rad/s"),
            ("acceleration", seg.qddot, -limits.acceleration, limits.acceleration, "rad/s^2")):
        bad = np.argwhere((values < lo - TOLERANCE) | (values > hi + TOLERANCE))
        if len(bad):
            k, j = bad[0]
            raise TrajectoryError(f"{at} point {k}: {ARM_JOINTS[j]} {what} {values[k, j]:.6g} {unit} is "
                                  f"outside the UR10e's limits [{lo[j]:.6g}, {hi[j]:.6g}]")


def _worst(residual: np.ndarray, tolerance: float) -> tuple[int, int] | None:
    """(sample interval, joint) of the largest residual (samples - 1, joints), if it exceeds `tolerance`."""
    if residual.size == 0 or not residual.max() > tolerance:
        return None
    k, j = np.unravel_index(np.argmax(residual), residual.shape)
    return int(k), int(j)


def _check_consistency(seg: Segment, at: str) -> None:
    """Velocities move the positions and accelerations the velocities, between every two samples."""
    h = np.diff(seg.t)[:, None]
    moved, by_velocity = np.diff(seg.q, axis=0), 0.5 * (seg.qdot[:-1] + seg.qdot[1:]) * h
    worst = _worst(np.abs(moved - by_velocity), POSITION_TOLERANCE)
    if worst is not None:
        k, j = worst
        raise TrajectoryError(
            f"{at} points {k}-{k + 1}: {ARM_JOINTS[j]} moves {moved[k, j]:.6g} rad in {h[k, 0]:.6g} s, but its "
            f"velocities ({seg.qdot[k, j]:.6g}, {seg.qdot[k + 1, j]:.6g} rad/s) move it {by_velocity[k, j]:.6g} rad "
            f"(tolerance {POSITION_TOLERANCE:g} rad): velocities and positions disagree")
    change, by_acceleration = np.diff(seg.qdot, axis=0), seg.qddot[:-1] * h
    worst = _worst(np.abs(change - by_acceleration), VELOCITY_TOLERANCE)
    if worst is not None:
        k, j = worst
        raise TrajectoryError(
            f"{at} points {k}-{k + 1}: {ARM_JOINTS[j]} velocity changes by {change[k, j]:.6g} rad/s in "
            f"{h[k, 0]:.6g} s, but its acceleration {seg.qddot[k, j]:.6g} rad/s^2 changes it by "
            f"{by_acceleration[k, j]:.6g} (tolerance {VELOCITY_TOLERANCE:g} rad/s): accelerations and velocities "
            "disagree")


def _check_segments(action: ActionMotion, where: str) -> None:
    """Known names in order, still dwells, and the jaws' events inside their dwells."""
    names = [s.name for s in action.segments]
    if any(n not in SEGMENT_ORDER for n in names) or names != sorted(names, key=SEGMENT_ORDER.index) \
            or len(set(names)) < len(names) or not set(STILL) <= set(names):
        raise TrajectoryError(f"{where}: action {action.index}: segments {names}; expected, in this order, the "
                              f"ones of {list(SEGMENT_ORDER)} the action has, {' and '.join(STILL)} always")
    by_name = {s.name: s for s in action.segments}
    for name in STILL:
        seg = by_name[name]
        if np.ptp(seg.q, axis=0).max() > TOLERANCE or np.abs(seg.qdot).max() > TOLERANCE:
            raise TrajectoryError(f"{where}: action {action.index} segment {name!r}: the arm must hold still there")
    for event, time, name in (("close", action.t_close, "grasp"), ("open", action.t_open, "release")):
        seg = by_name[name]
        if not seg.start - TOLERANCE <= time <= seg.end + TOLERANCE:
            raise TrajectoryError(f"{where}: action {action.index}: the jaws {event} at {time:.6f} s, outside the "
                                  f"{name!r} segment [{seg.start:.6f}, {seg.end:.6f}] s")


def _check_blocks(plan: PlanTrajectory, action: ActionMotion, where: str) -> None:
    n, at = plan.scene_init.n, f"{where}: action {action.index}"
    pick, _, place, _ = action.action
    if not (pick < n and place < n):
        raise TrajectoryError(f"{at}: {list(action.action)} names a block beyond the scene's {n} (0..{n - 1})")
    if not (action.block < n and action.block in action.carried and all(c < n for c in action.carried)):
        raise TrajectoryError(f"{at}: grasped block {action.block} (carried {action.carried}) is not one of the "
                              f"scene's {n} blocks")
    if action.X_after.shape != (n, 5):
        raise TrajectoryError(f"{at}: blocks_after must give {n} positions")


def check(plan: PlanTrajectory, limits: JointLimits, where: str) -> None:
    """Every check of the module docstring; TrajectoryError naming `where` (the file), the action,
    segment and sample otherwise."""
    check_scene(plan.scene_init.X(), where=where, field="scene.blocks")
    indices = [a.index for a in plan.actions] + [int(s["index"]) for s in plan.skipped]
    if len(set(indices)) < len(indices) or [a.index for a in plan.actions] != sorted(a.index for a in plan.actions):
        raise TrajectoryError(f"{where}: action indices {indices} must increase and appear once")
    total = sum(a.duration for a in plan.actions)
    if total > MAX_TOTAL_S:
        raise TrajectoryError(f"{where}: {total:.0f} s of motion; a file may hold at most {MAX_TOTAL_S:.0f} s")
    q_prev, v_prev, prev = np.asarray(plan.q_init), np.zeros(6), "the initial configuration"
    for action in plan.actions:
        if action.duration > MAX_ACTION_S:
            raise TrajectoryError(f"{where}: action {action.index} lasts {action.duration:.0f} s; an action may "
                                  f"last at most {MAX_ACTION_S:.0f} s")
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
            _check_limits(seg, limits, at)
            _check_consistency(seg, at)
            q_prev, v_prev, prev = seg.q[-1], seg.qdot[-1], f"segment {seg.name!r}"
            t_action = seg.end
        _check_segments(action, where)
        _check_blocks(plan, action, where)
        prev = f"action {action.index}"
    _check_grasps(plan, where)


def _check_grasps(plan: PlanTrajectory, where: str) -> None:
    """Each grasp where its block is in the scene before the action (GRASP_TOLERANCE); says by how much."""
    from tamp.sim.kinematics import tcp_pose

    X = plan.scene_init.X()
    for action in plan.actions:
        grasp = next(s for s in action.segments if s.name == "grasp")
        k = min(int(np.searchsorted(grasp.start + grasp.t, action.t_close)), len(grasp.t) - 1)
        held = (tcp_pose(grasp.q[k]) @ action.X_GC).translation()
        off = float(np.linalg.norm(held - X[action.block, :3]))
        if not off <= GRASP_TOLERANCE:
            raise TrajectoryError(f"{where}: action {action.index}: the jaws close on block {action.block} "
                                  f"{1000 * off:.1f} mm from where the scene before the action has it (at most "
                                  f"{1000 * GRASP_TOLERANCE:g} mm): the motion is not of this scene")
        X = action.X_after
