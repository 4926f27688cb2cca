"""Perception: the blocks of a scene from depth images alone (no label image), as the planner's state.

    seen = perceive(views, PerceptionConfig(), previous=X_before)
    seen.X          # (n, 5): block centres (m) and one-hot types, in the order of `previous`
    seen.failures   # what was not explained: a block missing, merged blocks, points that fit no block

The pipeline (numpy and scipy, no renderer; `tamp.sim.cameras` renders the views):
1. each camera's depth image back-projected to the world frame and fused; cropped to the table's workspace and
   the table removed by its known height (z = 0); averaged in voxel_m cubes; normals from each point's nearest
   neighbours (PCA) (`tamp.sim.point_cloud`);
2. top faces: the upward-facing points split into connected patches, the highest layer first and in it the
   largest patch (a bar's end piece proposes the whole bar; a piece between the blocks on it cannot). Each patch
   proposes upright blocks (a cube, or a bar along the patch, its ends at either end of the patch: a block on top
   may hide part of it), each fitted to the points of the block's height slab (`box_fit.fit_box` over x, y, yaw;
   the height from the face). A hypothesis that a camera saw through (`box_fit.seen_through`), or that holds the
   centre of a block found (or whose centre a block found holds), is dropped; of the others the one that explains
   most points (less those seen inside it) is kept, and its points leave the cloud; a bar most of whose top is
   hidden waits for step 3, since what hides it may lean on it. Blocks side by side at one height share a patch:
   what a block leaves of it is a patch again;
3. what is left is clustered, and each cluster fitted in turn from four families of proposals: upright blocks
   from a layer's outline and from each single side face (a block whose top a leaning bar or an overhang hides),
   blocks with six degrees of freedom from the largest upward face (leaning and toppled blocks) and from each
   vertical face (a leaning block whose top another covers shows only its sides). Then a block that explains
   little its neighbours do not, once they are refitted jointly to the points of all of them, is dropped (a
   piece of a pile fitted on its own). A left-over block that explains _DISPLACE times the points of blocks found
   whose centres it holds (or that hold its centre) replaces them: the lower end of a leaning bar, whose top looked
   flat at a block's height, is fitted as a cube in step 2;
4. with `previous`, its count and types (a closed loop knows them; positions may be stale, since a block moved):
   where the blocks found disagree with them, the explanations they name are tried on the points, to looser
   thresholds, and kept only where the points support them (not seen through, no overlap): two cubes for a bar
   fitted over a cube and the cube beyond it (the second's top proposed a bar running hidden under a block the
   first carries), a bar for the cubes fitted to pieces of its top (its ends hidden), a block of a type still
   missing among the points left. Such blocks are marked `prior`. What the points do not resolve stays a
   disagreement and is said in step 5; the prior never adds a block the points do not show;
5. identities: the estimates assigned to `previous` (where the blocks are expected, or the problem's scene) by
   `scipy.optimize.linear_sum_assignment` on distance and type, since goals name blocks. A block of `previous`
   with no estimate is said to be missing, an estimate with none an extra; points no block explains are said.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from enum import StrEnum

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial import cKDTree

from tamp.planning.vocabulary import BLOCK_HEIGHT, LARGE, SMALL, TYPE_NAMES
from tamp.sim.box_fit import (
    MIN_PATCH,
    TILTED_RAD,
    box_sdf,
    boxes_sdf,
    boxes_sdf_near,
    components,
    face_hypotheses,
    fit_each,
    fit_jointly,
    footprint_hypotheses,
    half_size,
    pose,
    seen_through_boxes,
    side_hypotheses,
    tilted_side_hypotheses,
    vertical_faces,
)
from tamp.sim.perception_config import PerceptionConfig
from tamp.sim.point_cloud import NEIGHBOURS, DepthView, Normals, fused_cloud

#   (4 sigma of the noise on the table at 1.1 m) removes the table
UP_COS = 0.97  # a point whose normal is within 14 degrees of vertical belongs to a top face
EXPLAINED_M = 0.005  # metres: a point this close to (or inside) an accepted box is that block's
MAX_SEEN_THROUGH = 0.12  # share of a hypothesis' face samples the cameras may have seen through
MIN_CLUSTER = 40  # points of a left-over cluster worth a block (fewer: speckle, said as unexplained)
MIN_EXPLAINED = 0.7  # a left-over block's fit must explain this share of the points within _VICINITY_M of it
_TIE = 0.93  # a smaller box whose score is within this factor of a larger one's is preferred (a cube over a bar)
_FITTED = 4  # hypotheses fitted per patch or cluster, those that explain most before the fit
_INSIDE_WEIGHT = 3  # a point seen inside a hypothesis' box counts against it this many times what one on it counts for
_HIDDEN_BAR_M = 0.15  # metres: a bar whose top face shows less of its length than this is left to step 3
_UNDER_TABLE_M = 0.01  # metres: a box reaching farther into the table is no block
_LEVEL_M = 0.008  # metres: a block resting flat has its top face this close to a whole number of block heights
_FLAT_QUALITY = 0.5  # a block resting flat must explain this share of the points within _VICINITY_M of it
_VICINITY_M = 0.01  # metres: the points a left-over block's fit is judged on
_PRIOR_MIN = 20  # points that a block of a type the prior misses must explain (MIN_CLUSTER otherwise)
_PRIOR_QUALITY = 0.5  # the share of its vicinity's points such a block must explain (MIN_EXPLAINED otherwise)
_DISPLACE = 3  # a left-over block may replace the blocks found it overlaps, explaining this many times their points
_FIT_REACH_M = 0.02  # metres: a hypothesis is fitted to the points this close to its starting box
# step 3's families of hypotheses (`_best_box` fits the best few of each): upright from a layer's outline, upright
# from a side face, six degrees of freedom from the largest upward face, and from a vertical face (leaning blocks only)
_OUTLINE, _SIDES, _TOP_FACE, _LEANING_SIDES = range(4)


class Failure(StrEnum):
    """What perception could not explain; never silent."""

    MISSING = "missing"  # a block of `previous` has no estimate
    EXTRA = "extra"  # an estimate that matches no block of `previous` (a ghost, or a block split in two)
    MERGED = "merged"  # a top face wider than any block, or side by side blocks no known box shape separates
    UNEXPLAINED = "unexplained"  # points that fit no block (a block half seen, two blocks touching at a tilt)


@dataclass(frozen=True)
class PerceptionFailure:
    kind: Failure
    reason: str  # in words, with where (metres)
    block: int = -1  # the block of `previous` it concerns (-1: none)


@dataclass(frozen=True)
class BlockEstimate:
    """One perceived block: its type and pose, with the points that explain it."""

    type: int  # SMALL or LARGE
    X_WB: np.ndarray  # (4, 4) pose in the world
    points: int  # fused points its box explains
    upright: bool  # fitted as resting flat (x, y, yaw), else with six degrees of freedom
    prior: bool = False  # found because `previous` named its type (a bar's hidden ends, a block half seen)

    @property
    def position(self) -> np.ndarray:
        return self.X_WB[:3, 3]

    @property
    def tilt(self) -> float:
        """Radians between the world's z and the block axis nearest it (0 for a block resting flat)."""
        return float(np.arccos(np.clip(np.abs(self.X_WB[2, :3]).max(), 0.0, 1.0)))

    @property
    def yaw(self) -> float:
        """Heading (radians) of the block's y axis (a bar's long axis) projected on the table, in [-pi/2, pi/2)."""
        y = self.X_WB[:2, 1]
        return float(np.mod(np.arctan2(y[1], y[0]) + np.pi / 2, np.pi) - np.pi / 2)


@dataclass
class Perception:
    """The blocks seen, in the order of `previous` where it was given."""

    blocks: list[BlockEstimate]
    identity: list[int]  # each block's index in `previous` (-1: an extra); without `previous`, 0, 1, ...
    failures: list[PerceptionFailure] = field(default_factory=list)
    points: int = 0  # fused points above the table

    @property
    def X(self) -> np.ndarray:
        """The planner's state (n, 5): positions (m) and one-hot types."""
        X = np.zeros((len(self.blocks), 5))
        for i, block in enumerate(self.blocks):
            X[i, :3], X[i, 3 + block.type] = block.position, 1.0
        return X

    @property
    def ok(self) -> bool:
        return not self.failures


def _scores(distance: np.ndarray) -> np.ndarray:
    """Each box's support from the points at these signed distances (boxes, points): those on its surface, less
    _INSIDE_WEIGHT for each one inside it (a surface the cameras saw inside a solid box is evidence against it)."""
    on = np.count_nonzero(np.abs(distance) < EXPLAINED_M, axis=1)
    return on - _INSIDE_WEIGHT * np.count_nonzero(distance <= -EXPLAINED_M, axis=1)


def _overlapped(X_WB: np.ndarray, block_type: int, found: Sequence[BlockEstimate]) -> list[BlockEstimate]:
    """The blocks `found` that the box at X_WB holds the centre of, or whose box holds its centre (solid blocks
    cannot)."""
    half = half_size(block_type)
    return [b for b in found if box_sdf(b.X_WB, half_size(b.type), X_WB[None, :3, 3])[0] < 0.0
            or box_sdf(X_WB, half, b.position[None])[0] < 0.0]


def _best_box(points: np.ndarray, candidates: np.ndarray, hypotheses, views, quality: float = 0.0,
              found: Sequence[BlockEstimate] = (), displace: bool = False):
    """(points explained, estimate, which of `candidates` it explains, the blocks `found` it overlaps) of the fitted
    hypothesis (type, initial pose, upright) that explains most of `candidates` and that no camera saw through (a
    smaller box wins a near tie), of those whose points within _VICINITY_M lie on its surface for at least the share
    `quality` and that do not overlap a block `found` (with `displace`: or that explain _DISPLACE times the points
    of those they overlap); None when there is none. Only the _FITTED hypotheses of each family (an optional fourth
    item) that explain most before the fit are fitted (a fit costs milliseconds; one family's many near misses must
    not crowd out another's right guess). The hypotheses are tested and fitted together (`box_fit`'s batched
    forms): numpy's time is in its calls more than in their sizes."""
    if not hypotheses:
        return None
    types = np.array([h[0] for h in hypotheses])
    X0 = np.array([h[1] for h in hypotheses])
    upright = np.array([h[2] for h in hypotheses], dtype=bool)
    family = np.array([h[3] if len(h) > 3 else 0 for h in hypotheses])
    half = np.array([half_size(t) for t in types])
    near = np.flatnonzero(seen_through_boxes(X0, types, views) <= 2 * MAX_SEEN_THROUGH)  # far off: most wrong
    #   ones end here
    ranked = near[np.argsort(-_scores(boxes_sdf_near(X0[near], half[near], candidates, EXPLAINED_M)), kind="stable")]
    chosen = np.array([i for f in sorted(set(family[ranked].tolist())) for i in ranked[family[ranked] == f][:_FITTED]],
                      dtype=int)
    if not len(chosen):
        return None
    reach = boxes_sdf_near(X0[chosen], half[chosen], points, _FIT_REACH_M) < _FIT_REACH_M
    X = fit_each([points[r] for r in reach], half[chosen], X0[chosen], upright[chosen])
    half, types, upright, family = half[chosen], types[chosen], upright[chosen], family[chosen]
    level = np.abs(X[:, 2, :3]).max(axis=1) > np.cos(TILTED_RAD)  # a block resting flat is proposed upright
    #   from its sides (a 6-DOF fit from a vertical face drifted 8 mm)
    bottom = X[:, 2, 3] - np.einsum("ki,ki->k", np.abs(X[:, 2, :3]), half)
    keep = ~((family == _LEANING_SIDES) & level) & (bottom >= -_UNDER_TABLE_M)  # through the table, where no
    #   camera sees: no block
    keep[keep] = seen_through_boxes(X[keep], types[keep], views) <= MAX_SEEN_THROUGH
    distance = boxes_sdf_near(X[keep], half[keep], candidates, _VICINITY_M)
    scores = np.zeros(len(X), dtype=int)
    scores[keep] = _scores(distance)
    vicinity = np.zeros(len(X), dtype=int)
    vicinity[keep] = np.count_nonzero(np.abs(distance) < _VICINITY_M, axis=1)
    row = np.cumsum(keep) - 1
    best = None
    for k in np.flatnonzero(keep):
        if scores[k] < quality * vicinity[k]:
            continue
        overlapped = _overlapped(X[k], int(types[k]), found)
        if overlapped and not (displace and scores[k] >= _DISPLACE * sum(b.points for b in overlapped)):
            continue
        volume = float(np.prod(half[k]))
        if best is None or (scores[k] > best[0] / _TIE if volume > best[2] else scores[k] >= best[0] * _TIE):
            best = (int(scores[k]), k, volume, overlapped)
    if best is None:
        return None
    k = best[1]
    block = BlockEstimate(int(types[k]), X[k], best[0], bool(upright[k]))
    return best[0], block, distance[row[k]] < EXPLAINED_M, best[3]


def _carries(block: BlockEstimate, found: list[BlockEstimate]) -> bool:
    """Whether one of the blocks `found` rests flat on `block`'s top face (its centre above the face)."""
    half = half_size(block.type)
    for other in found:
        bottom = other.position - [0.0, 0.0, BLOCK_HEIGHT / 2]
        if other.upright and box_sdf(block.X_WB, half, bottom[None])[0] < EXPLAINED_M:
            return True
    return False


def _top_faces(p: np.ndarray, normals: Normals, free: np.ndarray, views, voxel: float, found: list,
               failures: list) -> None:
    """Step 2 of the pipeline: upright blocks from the top face patches, the highest first."""
    high = np.flatnonzero(free & (p[:, 2] > BLOCK_HEIGHT - 0.01))
    up = high[np.abs(normals(high)[:, 2]) > UP_COS]
    queue = [up[c] for c in components(p[up], 2.5 * voxel) if len(c) >= MIN_PATCH]
    while queue:
        queue.sort(key=lambda c: (round(float(np.median(p[c, 2])) / BLOCK_HEIGHT), len(c)))  # the highest layer, its
        #   largest patch first: a bar's end piece proposes the bar that a piece between blocks on it cannot
        patch = queue.pop()
        patch = patch[free[patch]]
        if len(patch) < MIN_PATCH:
            continue
        top = float(np.median(p[patch, 2]))
        if abs(top - BLOCK_HEIGHT * round(top / BLOCK_HEIGHT)) > _LEVEL_M:
            continue  # no block resting flat on the table or on flat blocks has its top there: left to step 3
        near = np.flatnonzero(free & (np.linalg.norm(p[:, :2] - p[patch, :2].mean(axis=0), axis=1) < 0.3))
        slab = near[(p[near, 2] > top - BLOCK_HEIGHT + 0.006) & (p[near, 2] < top + 0.006)]
        hypotheses = face_hypotheses(p[patch], np.array([0.0, 0.0, 1.0]), BLOCK_HEIGHT / 2)
        best = _best_box(p[slab], p[near], [(t, X0, True) for t, X0 in hypotheses], views, _FLAT_QUALITY, found)
        if best is None:  # not a block resting flat (a leaning one's top, or blocks merged): left to step 3
            continue
        _, block, explained, _ = best
        if block.type == LARGE and np.ptp(p[patch] @ block.X_WB[:3, 1]) < _HIDDEN_BAR_M and not _carries(block, found):
            continue  # most of the bar's top unseen, and no block found on it: what hides it may lean on it (step 3)
        found.append(block)
        free[near[explained]] = False
        rest = patch[free[patch]]
        queue.extend(rest[c] for c in components(p[rest], 2.5 * voxel) if len(c) >= MIN_PATCH)


def _tilted_face(p: np.ndarray, normals: Normals, cluster: np.ndarray, voxel: float) -> tuple[np.ndarray, np.ndarray]:
    """The largest face of a cluster that looks up at all (a leaning block's top): its points and outward normal."""
    n = normals(cluster)
    n *= np.where(n[:, 2] < 0, -1.0, 1.0)[:, None]
    upward = np.flatnonzero(n[:, 2] > 0.3)
    if len(upward) < MIN_PATCH:
        return np.zeros((0, 3)), np.array([0.0, 0.0, 1.0])
    sample = upward[:: max(1, len(upward) // 200)]
    normal = n[sample[np.argmax((n[sample] @ n[sample].T > 0.97).sum(axis=1))]]
    on_face = cluster[n @ normal > 0.95]
    face = on_face[components(p[on_face], 2.5 * voxel)[0]] if len(on_face) else on_face
    return p[face], normal


def _cluster_hypotheses(p: np.ndarray, normals: Normals, cluster: np.ndarray, voxel: float) -> list:
    """(type, initial pose, upright, family) of the blocks a cluster's points may be, in four families: upright
    blocks from its layers' outline, upright blocks from its vertical faces, blocks with six degrees of freedom from
    its largest upward face and from its vertical faces."""
    face, normal = _tilted_face(p, normals, cluster, voxel)
    hypotheses = [(t, X0, True, _OUTLINE) for t, X0 in footprint_hypotheses(p[cluster])]
    n = normals(cluster)
    faces = vertical_faces(p[cluster], n, voxel)
    hypotheses += [(t, X0, True, _SIDES) for t, X0 in side_hypotheses(faces)]
    hypotheses += [(t, X0, False, _LEANING_SIDES) for t, X0 in tilted_side_hypotheses(faces)]
    if len(face) >= MIN_PATCH:
        hypotheses += [(t, X0, False, _TOP_FACE) for t, X0 in face_hypotheses(face, normal, BLOCK_HEIGHT / 2)]
    return hypotheses


def _left_over(p: np.ndarray, normals: Normals, free: np.ndarray, views, voxel: float, found: list) -> None:
    """Step 3 of the pipeline: the clusters left, as blocks whose top face is hidden (upright, from their sides'
    outline) or that lean (six degrees of freedom, from their largest upward face)."""
    left = np.flatnonzero(free)
    for cluster in components(p[left], 2.5 * voxel):
        cluster = left[cluster]
        while len(cluster) >= MIN_CLUSTER:
            hypotheses = _cluster_hypotheses(p, normals, cluster, voxel)
            best = _best_box(p[cluster], p[cluster], hypotheses, views, MIN_EXPLAINED, found, displace=True)
            if best is None or best[0] < MIN_CLUSTER:
                break
            if best[3]:  # blocks it overlaps, a few times smaller: pieces of it (the lower end of a leaning bar
                #   fitted as a cube from its top faces' step); their points go to it, or back to the cloud
                found[:] = [b for b in found if not any(b is d for d in best[3])]
                back = np.any([box_sdf(b.X_WB, half_size(b.type), p) < EXPLAINED_M for b in best[3]], axis=0)
                for other in [*found, best[1]]:
                    back &= box_sdf(other.X_WB, half_size(other.type), p) >= EXPLAINED_M
                free |= back
            found.append(best[1])
            free[cluster[best[2]]] = False
            cluster = cluster[~best[2]]


def _without_extras(p: np.ndarray, views, found: list) -> None:
    """The end of step 3: a block that explains little the blocks touching it do not (a piece of a pile fitted on
    its own beside a neighbour fitted a little off) is dropped, where those neighbours, refitted jointly to the
    points of all of them (each point to its nearest box), explain all but fewer than MIN_CLUSTER of what they
    explained with it, and no camera sees through them. The weakest block is tried first."""
    reaches: dict[int, tuple[BlockEstimate, np.ndarray]] = {}  # each block's points within _FIT_REACH_M, by id

    def reach_of(block: BlockEstimate) -> np.ndarray:
        if id(block) not in reaches or reaches[id(block)][0] is not block:
            reaches[id(block)] = (block, box_sdf(block.X_WB, half_size(block.type), p) < _FIT_REACH_M)
        return reaches[id(block)][1]

    for block in sorted(found, key=lambda b: b.points):
        if not any(b is block for b in found):
            continue
        others = [b for b in found if b is not block]
        if not others:
            continue
        reach = np.array([reach_of(b) for b in others])
        mine = reach_of(block)
        touching = np.any(reach[:, mine], axis=1)
        near = [b for b, t in zip(others, touching) if t]
        if not near:
            continue
        q = p[mine | np.any(reach[touching], axis=0)]
        half = _halves(near)
        before = np.abs(np.min(boxes_sdf(_poses([block, *near]), _halves([block, *near]), q), axis=0))
        fitted = fit_jointly(q, half, _poses(near), range(len(near)), np.array([b.upright for b in near]))
        after = np.abs(np.min(boxes_sdf(fitted, half, q), axis=0))
        lost = int(np.count_nonzero(before < EXPLAINED_M)) - int(np.count_nonzero(after < EXPLAINED_M))
        if lost >= MIN_CLUSTER or np.any(seen_through_boxes(fitted, np.array([b.type for b in near]), views)
                                         > MAX_SEEN_THROUGH):
            continue
        moved = {id(b): replace(b, X_WB=X) for X, b in zip(fitted, near)}
        found[:] = [moved.get(id(b), b) for b in found if b is not block]


def _poses(blocks: Sequence[BlockEstimate]) -> np.ndarray:
    return np.array([b.X_WB for b in blocks]).reshape(-1, 4, 4)


def _halves(blocks: Sequence[BlockEstimate]) -> np.ndarray:
    return np.array([half_size(b.type) for b in blocks]).reshape(-1, 3)


def _cubes_for_a_bar(p: np.ndarray, free: np.ndarray, views, found: list, want: np.ndarray) -> None:
    """Where the prior (`want`: blocks of each type) has fewer bars and at least two more cubes than found: a bar
    resting flat over two cubes in a row (one cube's top proposed a bar whose hidden rest runs under a block carried
    by the other) is replaced by two cubes fitted to its points, where they explain as much (_TIE) and no camera
    sees through them. The weakest bar is tried first; the cubes are marked `prior`."""
    for bar in sorted([b for b in found if b.type == LARGE and b.upright], key=lambda b: b.points):
        count = np.bincount([b.type for b in found], minlength=2)
        if count[LARGE] <= want[LARGE] or count[SMALL] + 2 > want[SMALL]:
            return
        distance = box_sdf(bar.X_WB, half_size(LARGE), p)
        near = np.flatnonzero((free | (distance < EXPLAINED_M)) & (distance < _VICINITY_M))
        others = [b for b in found if b is not bar]
        cubes: list[BlockEstimate] = []
        for _ in range(2):
            hypotheses = [(SMALL, pose(bar.X_WB[:3, :3], bar.position + s * bar.X_WB[:3, 1]), True)
                          for s in (-0.1, -0.05, 0.0, 0.05, 0.1)]
            best = _best_box(p[near], p[near], hypotheses, views, _FLAT_QUALITY, others + cubes)
            if best is None:
                break
            cubes.append(replace(best[1], prior=True))
            free[near[best[2]]] = False
            near = near[~best[2]]
        if len(cubes) == 2 and sum(c.points for c in cubes) >= _TIE * bar.points:
            found[:] = others + cubes


def _with_prior(p: np.ndarray, normals: Normals, free: np.ndarray, views, voxel: float, found: list,
                prior_types: np.ndarray) -> None:
    """Where the blocks found and the prior's types (`previous`) disagree, the explanations the prior names and the
    points support: two cubes for a bar over two cubes (`_cubes_for_a_bar`), a bar for a cube fitted to a bar's
    visible middle (its ends hidden), and a block of a type the prior has more of among the points left, to looser
    thresholds. These blocks are marked `prior`; what the points do not resolve stays a disagreement, which
    `assign` says."""
    want = np.bincount(prior_types, minlength=2)

    def short(block_type: int) -> int:
        return int(want[block_type]) - sum(b.type == block_type for b in found)

    _cubes_for_a_bar(p, free, views, found, want)
    up = np.array([0.0, 0.0, 1.0])
    for cube in sorted([b for b in found if b.type == SMALL and b.upright], key=lambda b: b.points):
        if short(LARGE) <= 0 or short(SMALL) >= 0 or not any(b is cube for b in found):
            continue
        layer = [b for b in found if b.type == SMALL and b.upright and abs(b.position[2] - cube.position[2]) < 0.01]
        mine = np.any([box_sdf(b.X_WB, half_size(SMALL), p) < EXPLAINED_M for b in layer], axis=0)
        near = np.flatnonzero((free | mine) & (np.linalg.norm(p[:, :2] - cube.position[:2], axis=1) < 0.2)
                              & (np.abs(p[:, 2] - cube.position[2]) < BLOCK_HEIGHT / 2 + 0.006))
        hypotheses = [(LARGE, pose(np.column_stack([np.cross(axis, up), axis, up]), cube.position + s * axis), True)
                      for axis in (cube.X_WB[:3, 0], cube.X_WB[:3, 1]) for s in (-0.1, 0.0, 0.1)]
        others = [b for b in found if not any(b is c for c in layer)]
        best = _best_box(p[near], p[near], hypotheses, views, _FLAT_QUALITY, others)
        if best is None:
            continue
        bar = best[1]  # it replaces the cubes of the layer whose centres it holds (pieces of its visible top)
        pieces = [b for b in layer if box_sdf(bar.X_WB, half_size(LARGE), b.position[None])[0] < 0.0]
        if best[0] >= _TIE * sum(b.points for b in pieces):
            found[:] = [b for b in found if not any(b is c for c in pieces)] + [replace(bar, prior=True)]
            free[near[best[2]]] = False
    left = np.flatnonzero(free)
    for cluster in components(p[left], 2.5 * voxel):
        cluster = left[cluster]
        while len(cluster) >= _PRIOR_MIN and max(short(SMALL), short(LARGE)) > 0:
            hypotheses = [h for h in _cluster_hypotheses(p, normals, cluster, voxel) if short(h[0]) > 0]
            best = _best_box(p[cluster], p[cluster], hypotheses, views, _PRIOR_QUALITY, found)
            if best is None or best[0] < _PRIOR_MIN:
                break
            found.append(replace(best[1], prior=True))
            free[cluster[best[2]]] = False
            cluster = cluster[~best[2]]


def _unexplained(p: np.ndarray, free: np.ndarray, voxel: float) -> list[PerceptionFailure]:
    """The clusters of points no block explains, said."""
    left = np.flatnonzero(free)
    said = []
    for cluster in components(p[left], 2.5 * voxel):
        if len(cluster) < MIN_CLUSTER:
            break
        x, y, z = p[left[cluster]].mean(axis=0)
        said.append(PerceptionFailure(Failure.UNEXPLAINED, f"{len(cluster)} points about ({x:.3f}, {y:.3f}, {z:.3f}) m "
                                      "fit no block"))
    return said


def assign(blocks: list[BlockEstimate], previous: np.ndarray) -> tuple[list[BlockEstimate], list[int],
                                                                        list[PerceptionFailure]]:
    """The estimates in the order of the blocks of `previous` (n, 5), by the assignment of least total distance (a
    block of another type costs 1 m more), the estimates left over after them; each one's block of `previous` (-1
    for one left over); the blocks missing and the estimates left over, said."""
    cost = np.zeros((len(previous), len(blocks)))
    if cost.size:
        cost = np.linalg.norm(previous[:, None, :3] - np.array([b.position for b in blocks])[None], axis=2)
        cost += np.argmax(previous[:, 3:], axis=1)[:, None] != np.array([b.type for b in blocks])[None]
    rows, cols = linear_sum_assignment(cost)
    matched = dict(zip(cols.tolist(), rows.tolist()))
    order = sorted(range(len(blocks)), key=lambda c: matched.get(c, len(previous) + c))
    failures = [PerceptionFailure(Failure.MISSING, f"block {i} ({TYPE_NAMES[int(np.argmax(previous[i, 3:]))]}, "
                                  f"expected at {_at_xyz(previous[i, :3])} m) not seen", i)
                for i in range(len(previous)) if i not in set(rows.tolist())]
    failures += [PerceptionFailure(Failure.EXTRA, f"a {TYPE_NAMES[blocks[c].type]} at {_at_xyz(blocks[c].position)} m "
                                   "matches no block") for c in order if c not in matched]
    return [blocks[c] for c in order], [matched.get(c, -1) for c in order], failures


def _at_xyz(p: np.ndarray) -> str:
    return f"({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f})"


def perceive(views: list[DepthView], config: PerceptionConfig, previous: np.ndarray | None = None) -> Perception:
    """The blocks the depth `views` show (see the module docstring); with `previous` (n, 5) in its order."""
    p = fused_cloud(views, config.voxel_m)
    free = np.ones(len(p), dtype=bool)
    found: list[BlockEstimate] = []
    failures: list[PerceptionFailure] = []
    if len(p) >= NEIGHBOURS:
        normals = Normals(p, cKDTree(p))
        _top_faces(p, normals, free, views, config.voxel_m, found, failures)
        _left_over(p, normals, free, views, config.voxel_m, found)
        _without_extras(p, views, found)
        if previous is not None:
            _with_prior(p, normals, free, views, config.voxel_m, found, np.argmax(np.asarray(previous)[:, 3:], axis=1))
        failures += _unexplained(p, free, config.voxel_m)
    identity = list(range(len(found)))
    if previous is not None:
        found, identity, said = assign(found, np.asarray(previous, dtype=float))
        failures += said
    return Perception(found, identity, failures, len(p))


__all__ = ["BlockEstimate", "DepthView", "Failure", "Perception", "PerceptionFailure", "assign", "fused_cloud",
           "perceive"]
