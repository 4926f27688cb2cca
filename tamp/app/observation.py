"""What a closed loop observes: the simulator's truth, or the blocks the camera rig perceives.

    observer = TruthObserver(faults, rng)                    # today's default: the world's X (with `faults`' noise)
    observer = CameraObserver(rig, rng, X_init, predict)     # the blocks perceived from the rig's depth images
    seen = observer.first(world.scene)                       # the initial scene
    seen = observer.after(world.scene, action)               # after an executed action
    seen = observer.again(world.scene)                       # the same scene observed again (the loop's look)

An observation (`Observed`) is all the planner, the kinematic check and the skill are given: the state X (n, 5)
in the blocks' identities, and with the cameras the blocks' perceived poses (`Observed.scene`, orientations
included). The world executes in its own truth; the observer is handed the true scene only to render it.

The camera observer keeps the blocks' identities by assigning each perception to where it expects the blocks
(`tamp.sim.perception.perceive`'s `previous`): its last estimates, moved as the Dynamics Model predicts the action
moved them (a block the action carried far is not taken for a neighbour a push moved a little). It never passes a
failure silently:
- a block not found, two blocks merged into one estimate, a ghost, a block of the wrong type, points no block
  explains or a block seen `SURPRISE_M` from where the action should have left it are said (`Observed.said`), and
  the rig observes again, up to `LOOKS` more times (new sensor noise);
- if the count is still wrong, the loop plans with n blocks and says so: a block not seen is planned at where the
  Dynamics Model predicts it after the action (its last estimate when nothing moved it), an estimate left over
  is left out (`_as_expected` first tries the prediction's split of the points);
- blocks still seen more than `APART_M` in each other are refitted jointly from where they were seen (`_jointly`),
  and blocks seen up to `APART_M` in each other are moved apart (`_apart`): the kinematic check would take the
  overlap of two touching blocks' fits for a collision of every action.

It also learns its own error from what it measures, not from an assumed sigma: a block the action did not pick
or place (or a scene observed twice) should be seen where it was seen before, so the difference of the two
estimates, over such blocks within `SAME_BLOCK_M`, carries twice the variance of one observation's error
(`sigma_m`). The first observation looks twice to start the estimate. The loop stops `stop_margin` inside eps,
as it does with noise of a known sigma (`tamp.app.faults`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations
from typing import TYPE_CHECKING, Callable

import numpy as np

from tamp.app.faults import STOP_MARGIN_SIGMAS, Faults
from tamp.planning.vocabulary import BLOCK_SIZES, TYPE_NAMES, PickPlace

if TYPE_CHECKING:  # Drake loads when a loop runs
    from tamp.sim.cameras import CameraRig
    from tamp.sim.perception import Perception
    from tamp.sim.perception_config import PerceptionConfig
    from tamp.sim.replay import Timeline
    from tamp.sim.skill import Scene

LOOKS = 2  # observations again when a perception said a failure, before the loop plans with what it has
SURPRISE_M = 0.05  # metres: a block seen this far from where it was expected is said (a step that far off the
#   Dynamics Model's prediction is rarer than a split of blocks that touch end to end the wrong way, which depth
#   alone cannot tell apart)
AS_WELL = 1.02  # the prediction's scene explains the depth as well as the one seen when its residual is this close
REFIT_M = 0.02  # metres: a block seen this far from the prediction is fitted again from it in `_as_expected`
#   (a cube split off a bar's far end shifts the bar by the cube's length)
APART_M = 0.003  # metres: blocks seen this far or less in each other are moved apart (blocks that touch, each fitted
#   within a millimetre or so); a deeper overlap is no fitting noise and is left to the planner's checks
NEAR_M = 0.01  # metres: fused points this far beyond a block's box at most are refitted with it
MIN_POINTS = 30  # fused points near where a block is expected, for it to be fitted there (a 5 cm face holds ~150)
_CLEARANCE_M = 0.0002  # metres: blocks moved apart (`APART_M`) are left this far apart
SAME_BLOCK_M = 0.01  # metres: two estimates of a block nothing moved that differ more are a failure, not noise
MARGIN_OF_EPS = 0.5  # the learned stop margin stays below this share of eps (a loop that sees badly still stops)

Predict = Callable[[np.ndarray, PickPlace], np.ndarray]  # the (n, 5) state predicted after an action from X
_RIGS: dict[PerceptionConfig, CameraRig] = {}  # one warm rig per configuration in a process (VTK starts slowly)


def rig_for(config: PerceptionConfig) -> CameraRig | None:
    """The camera rig the closed loops observe through when `config.observe` is "cameras" (None: the truth),
    built once per process and configuration."""
    if not config.cameras_on:
        return None
    if config not in _RIGS:
        from tamp.sim.cameras import CameraRig

        _RIGS[config] = CameraRig(config)
    return _RIGS[config]


@dataclass
class Observed:
    """One observation, as the planner, the kinematic check and the skill take it."""

    X: np.ndarray  # (n, 5) block centres (m) and one-hot types, in the problem's block order
    scene: Scene | None = None  # the blocks' observed poses (orientations included); None: the world's own (truth)
    said: list[str] = field(default_factory=list)  # what perception could not explain, in words (empty: nothing)
    looks: int = 1  # renderings of the rig this observation took
    errors_m: list[float] = field(default_factory=list)  # per block, metres from the truth (a record; never used)


class TruthObserver:
    """The world's own X, with `faults`' observation noise if given (`Faults.observe`, drawn from `rng`)."""

    cameras = False

    def __init__(self, faults: Faults | None, rng: np.random.Generator) -> None:
        self.faults, self.rng = faults, rng
        self.observations: list[Observed] = []

    def observe(self, scene: Scene) -> Observed:
        X = scene.X()
        seen = Observed(X if self.faults is None else self.faults.observe(X, self.rng, scene))
        self.observations.append(seen)
        return seen

    def first(self, scene: Scene) -> Observed:
        return self.observe(scene)

    def after(self, scene: Scene, action: PickPlace) -> Observed:
        return self.observe(scene)

    def again(self, scene: Scene) -> Observed:
        return self.observe(scene)

    def stop_margin(self) -> float:
        """Metres inside eps the loop stops: the noise is known (`Faults.known_to` sets it in the configuration)."""
        return 0.0 if self.faults is None else STOP_MARGIN_SIGMAS * self.faults.noise_m


class CameraObserver:
    """The blocks perceived from `rig`'s depth images of the true scene (see the module docstring). `X_init`: the
    problem's initial scene, which names the blocks (their identities and types); `predict`: the Dynamics Model,
    where a block not seen is planned; `timeline`: a replay that shows each observation's cloud and boxes."""

    cameras = True

    def __init__(self, rig: CameraRig, rng: np.random.Generator, X_init: np.ndarray, predict: Predict | None = None,
                 timeline: Timeline | None = None, looks: int = LOOKS) -> None:
        self.rig, self.rng, self.predict, self.timeline, self.looks = rig, rng, predict, timeline, looks
        self.last = np.array(X_init, dtype=float)  # the last estimates: identities are assigned to them
        self.types = np.argmax(self.last[:, 3:], axis=1)  # the problem names each block's type
        self.scene: Scene | None = None  # the last observed poses
        self.unseen: set[int] = set()  # the blocks the last observation did not see (filled in)
        self.residuals: list[np.ndarray] = []  # (dx, dy) between two estimates of a block nothing moved, metres
        self.observations: list[Observed] = []

    @property
    def sigma_m(self) -> float | None:
        """Metres: the learned standard deviation of an observed x or y (None before two estimates of a block)."""
        if not self.residuals:
            return None
        d = np.array(self.residuals)
        return float(np.sqrt(np.mean(d ** 2) / 2))  # a difference of two estimates has twice one's variance

    def stop_margin(self) -> float:
        """Metres inside eps the loop stops: `STOP_MARGIN_SIGMAS` learned sigmas (`sigma_m`)."""
        return STOP_MARGIN_SIGMAS * (self.sigma_m or 0.0)

    def first(self, scene: Scene) -> Observed:
        """The initial scene, observed twice: the second observation starts the estimate of the error."""
        self._observe(scene, self.last)
        return self.again(scene)

    def after(self, scene: Scene, action: PickPlace) -> Observed:
        """The scene after `action`: the blocks it picked or placed are not expected where they were seen."""
        expected = self.last if self.predict is None else self.predict(self.last, action)
        return self._observe(scene, expected, moved={action.pick, action.place})

    def again(self, scene: Scene) -> Observed:
        """The same scene observed again (nothing moved)."""
        return self._observe(scene, self.last)

    def _observe(self, scene: Scene, expected: np.ndarray, moved: frozenset[int] | set[int] = frozenset()) -> Observed:
        """Render, perceive (identities from `expected`), look again while perception says a failure, and
        fill in what is still missing from `expected` (the state predicted after the action), saying so. A scene
        the planner would refuse (`check_scene`: blocks in each other, floating, out of reach) is said too; if every
        look gives one, the loop plans from `expected`, else from its last observation. Blocks fitted a little into
        each other are moved apart (`_apart`)."""
        from tamp.sim.perception import perceive

        said: list[str] = []
        best: tuple[int, Perception, list[str], list] | None = None
        for look in range(1 + self.looks):
            views = self.rig.observe(scene, self.rng)
            seen = perceive(views, self.rig.config, previous=expected)
            problems = [f.reason for f in seen.failures] + self._wrong_types(seen) + self._surprises(seen, expected)
            refused = _refused(self._state(seen, expected)[0])
            self._show(views, seen)
            if best is None or (refused is None, -len(problems)) > (not best[2], -best[0]):
                best = (len(problems), seen, [] if refused is None else [refused], views)
            if not problems and refused is None:
                break
            said.append(f"look {look + 1}: " + "; ".join(problems + ([] if refused is None else [refused])))
        assert best is not None  # one look at least
        X, poses, unseen, filled = self._state(best[1], expected)
        if best[0] and not best[2]:  # still a failure: does the prediction explain the depth images as well?
            X, poses, unseen, filled = self._as_expected(best[3], X, poses, unseen, expected) or \
                (X, poses, unseen, filled)
        X, poses = self._jointly(best[3], X, poses)
        if filled:
            said.append(f"after {look + 1} look(s), planned with every block: " + "; ".join(filled))
        if best[2]:  # every look gave a scene the planner refuses
            fallback = "the prediction after the action" if _refused(expected) is None else "the last observation"
            X = np.array(expected if _refused(expected) is None else self.last, dtype=float)
            poses = [self._pose(i, X[i, :3]) for i in range(len(X))]
            unseen = set(range(len(X)))
            said.append(f"after {look + 1} look(s), no scene the planner accepts: planned from {fallback}")
        from pydrake.math import RigidTransform

        from tamp.sim.skill import Scene

        poses = _apart(self.types, poses)
        X[:, :3] = [p[:3, 3] for p in poses]
        observed = Scene(self.types.copy(), [RigidTransform(p) for p in poses])  # type: ignore[arg-type]  # stubs
        self._learn(X, set(moved) | unseen | self.unseen)
        self.last, self.scene, self.unseen = X, observed, unseen
        truth = scene.X()
        seen_now = Observed(X, observed, said, look + 1, np.linalg.norm(X[:, :3] - truth[:, :3], axis=1).tolist())
        self.observations.append(seen_now)
        return seen_now

    def _pose(self, i: int, position: np.ndarray) -> np.ndarray:
        """A (4, 4) pose of block i at `position`, turned as it was last seen (upright before it was seen)."""
        pose = np.eye(4)
        pose[:3, :3] = np.eye(3) if self.scene is None else self.scene.X_WB[i].rotation().matrix()
        pose[:3, 3] = position
        return pose

    def _jointly(self, views, X: np.ndarray, poses: list[np.ndarray]) -> tuple[np.ndarray, list[np.ndarray]]:
        """(X, poses) with the blocks seen more than `APART_M` in each other refitted jointly from where they were
        seen, each point to its nearest box (`box_fit.fit_jointly`), if that leaves them at most `APART_M` in each
        other and explains the depth images as well (`AS_WELL`): a bar and a cube lying end to end show one top face,
        and the bar fitted to it alone reaches into the cube. Unchanged otherwise."""
        pairs = [(a, b) for a, b in combinations(range(len(X)), 2) if _overlap(self.types, poses, a, b)[0] > APART_M]
        if not pairs:
            return X, poses
        from tamp.sim.box_fit import boxes_sdf, fit_jointly, half_size, leans
        from tamp.sim.point_cloud import fused_cloud

        inside = sorted({k for pair in pairs for k in pair})
        halves = np.array([half_size(int(t)) for t in self.types])
        cloud = fused_cloud(views, self.rig.config.voxel_m)
        near = np.min(np.abs(boxes_sdf(np.array(poses)[inside], halves[inside], cloud)), axis=0) < NEAR_M
        upright = np.array([not leans(p) for p in poses])
        refitted = list(fit_jointly(cloud[near], halves, np.array(poses), inside, upright))
        if any(_overlap(self.types, refitted, a, b)[0] > APART_M for a, b in pairs):
            return X, poses
        if self._depth_residual_m(views, refitted) > AS_WELL * self._depth_residual_m(views, poses):
            return X, poses
        X = X.copy()
        X[inside, :3] = [refitted[i][:3, 3] for i in inside]
        return X, refitted

    def _as_expected(self, views, X: np.ndarray, poses: list[np.ndarray], unseen: set[int], expected: np.ndarray):
        """(X, poses, unseen, what was done, in words) with each block not seen, seen `REFIT_M` from `expected` or
        seen more than `APART_M` inside another block fitted to the cloud from where `expected` has it, if that scene
        explains the depth images as well as the one seen (`_depth_residual_m`, within `AS_WELL`): a cube and a bar
        lying end to end look alike however they are split, and the prediction says which split the action made.
        None otherwise. The blocks are fitted jointly with the blocks around them, each point to its nearest box
        (`box_fit.fit_jointly`), so that blocks that touch do not pull each other into one another; each upright (x, y,
        yaw), unless its points say it leans (with six degrees of freedom it tilts more than `box_fit.TILTED_RAD`: a
        bar set down on a cube's end, its far end on the table)."""
        from tamp.sim.box_fit import fit_jointly, half_size, leans
        from tamp.sim.point_cloud import fused_cloud

        off = np.linalg.norm(X[:, :3] - expected[:, :3], axis=1)
        inside = {k for a, b in combinations(range(len(X)), 2) if _overlap(self.types, poses, a, b)[0] > APART_M
                  for k in (a, b)}
        odd = sorted({i for i in range(len(X)) if i in unseen or off[i] >= REFIT_M} | inside)
        if not odd:
            return None
        cloud = fused_cloud(views, self.rig.config.voxel_m)
        halves = np.array([half_size(int(t)) for t in self.types])
        near = [np.linalg.norm(cloud - expected[i, :3], axis=1) < np.linalg.norm(halves[i]) + NEAR_M for i in odd]
        if min(np.count_nonzero(m) for m in near) < MIN_POINTS:
            return None
        points = cloud[np.any(near, axis=0)]
        starts = [self._pose(i, expected[i, :3]) if i in odd else p for i, p in enumerate(poses)]
        six = fit_jointly(points, halves, np.array(starts), odd, np.zeros(len(X), dtype=bool))
        leaning = {i for i in odd if leans(six[i])}
        poses_alt = list(fit_jointly(points, halves, np.array([six[i] if i in leaning else p
                                                               for i, p in enumerate(starts)]),
                                     odd, np.array([i not in leaning for i in range(len(X))])))
        X_alt = X.copy()
        X_alt[odd, :3] = [poses_alt[i][:3, 3] for i in odd]
        if _refused(X_alt) is not None:
            return None
        if self._depth_residual_m(views, poses_alt) > AS_WELL * self._depth_residual_m(views, poses):
            return None
        return X_alt, poses_alt, unseen - set(odd), [f"blocks {', '.join(map(str, odd))} taken where the action should "
                                                     "have left them, which explains the depth images as well"]

    def _depth_residual_m(self, views, poses: list[np.ndarray]) -> float:
        """Metres: the mean depth difference (each pixel's capped at 5 cm) between `views` and the rig's rendering of
        the blocks at `poses`."""
        from pydrake.math import RigidTransform

        from tamp.sim.skill import Scene

        rendered = self.rig.render(Scene(self.types, [RigidTransform(p) for p in poses]))  # type: ignore[arg-type]
        total = 0.0
        for measured, model in zip(views, rendered):
            seen = np.isfinite(measured.depth) & (measured.depth > 0)
            both = seen & np.isfinite(model.depth)
            diff = np.full(measured.depth.shape, 0.05)
            diff[both] = np.abs(measured.depth[both] - model.depth[both])
            total += float(np.minimum(diff[seen], 0.05).mean())
        return total / len(views)

    def _turned_as_before(self, i: int, X_WB: np.ndarray) -> np.ndarray:
        """X_WB with its rotation the one of the box's symmetric equivalents (`box_fit.symmetries`: a cube's axes can
        be named 24 ways, a bar's 8) nearest the rotation block i was last seen with (upright, axis-aligned before it
        was seen, as a problem places its blocks): the skill's grasp heading and offset axis follow the names of the
        axes, which no camera sees, so they are kept from one observation to the next."""
        from tamp.sim.box_fit import symmetries

        before = np.eye(3) if self.scene is None else self.scene.X_WB[i].rotation().matrix()
        turned = X_WB[:3, :3] @ symmetries(int(self.types[i]))
        pose = np.array(X_WB, dtype=float)
        pose[:3, :3] = turned[int(np.argmin(np.linalg.norm(turned - before, axis=(1, 2))))]
        return pose

    def _wrong_types(self, seen: Perception) -> list[str]:
        """A block seen as the other type: said (the problem names every block's type)."""
        return [f"block {i} ({TYPE_NAMES[int(self.types[i])]}) seen as a {TYPE_NAMES[b.type]}"
                for b, i in zip(seen.blocks, seen.identity) if i >= 0 and b.type != self.types[i]]

    def _surprises(self, seen: Perception, expected: np.ndarray) -> list[str]:
        """A block seen `SURPRISE_M` or farther from where `expected` (the prediction after the action) has it: said."""
        out = []
        for b, i in zip(seen.blocks, seen.identity):
            off = np.linalg.norm(b.position - expected[i, :3]) if i >= 0 else 0.0
            if off >= SURPRISE_M:
                x, y, z = b.position
                out.append(f"block {i} seen at ({x:.3f}, {y:.3f}, {z:.3f}) m, {off * 100:.0f} cm from where it was "
                           "expected")
        return out

    def _state(self, seen: Perception, expected: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], set[int],
                                                                        list[str]]:
        """X (n, 5), each block's pose (4, 4), the blocks not seen and what was filled in, in words: every block
        perceived with its own type, the others where `expected` has them (orientation: as last seen); estimates
        left over are left out."""
        n = len(self.types)
        X = np.array(expected, dtype=float)
        X[:, 3:] = np.eye(2)[self.types]
        poses: list[np.ndarray | None] = [None] * n
        for block, i in zip(seen.blocks, seen.identity):
            if i >= 0 and block.type == self.types[i]:
                X[i, :3], poses[i] = block.position, self._turned_as_before(i, block.X_WB)
        unseen = {i for i in range(n) if poses[i] is None}
        filled = []
        for i in sorted(unseen):
            poses[i] = self._pose(i, X[i, :3])
            x, y, z = X[i, :3]
            filled.append(f"block {i} ({TYPE_NAMES[int(self.types[i])]}) not seen, taken at ({x:.3f}, {y:.3f}, "
                          f"{z:.3f}) m as predicted")
        left = sum(1 for i in seen.identity if i < 0)
        if left:
            filled.append(f"{left} estimate(s) matching no block left out")
        return X, [p for p in poses if p is not None], unseen, filled

    def _learn(self, X: np.ndarray, moved: set[int]) -> None:
        """Add the differences to the last estimates of the blocks nothing moved and both observations saw."""
        d = X[:, :2] - self.last[:, :2]
        for i in range(len(X)):
            if i not in moved and np.linalg.norm(d[i]) < SAME_BLOCK_M:
                self.residuals.append(d[i])

    def _show(self, views, seen: Perception) -> None:
        """The fused cloud and the estimated boxes in the replay, at the replay's current time."""
        if self.timeline is None:
            return
        from tamp.sim.point_cloud import fused_cloud

        cloud = fused_cloud(views, self.rig.config.voxel_m)
        self.timeline.observed(cloud, [(b.type, b.X_WB) for b in seen.blocks])


def _overlap(types: np.ndarray, poses: list[np.ndarray], a: int, b: int) -> tuple[float, np.ndarray]:
    """(metres, unit axis from a towards b): how far block b must move along the axis to leave block a (0 or less:
    they do not overlap; `skill.penetration`)."""
    from pydrake.math import RigidTransform

    from tamp.sim.skill import penetration

    return penetration(RigidTransform(poses[a]), BLOCK_SIZES[int(types[a])],  # type: ignore[arg-type]  # stubs
                       RigidTransform(poses[b]), BLOCK_SIZES[int(types[b])])  # type: ignore[arg-type]


def _apart(types: np.ndarray, poses: list[np.ndarray]) -> list[np.ndarray]:
    """`poses` with blocks seen up to `APART_M` in each other moved apart along their axis of least overlap, to
    `_CLEARANCE_M`: blocks that touch are each fitted within a millimetre or so, and the kinematic check takes any
    overlap for a collision of every action. Of two blocks one above the other (the axis within 60 degrees of
    vertical), the upper one moves; else each moves half."""
    poses = [np.array(p, dtype=float) for p in poses]
    for _ in range(3):  # a block moved from one neighbour may reach another
        moved = False
        for a, b in combinations(range(len(poses)), 2):
            depth, axis = _overlap(types, poses, a, b)
            if not 0.0 < depth <= APART_M:
                continue
            step = (depth + _CLEARANCE_M) * axis
            if abs(axis[2]) > 0.5:
                upper, sign = (b, 1.0) if axis[2] > 0 else (a, -1.0)
                poses[upper][:3, 3] += sign * step
            else:
                poses[a][:3, 3] -= step / 2
                poses[b][:3, 3] += step / 2
            moved = True
        if not moved:
            break
    return poses


def _refused(X: np.ndarray) -> str | None:
    """Why the planner would refuse the observed scene X (`plan()` checks its X_init so), or None."""
    from tamp.errors import UserError
    from tamp.planning.validate import check_scene

    try:
        check_scene(X, where="the scene seen", upright=False)
    except UserError as error:
        return str(error)
    return None


__all__ = ["CameraObserver", "LOOKS", "Observed", "TruthObserver", "rig_for"]
