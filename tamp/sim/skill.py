"""Geometry of the pick-place skill: gripper poses, what the jaws hold, where a block is released.

All poses are of the tcp frame G (drake_models/gripper.sdf) in the world W: top-down, +z_G pointing
down, the jaws closing along x_G and y_G along the block's own y axis, so a 5 x 25 cm bar is held
across its 5 cm width. The grasp point is p_pick + grasp_offset * 7.5 cm along the picked block's
offset axis, the target point p_place + release_offset * 7.5 cm along the place block's offset axis
(`Scene.offset_axis_xy`: a bar's long axis, a cube's horizontal axis nearest world +y, both signed
toward +y, so that an action means the same for the same X), and the gripper keeps the block where
it held it: the block ends at target - (grasp point - block centre), rotated with the gripper.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pydrake.math import RigidTransform, RotationMatrix

from tamp.planning.vocabulary import BLOCK_SIZES, LARGE, OFFSET_STEP, PickPlace
from tamp.sim.plants import X_FlangeTcp
from tamp.sim.world_types import WorldConfig

_CORNER_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0
JAW_OPENING = 0.08  # metres between the open jaws' inner faces
_FOOTPRINT_INSET = 0.01  # metres: a block's bottom corners moved this far inward before asking what they rest on, so
#   that a neighbour it only touches at an edge does not count as its support
_LYING = np.sqrt(0.5)  # a block axis whose projection on the table is this long lies within 45 degrees of it
_GRASP_TOLERANCE = 0.005  # metres: the grasp point may lie this far outside a block and still hold it


@dataclass
class Scene:
    """Simulator state of the blocks: types (n,) and full poses (orientation is not in X)."""

    types: np.ndarray
    X_WB: list[RigidTransform]
    _corners: dict[int, tuple[RigidTransform, np.ndarray]] = field(default_factory=dict, repr=False, compare=False)

    @property
    def n(self) -> int:
        return len(self.types)

    def X(self) -> np.ndarray:
        """The planner's state: (n, 5) = position (m) and one-hot type."""
        X = np.zeros((self.n, 5))
        for i, (t, pose) in enumerate(zip(self.types, self.X_WB)):
            X[i, :3] = pose.translation()
            X[i, 3 + int(t)] = 1.0
        return X

    def size(self, i: int) -> np.ndarray:
        return np.array(BLOCK_SIZES[int(self.types[i])])

    def corners(self, i: int) -> np.ndarray:
        """(8, 3) world coordinates of block i's corners (kept while block i keeps its pose object: the
        skill's geometry asks for them many times per action)."""
        pose = self.X_WB[i]
        known = self._corners.get(i)
        if known is None or known[0] is not pose:
            known = self._corners[i] = (pose, (pose @ (_CORNER_SIGNS * (self.size(i) / 2)).T).T)
        return known[1]

    def top(self, i: int) -> float:
        return float(self.corners(i)[:, 2].max())

    def bottom(self, i: int) -> float:
        return float(self.corners(i)[:, 2].min())

    def yaw(self, i: int) -> float:
        """Heading of the jaws over block i (radians, 0 for an axis-aligned block): its y axis projected on
        the table, minus 90 degrees. A block tipped so that its y axis stands more than 45 degrees from the
        table has another axis lying on it, whose heading is taken instead (x as it is, z in y's place):
        the projection of a standing axis is a heading of a few millimetres, which turned the jaws across
        a tipped cube's corners."""
        x, y, z = (axis[:2] for axis in self.X_WB[i].rotation().matrix().T)
        if np.linalg.norm(y) >= _LYING:
            return float(np.arctan2(y[1], y[0]) - np.pi / 2)
        if np.linalg.norm(x) >= np.linalg.norm(z):
            return float(np.arctan2(x[1], x[0]))
        return float(np.arctan2(z[1], z[0]) - np.pi / 2)

    def offset_axis_xy(self, i: int) -> np.ndarray:
        """Unit vector on the table along which grasp and release offsets of block i move.

        A block's own axes have an arbitrary sign after physics (a block released at the other
        jaw heading turns by 180 degrees) and the state X holds no yaw, so the axis is chosen from
        what X says: the long axis of a bar, for a cube the horizontal block axis nearest world
        +y, always signed toward world +y (toward +x when it lies across y). For an axis-aligned
        block it is world +y, as in the paper's world. Only the block's axes that lie within 45
        degrees of the table count (a bar standing on its end offers its short axes).
        """
        R = self.X_WB[i].rotation().matrix()
        long_lies = np.linalg.norm(R[:2, 1]) >= _LYING
        axes = [R[:2, 1]] if self.types[i] == LARGE and long_lies else [R[:2, k] for k in range(3)]
        axes = [a / np.linalg.norm(a) for a in axes if np.linalg.norm(a) >= _LYING] or [np.array([0.0, 1.0])]
        axis = max(axes, key=lambda a: abs(a[1]))
        flip = axis[1] < -1e-9 or (abs(axis[1]) <= 1e-9 and axis[0] < 0)
        return -axis if flip else axis

    def inside(self, i: int, p_W: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
        """Which of the points p_W ((k, 3) or (3,), world frame, metres) lie in block i's box grown by `tolerance`."""
        X_WB = self.X_WB[i]
        p_B = (np.atleast_2d(p_W) - X_WB.translation()) @ X_WB.rotation().matrix()
        return np.all(np.abs(p_B) <= self.size(i) / 2 + tolerance, axis=1)

    def contains(self, i: int, p_W: np.ndarray, tolerance: float = 0.0) -> bool:
        return bool(self.inside(i, p_W, tolerance)[0])

    def resting_on(self, i: int, tolerance: float = 0.01) -> list[int]:
        """Blocks whose bottom touches block i's top inside its footprint, recursively."""
        found: list[int] = []
        frontier = [i]
        while frontier:
            k = frontier.pop()
            for j in range(self.n):
                if j == i or j in found:
                    continue
                if abs(self.bottom(j) - self.top(k)) > tolerance:
                    continue
                c = self.X_WB[j].translation()
                probe = np.array([c[0], c[1], self.top(k) - 0.005])
                if self.contains(k, probe, tolerance=0.0):
                    found.append(j)
                    frontier.append(j)
        return found

    def settled(self, tolerance: float) -> "Scene":
        """This scene with every block whose bottom lies within `tolerance` (metres) of what it would rest on (the
        table, or the highest block under its bottom face) moved vertically onto it, lowest block first.

        A predicted state places blocks a few millimetres above or into their support (a regression's mean), and
        the skill's collision checks are exact to the millimetre: a gripper that clears a stacked block predicted
        2 mm low strikes it in the world. A block farther off than `tolerance` (leaning, or on its way down) is
        left where it is."""
        poses = list(self.X_WB)
        scene = Scene(self.types, poses)
        for i in sorted(range(self.n), key=scene.bottom):
            corners = scene.corners(i)
            below = corners[np.argsort(corners[:, 2])[:4]]  # the bottom face's corners
            centre = below.mean(axis=0)
            inward = centre - below
            reach = np.linalg.norm(inward, axis=1, keepdims=True)
            probes = np.vstack([centre, below + inward * np.minimum(1.0, _FOOTPRINT_INSET / np.maximum(reach, 1e-9))])
            bottom, support = scene.bottom(i), 0.0  # the table's top
            for j in range(self.n):
                top = scene.top(j)
                if j == i or not support < top <= bottom + tolerance:
                    continue
                probes[:, 2] = top - 0.005  # just inside block j's top face, under block i's bottom face
                if scene.inside(j, probes).any():
                    support = top
            gap = bottom - support
            if abs(gap) <= tolerance and gap != 0.0:
                poses[i] = RigidTransform(poses[i].rotation(), poses[i].translation() - np.array([0.0, 0.0, gap]))
        return scene


def topdown(p_W: np.ndarray, yaw: float) -> RigidTransform:
    """Tcp pose at p_W pointing down, with y_G along yaw + 90 degrees (the block's y axis)."""
    # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
    return RigidTransform(RotationMatrix.MakeZRotation(yaw) @ RotationMatrix.MakeXRotation(np.pi), p_W)  # type: ignore[arg-type]


def grasp_pose(scene: Scene, action: PickPlace, config: WorldConfig) -> RigidTransform:
    """Tcp pose that closes the jaws around the picked block at its grasp offset."""
    i = action.pick
    c = scene.X_WB[i].translation()
    x, y = c[:2] + action.grasp_offset * OFFSET_STEP * scene.offset_axis_xy(i)
    return topdown(np.array([x, y, scene.top(i) - config.grasp_depth]), scene.yaw(i))


def approach_poses(scene: Scene, action: PickPlace, config: WorldConfig) -> list[tuple[str, RigidTransform]]:
    """The first two tcp poses of the action, known before anything is grasped: jaws open over the
    grasp point (pre-grasp), then down to it (grasp). The same poses as in `pick_place_waypoints`."""
    X_WGrasp = grasp_pose(scene, action, config)
    return [("pregrasp", _raised_to(X_WGrasp, X_WGrasp.translation()[2] + config.approach_height)),
            ("grasp", X_WGrasp)]


def held_block(scene: Scene, X_WG: RigidTransform) -> int:
    """The block the closing jaws hold at X_WG (-1 if none): the grasp point lies inside it and
    its width across the jaws fits the opening."""
    p = X_WG.translation()
    for j in range(scene.n):
        if scene.contains(j, p, tolerance=_GRASP_TOLERANCE):  # type: ignore[arg-type]  # pydrake stubs: translation()
            across = np.abs((X_WG.inverse() @ scene.corners(j).T)[0]).max() * 2
            if across < JAW_OPENING:
                return j
    return -1


def can_hold(block_type: int, grasp_offset: int) -> bool:
    """Whether some pose of a block of `block_type` puts the grasp point of `grasp_offset` inside it: the point
    lies |grasp_offset| * OFFSET_STEP from the block's centre on the table, and no point of the block (with the
    grasp tolerance) is farther than half its diagonal. False for a cube grasped off its centre: `held_block`
    never returns the picked block there, whatever the scene."""
    reach = np.linalg.norm(np.asarray(BLOCK_SIZES[int(block_type)]) / 2 + _GRASP_TOLERANCE)
    return bool(abs(grasp_offset) * OFFSET_STEP <= reach)


@dataclass
class PickWaypoints:
    """The pick half of an action: its first three tcp poses and what they carry away. A function of
    the scene and (pick, grasp offset) alone, so one result serves every place of that grasp."""

    pregrasp: RigidTransform
    grasp: RigidTransform
    liftoff: RigidTransform
    carried: list[int]  # grasped block first, then blocks resting on it
    X_GC: list[RigidTransform]  # each carried block's pose in the tcp frame

    def named(self) -> list[tuple[str, RigidTransform]]:
        return [("pregrasp", self.pregrasp), ("grasp", self.grasp), ("liftoff", self.liftoff)]


@dataclass
class Waypoints(PickWaypoints):
    """Tcp poses of one pick-place, in execution order (the pick half's, then the place's), and the carried
    blocks' grasp."""

    lift: RigidTransform
    preplace: RigidTransform
    place: RigidTransform
    retreat: RigidTransform

    def named(self) -> list[tuple[str, RigidTransform]]:
        return super().named() + [("lift", self.lift), ("preplace", self.preplace), ("place", self.place),
                                  ("retreat", self.retreat)]


def pick_waypoints(scene: Scene, action: PickPlace, grasped: int, config: WorldConfig) -> PickWaypoints:
    """Pre-grasp, grasp and lift-off poses, once `grasped` is known to be held at the grasp pose."""
    (_, X_WPregrasp), (_, X_WGrasp) = approach_poses(scene, action, config)
    carried = [grasped] + scene.resting_on(grasped)
    return PickWaypoints(X_WPregrasp, X_WGrasp, _raised_to(X_WGrasp, X_WGrasp.translation()[2] + config.lift_off),
                         carried, [X_WGrasp.inverse() @ scene.X_WB[c] for c in carried])


def pick_place_waypoints(scene: Scene, action: PickPlace, grasped: int, config: WorldConfig,
                         pick: PickWaypoints | None = None) -> Waypoints:
    """All tcp poses of the action once `grasped` is known to be held at the grasp pose (`pick`: its
    pick half, if already computed)."""
    pick = pick or pick_waypoints(scene, action, grasped, config)
    X_WGrasp, carried, X_GC = pick.grasp, pick.carried, pick.X_GC
    # Depth of the carried blocks' lowest corner below the tcp (a yaw about z keeps it).
    below = X_WGrasp.translation()[2] - min(scene.bottom(c) for c in carried)
    j = action.place
    cj = scene.X_WB[j].translation()
    target_xy = cj[:2] + action.release_offset * OFFSET_STEP * scene.offset_axis_xy(j)
    support = scene.bottom(j) if j == action.pick else scene.top(j)
    place_z = support + config.release_clearance + below
    # Of the two equivalent jaw headings at the target, keep the one nearer the grasp heading.
    grasp_yaw = scene.yaw(action.pick)
    yaw = scene.yaw(j)
    if abs(_wrap(yaw + np.pi - grasp_yaw)) < abs(_wrap(yaw - grasp_yaw)):
        yaw += np.pi
    X_WPlace = topdown(np.array([target_xy[0], target_xy[1], place_z]), yaw)

    others = [k for k in range(scene.n) if k not in carried]
    tallest = max([scene.top(k) for k in others], default=0.0)
    carry_z = max(X_WGrasp.translation()[2] + config.approach_height,
                  place_z + config.approach_height,
                  tallest + config.carry_clearance + below)
    up = _raised_to
    return Waypoints(
        pregrasp=pick.pregrasp,
        grasp=X_WGrasp,
        liftoff=pick.liftoff,
        lift=up(X_WGrasp, carry_z),
        preplace=up(X_WPlace, carry_z),
        place=X_WPlace,
        retreat=up(X_WPlace, place_z + config.approach_height),
        carried=carried,
        X_GC=X_GC,
    )


Box = tuple[tuple[float, float, float], RigidTransform]  # (size in metres, pose in the gripper body frame)


def carried_size(block_type: int, config: WorldConfig) -> tuple[float, float, float]:
    """Size (metres) of a carried block's collision box: narrowed by `config.carried_inset` on each side, so
    that a block standing face to face with another one slides up past it, which a padded box the block's
    full width would call a collision."""
    sx, sy, sz = BLOCK_SIZES[int(block_type)]
    inset = 2 * config.carried_inset
    return (sx - inset, sy - inset, sz)


def carried_shapes(scene: Scene, wp: PickWaypoints, config: WorldConfig) -> list[Box]:
    """Collision boxes of the carried blocks in the gripper body frame (`MotionPlanner.attach`), of
    `carried_size`."""
    return [(carried_size(scene.types[c], config), X_FlangeTcp @ X_GC) for c, X_GC in zip(wp.carried, wp.X_GC)]


def _raised_to(X_WG: RigidTransform, z: float) -> RigidTransform:
    """X_WG moved vertically to height z (metres), orientation kept."""
    x, y, _ = X_WG.translation()
    return RigidTransform(X_WG.rotation(), np.array([x, y, z]))  # type: ignore[arg-type]  # pydrake stubs


def _wrap(a: float) -> float:
    return (a + np.pi) % (2 * np.pi) - np.pi


def boxes_overlap(X_WA: RigidTransform, size_A, X_WB: RigidTransform, size_B, margin: float = 1e-4) -> bool:
    """Whether two boxes (sizes in metres, centred at their poses) interpenetrate by more than `margin`
    along every separating axis (the 15 of the separating axis theorem): then any collision checker that
    knows these boxes reports a collision. A cheap, conservative test: False does not mean free."""
    return penetration(X_WA, size_A, X_WB, size_B)[0] > margin


def penetration(X_WA: RigidTransform, size_A, X_WB: RigidTransform, size_B) -> tuple[float, np.ndarray]:
    """(metres, unit axis from A towards B): how far box B must move along the axis (of the 15 of the separating
    axis theorem, the one of least overlap) to leave box A; depth 0 or less when a separating axis exists (-inf
    when their bounding spheres do not meet)."""
    h_A, h_B = np.asarray(size_A, dtype=float) / 2, np.asarray(size_B, dtype=float) / 2
    T = np.asarray(X_WB.translation()) - np.asarray(X_WA.translation())
    if np.linalg.norm(T) >= np.linalg.norm(h_A) + np.linalg.norm(h_B):  # their bounding spheres do not meet
        return -np.inf, np.zeros(3)
    R_A, R_B = X_WA.rotation().matrix(), X_WB.rotation().matrix()
    cross = np.einsum("klm,il,jm->ijk", _LEVI_CIVITA, R_A.T, R_B.T).reshape(9, 3)  # every edge pair's axis
    axes = np.concatenate([R_A.T, R_B.T, cross])
    norms = np.linalg.norm(axes, axis=1)
    axes = axes[norms > 1e-9] / norms[norms > 1e-9, None]  # parallel edges give no axis of their own
    along = axes @ T
    overlap = np.abs(axes @ R_A) @ h_A + np.abs(axes @ R_B) @ h_B - np.abs(along)
    k = int(np.argmin(overlap))
    return float(overlap[k]), axes[k] * (1.0 if along[k] >= 0 else -1.0)

