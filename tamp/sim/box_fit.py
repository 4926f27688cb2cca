"""Fitting the known block boxes to points: where a fit may start (blocks proposed from a face, a layer's outline or
a side seen alone), a box's signed distance, its least-squares pose, the free space the cameras saw through it, its
orientation error up to the box's symmetries. numpy and scipy only.

Poses are (4, 4) homogeneous matrices X_WB (block B in the world W), lengths metres, angles radians.
"""
from __future__ import annotations

from functools import cache
from itertools import permutations, product

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, cKDTree
from scipy.spatial.transform import Rotation

from tamp.planning.vocabulary import BLOCK_HEIGHT, BLOCK_SIZES, LARGE, SMALL

FIT_SCALE_M = 0.002  # metres: residuals beyond this weigh less and less (Cauchy), so neighbours' points do not pull
FIT_POINTS = 250  # points a fit uses at most (an even subsample): enough for sub-millimetre poses, and fast
SEEN_THROUGH_M = 0.008  # metres: a camera that measured this much farther than a box's surface saw through it
_FACE_INSET_M = 0.004  # metres: free-space samples keep this far inside a face's edges (pose errors at silhouettes)
_SAMPLE_STEP_M = 0.01  # metres between free-space samples on a box's faces
MIN_PATCH = 12  # points of a face worth a hypothesis (a 5 cm face holds about 150 at 4 mm)
TILTED_RAD = np.radians(5.0)  # a block proposed from a vertical face with six degrees of freedom leans more: a
#   6-DOF fit of an upright block hidden but for its sides drifted 8 mm where the upright fit did not
_GRAZING_COS = 0.34  # a face seen more obliquely than 70 degrees by a camera is not checked against it


def half_size(block_type: int) -> np.ndarray:
    return np.array(BLOCK_SIZES[int(block_type)]) / 2


def pose(R: np.ndarray, p: np.ndarray) -> np.ndarray:
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, p
    return X


def box_sdf(X_WB: np.ndarray, half: np.ndarray, p_W: np.ndarray) -> np.ndarray:
    """Signed distance (metres, negative inside) of the points p_W (k, 3) to the box of half sizes `half` at X_WB."""
    q = np.abs((p_W - X_WB[:3, 3]) @ X_WB[:3, :3]) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def _sdf_and_gradient(X_WB: np.ndarray, half: np.ndarray, p_W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """box_sdf of the points and its gradient with respect to the points (k, 3), in the world frame."""
    R, c = X_WB[:3, :3], X_WB[:3, 3]
    p_B = (p_W - c) @ R
    q = np.abs(p_B) - half
    out = np.maximum(q, 0.0)
    distance = np.linalg.norm(out, axis=1)
    outside = distance > 0
    g_B = np.zeros_like(p_B)
    g_B[outside] = out[outside] / distance[outside, None]
    nearest = np.argmax(q, axis=1)
    inside = np.flatnonzero(~outside)
    g_B[inside, nearest[inside]] = 1.0
    g_B *= np.where(p_B < 0, -1.0, 1.0)
    return distance + np.minimum(q.max(axis=1), 0.0), g_B @ R.T


def fit_box(points: np.ndarray, half: np.ndarray, X0: np.ndarray, upright: bool, iterations: int = 15) -> np.ndarray:
    """The pose near X0 whose box surface passes closest to `points`: Gauss-Newton on the signed distance with
    Cauchy weights (iteratively reweighted), so that a neighbour's points do not pull. `upright`: only x, y and the
    yaw about the world's z move (a block resting flat, its height known from its top face)."""
    if len(points) > FIT_POINTS:
        points = points[np.linspace(0, len(points) - 1, FIT_POINTS).astype(int)]
    columns = [2, 3, 4] if upright else list(range(6))  # of (rotation about x, y, z; translation x, y, z)
    if len(points) < 2 * len(columns):
        return X0
    X = X0.copy()
    for _ in range(iterations):
        r, g_W = _sdf_and_gradient(X, half, points)
        # a small rotation w about the centre and a translation dc move the points' box coordinates by
        # -(w x d) and -dc (d = p - c): the signed distance changes by -(d x g).w - g.dc
        J = -np.hstack([np.cross(points - X[:3, 3], g_W), g_W])[:, columns]
        w = 1.0 / (1.0 + (r / FIT_SCALE_M) ** 2)
        step = np.zeros(6)
        step[columns] = np.linalg.lstsq(J * np.sqrt(w)[:, None], -r * np.sqrt(w), rcond=None)[0]
        X = pose(Rotation.from_rotvec(step[:3]).as_matrix() @ X[:3, :3], X[:3, 3] + step[3:])
        if np.abs(step).max() < 1e-5:
            break
    return X


def leans(X_WB: np.ndarray) -> bool:
    """Whether the box at X_WB tilts more than TILTED_RAD (none of its axes that close to the world's z)."""
    return bool(np.abs(X_WB[2, :3]).max() < np.cos(TILTED_RAD))


def fit_boxes(points: np.ndarray, halves: list[np.ndarray], poses: list[np.ndarray], moving: list[int],
              upright: list[bool], rounds: int = 2) -> list[np.ndarray]:
    """`poses` with the boxes `moving` refitted jointly to `points`: each point goes to its nearest box (of all of
    them), each moving box is fitted to its points (`fit_box`, `upright[k]`), `rounds` times, so that the points of
    blocks that touch pull only their own box."""
    poses = list(poses)
    for _ in range(rounds):
        distance = np.array([box_sdf(X, half, points) for X, half in zip(poses, halves)])
        nearest = np.argmin(np.abs(distance), axis=0)
        for k in moving:
            poses[k] = fit_box(points[nearest == k], halves[k], poses[k], upright[k])
    return poses


@cache
def _face_samples(block_type: int) -> tuple[np.ndarray, np.ndarray]:
    """Points on block_type's faces and their faces' outward normals (box frame), _SAMPLE_STEP_M apart and
    _FACE_INSET_M inside the faces' edges."""
    half = half_size(block_type)
    samples, normals = [], []
    for axis, sign in product(range(3), (-1.0, 1.0)):
        a, b = [k for k in range(3) if k != axis]
        grid = [np.linspace(-half[k] + _FACE_INSET_M, half[k] - _FACE_INSET_M,
                            max(2, int(round(2 * half[k] / _SAMPLE_STEP_M)))) for k in (a, b)]
        ga, gb = np.meshgrid(*grid)
        face = np.zeros((ga.size, 3))
        face[:, axis], face[:, a], face[:, b] = sign * half[axis], ga.ravel(), gb.ravel()
        samples.append(face)
        normals.append(np.tile(np.eye(3)[axis] * sign, (ga.size, 1)))
    return np.concatenate(samples), np.concatenate(normals)


def seen_through(X_WB: np.ndarray, block_type: int, views) -> float:
    """The share of the box's face samples that some camera saw past: its measured depth there is farther than the
    sample by SEEN_THROUGH_M. A box that is really there hides what is behind it; no return proves nothing, and
    a face a camera sees more obliquely than _GRAZING_COS is not asked of it (a pixel's width there spans the
    face's whole depth)."""
    p_B, n_B = _face_samples(block_type)
    p_W, n_W = p_B @ X_WB[:3, :3].T + X_WB[:3, 3], n_B @ X_WB[:3, :3].T
    through = np.zeros(len(p_W), dtype=bool)
    for view in views:
        R_WC, p_WC = view.X_WC[:3, :3], view.X_WC[:3, 3]
        p_C = (p_W - p_WC) @ R_WC
        ray = p_W - p_WC
        oblique = np.abs(np.sum(ray * n_W, axis=1)) < _GRAZING_COS * np.linalg.norm(ray, axis=1)
        fx, fy, cx, cy = view.intrinsics
        z = p_C[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.round(fx * p_C[:, 0] / z + cx).astype(np.int64, copy=False)
            v = np.round(fy * p_C[:, 1] / z + cy).astype(np.int64, copy=False)
        h, w = view.depth.shape
        inside = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h) & ~oblique
        measured = np.full(len(p_W), np.nan)
        measured[inside] = view.depth[v[inside], u[inside]]
        through |= np.isfinite(measured) & (measured > z + SEEN_THROUGH_M)
    return float(through.mean())


def min_area_rectangle(xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(centre (2,), unit long axis (2,), sizes (short, long)) of the smallest rectangle around the points
    (rotating calipers over the convex hull's edges); None for fewer than 3 points or points on a line."""
    if len(xy) < 3:
        return None
    try:
        hull = xy[ConvexHull(xy).vertices]
    except Exception:  # scipy's QhullError: the points lie on a line
        return None
    edges = np.diff(np.vstack([hull, hull[:1]]), axis=0)
    angles = np.unique(np.mod(np.arctan2(edges[:, 1], edges[:, 0]), np.pi / 2))
    best = None
    for angle in angles:
        axes = np.array([[np.cos(angle), np.sin(angle)], [-np.sin(angle), np.cos(angle)]])
        local = hull @ axes.T
        low, high = local.min(axis=0), local.max(axis=0)
        area = float(np.prod(high - low))
        if best is None or area < best[0]:
            best = (area, axes, low, high)
    assert best is not None
    _, axes, low, high = best
    centre = ((low + high) / 2) @ axes
    sizes = high - low
    long = int(np.argmax(sizes))
    return centre, axes[long], np.array([sizes[1 - long], sizes[long]])


def components(p: np.ndarray, radius: float) -> list[np.ndarray]:
    """Indices of the points' connected components (points within `radius` are connected), largest first."""
    if not len(p):
        return []
    pairs = cKDTree(p).query_pairs(radius, output_type="ndarray")
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(p), len(p)))
    _, labels = connected_components(graph, directed=False)
    groups = np.split(np.argsort(labels, kind="stable"), np.cumsum(np.bincount(labels))[:-1])
    return sorted(groups, key=len, reverse=True)


def face_hypotheses(face: np.ndarray, normal: np.ndarray, depth: float) -> list[tuple[int, np.ndarray]]:
    """(type, initial pose) of the blocks whose face `face` (points) may be, seen from outside along `normal`, the
    box `depth` behind the face's plane along it: a cube at either end or the middle of the face, a bar along it (or
    across a square one) with an end at either end of the face or centred on it (a block on top may hide part of
    it). The block's z axis is `normal`, its y axis a bar's long axis."""
    e1 = np.cross(normal, [0.0, 1.0, 0.0] if abs(normal[1]) < 0.9 else [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    rectangle = min_area_rectangle(np.column_stack([face @ e1, face @ e2]))
    if rectangle is None:
        return []
    (c1, c2), (u1, u2), sizes = rectangle
    centre = c1 * e1 + c2 * e2 + (float(np.median(face @ normal)) - depth) * normal
    long_axis = u1 * e1 + u2 * e2
    hypotheses = []
    for axis, extent in [(long_axis, sizes[1])] + ([(np.cross(normal, long_axis), sizes[0])] if sizes[1] < 0.065
                                                    else []):
        R = np.column_stack([np.cross(axis, normal), axis, normal])  # block y along `axis`, z along `normal`
        for block_type in (SMALL, LARGE) if axis is long_axis else (LARGE,):
            length = BLOCK_SIZES[block_type][1]
            if abs(extent - length) < 0.015:  # the face is the block's whole face
                offsets = {0.0}
            else:  # an end of the block at either end of the face, or (a longer block partly hidden) centred
                ends = {round((extent - length) / 2, 3), round((length - extent) / 2, 3)}
                offsets = ends | {0.0} if extent < length else ends
            hypotheses += [(block_type, pose(R, centre + s * axis)) for s in offsets]
    return hypotheses


def footprint_hypotheses(points: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """Upright blocks whose sides `points` may be (a block whose top face a block on it hides), a layer of blocks at a
    time: the footprint is the outline on the table of the points between two whole numbers of block heights. Where
    the cameras saw one side only (an outline narrower than a block), the block stands behind it, on either side."""
    up = np.array([0.0, 0.0, 1.0])
    hypotheses = []
    for layer in range(1, int(np.ceil(float(points[:, 2].max()) / BLOCK_HEIGHT)) + 1):
        top = layer * BLOCK_HEIGHT
        outline = points[(points[:, 2] > top - BLOCK_HEIGHT + 0.006) & (points[:, 2] < top + 0.006)]
        if len(outline) < MIN_PATCH:
            continue
        outline = np.column_stack([outline[:, :2], np.full(len(outline), top)])
        rectangle = min_area_rectangle(outline[:, :2])
        if rectangle is None or rectangle[2][0] >= 0.04:
            hypotheses += face_hypotheses(outline, up, BLOCK_HEIGHT / 2)
            continue
        across = np.array([-rectangle[1][1], rectangle[1][0], 0.0]) * (BLOCK_SIZES[SMALL][0] - rectangle[2][0])
        hypotheses += [h for sign in (-1.0, 1.0)
                       for h in face_hypotheses(np.vstack([outline, outline + sign * across]), up, BLOCK_HEIGHT / 2)]
    return hypotheses


def vertical_faces(p: np.ndarray, n: np.ndarray, voxel: float) -> list[tuple[np.ndarray, np.ndarray]]:
    """The vertical faces among the points p (normals n, sign arbitrary): (points, horizontal unit normal, sign
    arbitrary) of each group of points whose horizontal normals agree (5 degree bins, the four fullest), connected."""
    side = np.flatnonzero(np.abs(n[:, 2]) < 0.2)
    if len(side) < MIN_PATCH:
        return []
    heading = np.mod(np.arctan2(n[side, 1], n[side, 0]), np.pi)  # the face's direction, either sign
    bins = np.round(heading / np.radians(5.0)).astype(int) % 36
    faces = []
    for peak in np.argsort(np.bincount(bins, minlength=36))[::-1][:4]:
        near = side[np.abs(np.mod(bins - peak + 18, 36) - 18) <= 1]
        if len(near) < MIN_PATCH:
            break
        m = np.array([np.cos(peak * np.radians(5.0)), np.sin(peak * np.radians(5.0)), 0.0])
        faces += [(p[near[face]], m) for face in components(p[near], 2.5 * voxel) if len(face) >= MIN_PATCH]
    return faces


def side_hypotheses(p: np.ndarray, n: np.ndarray, voxel: float) -> list[tuple[int, np.ndarray]]:
    """Upright blocks behind the vertical faces among the points p (normals n, sign arbitrary): a block whose top
    face is hidden (under a leaning bar, or an overhang) may show a single side. Each face (`vertical_faces`)
    proposes, on either side of its plane (which side the cameras looked from is unknown), a cube at either end or
    the middle of the face, a bar along it likewise, and a bar across it; the block stands in the layer of the
    face's median height."""
    hypotheses = []
    for f, m in vertical_faces(p, n, voxel):
        t = np.array([-m[1], m[0], 0.0])
        plane, (lo, hi) = float(np.median(f @ m)), np.percentile(f @ t, [2.0, 98.0])
        z = (np.floor(float(np.median(f[:, 2])) / BLOCK_HEIGHT) + 0.5) * BLOCK_HEIGHT
        for sign in (-1.0, 1.0):
            for block_type, axis, depth in ((SMALL, t, 0.025), (LARGE, t, 0.025), (LARGE, m, 0.125)):
                R = np.column_stack([np.cross(axis, [0.0, 0.0, 1.0]), axis, [0.0, 0.0, 1.0]])
                half = BLOCK_SIZES[block_type][1] / 2 if axis is t else 0.0
                along = {(lo + hi) / 2} | ({lo + half, hi - half} if half else set())
                hypotheses += [(block_type, pose(R, (plane - sign * depth) * m + s * t + [0.0, 0.0, z]))
                               for s in along]
    return hypotheses


def tilted_side_hypotheses(p: np.ndarray, n: np.ndarray, voxel: float) -> list[tuple[int, np.ndarray]]:
    """Blocks with six degrees of freedom behind the vertical faces among the points p (normals n, sign arbitrary):
    a block leaning in the plane of a side face (rolled about its short axis) whose top another block covers shows
    only its sides, tilted rectangles. Each face (`vertical_faces`) proposes `face_hypotheses` on either side of
    its plane, those tilted more than TILTED_RAD (an upright block's sides propose it upright: `side_hypotheses`)."""
    return [h for f, m in vertical_faces(p, n, voxel) for sign in (-1.0, 1.0)
            for h in face_hypotheses(f, sign * m, BLOCK_HEIGHT / 2) if np.abs(h[1][2, :3]).max() < np.cos(TILTED_RAD)]


@cache
def symmetries(block_type: int) -> np.ndarray:
    """(k, 3, 3) rotations that map block_type's box onto itself (24 for a cube, 8 for a bar)."""
    half = half_size(block_type)
    found = []
    for perm in permutations(range(3)):
        for signs in product((-1.0, 1.0), repeat=3):
            S = np.zeros((3, 3))
            S[range(3), perm] = signs
            if np.linalg.det(S) > 0 and np.allclose(np.abs(S) @ half, half):
                found.append(S)
    return np.array(found)


def orientation_error(R_est: np.ndarray, R_true: np.ndarray, block_type: int) -> float:
    """Radians between two orientations of a block, the nearest of its symmetric equivalents."""
    traces = np.einsum("ij,kjl,il->k", R_true.T @ R_est, symmetries(block_type), np.eye(3))
    return float(np.arccos(np.clip((traces.max() - 1.0) / 2.0, -1.0, 1.0)))


__all__ = ["MIN_PATCH", "TILTED_RAD", "box_sdf", "components", "face_hypotheses", "fit_box", "fit_boxes",
           "footprint_hypotheses", "half_size", "leans", "min_area_rectangle", "orientation_error", "pose",
           "seen_through", "side_hypotheses", "symmetries", "tilted_side_hypotheses", "vertical_faces"]
