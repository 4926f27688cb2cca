"""Fitting the known block boxes to points: where a fit may start (blocks proposed from a face, a layer's outline or
a side seen alone), a box's signed distance, its least-squares pose, the free space the cameras saw through it, its
orientation error up to the box's symmetries. numpy and scipy only.

Poses are (4, 4) homogeneous matrices X_WB (block B in the world W), lengths metres, angles radians.
"""
from __future__ import annotations

from collections.abc import Sequence
from functools import cache
from itertools import permutations, product

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, cKDTree

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
    return boxes_sdf(X_WB[None], np.asarray(half)[None], p_W)[0]


def boxes_sdf(X_WB: np.ndarray, half: np.ndarray, p_W: np.ndarray) -> np.ndarray:
    """box_sdf of the points p_W (k, 3) to each of the boxes at X_WB (b, 4, 4) of half sizes `half` (b, 3): (b, k)."""
    q = np.abs((p_W[None] - X_WB[:, None, :3, 3]) @ X_WB[:, :3, :3]) - half[:, None]
    return _sdf_of(q[..., 0], q[..., 1], q[..., 2])


def boxes_sdf_near(X_WB: np.ndarray, half: np.ndarray, p_W: np.ndarray, margin_m: float) -> np.ndarray:
    """boxes_sdf (b, k) where it is below margin_m, and margin_m where it is not: the points outside the
    axis-aligned box around all the boxes, grown by margin_m, are farther than that from each and not computed (a
    test of `< margin_m` or of inside is the same on both)."""
    distance = np.full((len(X_WB), len(p_W)), margin_m)
    if not len(X_WB):
        return distance
    extent = np.abs(X_WB[:, :3, :3]) @ half[:, :, None]  # (b, 3, 1): each box's half extent along the world axes
    low = (X_WB[:, :3, 3] - extent[:, :, 0]).min(axis=0) - margin_m
    high = (X_WB[:, :3, 3] + extent[:, :, 0]).max(axis=0) + margin_m
    x, y, z = p_W.T
    near = np.flatnonzero((x >= low[0]) & (x <= high[0]) & (y >= low[1]) & (y <= high[1]) & (z >= low[2])
                          & (z <= high[2]))
    distance[:, near] = boxes_sdf(X_WB, half, p_W[near])
    return distance


def _sdf_of(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The signed distance of points whose box coordinates' magnitudes exceed the half sizes by x, y and z (written
    per axis: numpy's reductions over an axis of three cost ten times an elementwise operation)."""
    outside = np.sqrt(np.maximum(x, 0.0) ** 2 + np.maximum(y, 0.0) ** 2 + np.maximum(z, 0.0) ** 2)
    return outside + np.minimum(np.maximum(np.maximum(x, y), z), 0.0)


def _rotations(w: np.ndarray) -> np.ndarray:
    """The rotation matrices (b, 3, 3) of the rotation vectors w (b, 3) (Rodrigues' formula)."""
    angle = np.linalg.norm(w, axis=1)
    k = w / np.where(angle > 0, angle, 1.0)[:, None]
    K = np.zeros((len(w), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K -= np.swapaxes(K, 1, 2)
    return np.eye(3) + np.sin(angle)[:, None, None] * K + (1.0 - np.cos(angle))[:, None, None] * (K @ K)


def fit_box(points: np.ndarray, half: np.ndarray, X0: np.ndarray, upright: bool, iterations: int = 15) -> np.ndarray:
    """The pose near X0 whose box surface passes closest to `points`: Gauss-Newton on the signed distance with
    Cauchy weights (iteratively reweighted), so that a neighbour's points do not pull. `upright`: only x, y and the
    yaw about the world's z move (a block resting flat, its height known from its top face)."""
    return fit_boxes([points], np.asarray(half)[None], X0[None], upright, iterations)[0]


def fit_boxes(points: list[np.ndarray], half: np.ndarray, X0: np.ndarray, upright: bool,
              iterations: int = 15) -> np.ndarray:
    """`fit_box` of several boxes at once (half sizes (b, 3), starting poses (b, 4, 4)), each to its own points:
    the poses (b, 4, 4). A box with fewer points than twice its degrees of freedom stays at its start."""
    points = [q[np.linspace(0, len(q) - 1, FIT_POINTS).astype(int)] if len(q) > FIT_POINTS else q for q in points]
    p = np.zeros((len(points), max((len(q) for q in points), default=0), 3))
    used = np.zeros(p.shape[:2])  # 1 for a box's points, 0 for the padding after them
    for box, q in enumerate(points):
        p[box, :len(q)], used[box, :len(q)] = q, 1.0
    dof = 3 if upright else 6
    moving = np.array([len(q) >= 2 * dof for q in points], dtype=bool)
    R, c = X0[:, :3, :3].copy(), X0[:, :3, 3].copy()
    for _ in range(iterations):
        k = np.flatnonzero(moving)
        if not len(k):
            break
        d = p[k] - c[k, None]
        p_B = d @ R[k]
        q = np.abs(p_B) - half[k, None]
        r = _sdf_of(q[..., 0], q[..., 1], q[..., 2])
        # its gradient: outside, towards the nearest surface point; inside, the nearest face's normal (the first
        #   axis of the largest excess, as argmax)
        out = np.maximum(q, 0.0)
        outside_m = np.sqrt(out[..., 0] ** 2 + out[..., 1] ** 2 + out[..., 2] ** 2)
        inside = outside_m == 0
        g_B = out / np.where(inside, 1.0, outside_m)[:, :, None]
        x_first = (q[..., 0] >= q[..., 1]) & (q[..., 0] >= q[..., 2])
        g_B[..., 0] += inside & x_first
        g_B[..., 1] += inside & ~x_first & (q[..., 1] >= q[..., 2])
        g_B[..., 2] += inside & ~x_first & (q[..., 1] < q[..., 2])
        g = np.copysign(g_B, p_B) @ np.swapaxes(R[k], 1, 2)
        # a small rotation w about the centre and a translation dc move the points' box coordinates by
        # -(w x d) and -dc (d = p - c): the signed distance changes by -(d x g).w - g.dc
        yaw = d[:, :, 0] * g[:, :, 1] - d[:, :, 1] * g[:, :, 0]
        if upright:  # yaw, x, y
            J = -np.stack([yaw, g[:, :, 0], g[:, :, 1]], axis=2)
        else:
            J = -np.stack([d[:, :, 1] * g[:, :, 2] - d[:, :, 2] * g[:, :, 1],
                           d[:, :, 2] * g[:, :, 0] - d[:, :, 0] * g[:, :, 2], yaw, g[:, :, 0], g[:, :, 1], g[:, :, 2]],
                          axis=2)
        Jw = J * (used[k] / (1.0 + (r / FIT_SCALE_M) ** 2))[:, :, None]
        # the weighted least squares' normal equations, damped a trace's 1e-12th: a direction the points do not fix
        #   (a face's own plane, seen alone) stays where it is, and so does an upright box fitted to points all
        #   above its top face (no x, y or yaw moves them: J = 0)
        A = np.swapaxes(Jw, 1, 2) @ J
        A += (1e-12 * np.trace(A, axis1=1, axis2=2) + np.finfo(float).tiny)[:, None, None] * np.eye(dof)
        solution = np.linalg.solve(A, -(np.swapaxes(Jw, 1, 2) @ r[:, :, None]))[:, :, 0]
        step = np.zeros((len(k), 6))
        step[:, [2, 3, 4] if upright else slice(None)] = solution
        R[k], c[k] = _rotations(step[:, :3]) @ R[k], c[k] + step[:, 3:]
        moving[k[np.abs(step).max(axis=1) < 1e-4]] = False  # a step under 0.1 mm and 1e-4 rad: converged (under
        #   half the position error's median; 1e-5 took a fifth more iterations, for no better estimate)
    X = np.repeat(np.eye(4)[None], len(points), axis=0)
    X[:, :3, :3], X[:, :3, 3] = R, c
    return X


def leans(X_WB: np.ndarray) -> bool:
    """Whether the box at X_WB tilts more than TILTED_RAD (none of its axes that close to the world's z)."""
    return bool(np.abs(X_WB[2, :3]).max() < np.cos(TILTED_RAD))


def fit_each(points: list[np.ndarray], half: np.ndarray, X0: np.ndarray, upright: np.ndarray) -> np.ndarray:
    """`fit_boxes` of boxes some of which are `upright` (b,) and some not: their poses (b, 4, 4)."""
    X = np.zeros((len(points), 4, 4))
    for flat in (True, False):
        mine = np.flatnonzero(np.asarray(upright, dtype=bool) == flat)
        if len(mine):
            X[mine] = fit_boxes([points[k] for k in mine], half[mine], X0[mine], flat)
    return X


def fit_jointly(points: np.ndarray, half: np.ndarray, X0: np.ndarray, moving: Sequence[int], upright: np.ndarray,
                rounds: int = 2) -> np.ndarray:
    """The poses X0 (b, 4, 4) of boxes of half sizes `half` (b, 3) with the boxes `moving` refitted jointly to
    `points`: each point goes to its nearest box (of all of them), each moving box is fitted to its points
    (`fit_each`, upright where `upright` (b,) says), `rounds` times, so that the points of blocks that touch pull
    only their own box."""
    X = np.array(X0, dtype=float)
    moving = list(moving)
    if not moving:
        return X
    upright = np.asarray(upright, dtype=bool)
    for _ in range(rounds):
        nearest = np.argmin(np.abs(boxes_sdf(X, half, points)), axis=0)
        X[moving] = fit_each([points[nearest == k] for k in moving], half[moving], X[moving], upright[moving])
    return X


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


class _Cameras:
    """The views' cameras stacked (poses, intrinsics, depth images) so that `seen_through` asks them all at once."""

    def __init__(self, views) -> None:
        self.views = list(views)
        self.R_WC = np.array([v.X_WC[:3, :3] for v in self.views]).reshape(-1, 3, 3)
        self.p_WC = np.array([v.X_WC[:3, 3] for v in self.views]).reshape(-1, 3)
        self.p_WC_sq = np.sum(self.p_WC ** 2, axis=1)
        self.fx, self.fy, self.cx, self.cy = (np.array([v.intrinsics[k] for v in self.views]) for k in range(4))
        self.h = np.array([v.depth.shape[0] for v in self.views])
        self.w = np.array([v.depth.shape[1] for v in self.views])
        self.depth = [v.depth for v in self.views]


_cameras_cache: list[_Cameras] = []  # the last views' stack (it holds them, so their ids are not reused)


def _cameras(views) -> _Cameras:
    """The stack of `views`, built once for the views of one perception."""
    views = list(views)
    if not (_cameras_cache and len(_cameras_cache[0].views) == len(views)
            and all(a is b for a, b in zip(_cameras_cache[0].views, views))):
        _cameras_cache[:] = [_Cameras(views)]
    return _cameras_cache[0]


def seen_through(X_WB: np.ndarray, block_type: int, views) -> float:
    """The share of the box's face samples that some camera saw past: its measured depth there is farther than the
    sample by SEEN_THROUGH_M. A box that is really there hides what is behind it; no return proves nothing, and
    a face a camera sees more obliquely than _GRAZING_COS is not asked of it (a pixel's width there spans the
    face's whole depth)."""
    return float(seen_through_boxes(X_WB[None], np.array([block_type]), views)[0])


def seen_through_boxes(X_WB: np.ndarray, block_types: np.ndarray, views) -> np.ndarray:
    """`seen_through` of each of the boxes at X_WB (b, 4, 4) of types `block_types` (b,): (b,)."""
    cameras = _cameras(views)
    shares = np.zeros(len(X_WB))
    for block_type in np.unique(block_types):
        mine = np.flatnonzero(block_types == block_type)
        p_B, n_B = _face_samples(int(block_type))
        p_W = (p_B @ np.swapaxes(X_WB[mine, :3, :3], 1, 2) + X_WB[mine, None, :3, 3]).reshape(-1, 3)
        n_W = (n_B @ np.swapaxes(X_WB[mine, :3, :3], 1, 2)).reshape(-1, 3)
        shares[mine] = np.mean(_seen_past(p_W, n_W, cameras).reshape(len(mine), -1), axis=1)
    return shares


def _seen_past(p_W: np.ndarray, n_W: np.ndarray, cameras: _Cameras) -> np.ndarray:
    """Whether some camera measured a depth farther than each point p_W (k, 3) by SEEN_THROUGH_M, where it sees the
    point's face (normal n_W) less obliquely than _GRAZING_COS."""
    # per camera (rows) and point (columns), written per axis (a (k, 3) by (3, 12) matmul takes OpenBLAS's threads,
    #   which wait for each other on a busy machine): the ray's length squared and its dot with the face's normal
    x, y, z = np.ascontiguousarray(p_W.T)
    o = cameras.p_WC[:, :, None]  # (cameras, 3, 1)
    ray_sq = x * x + y * y + z * z - 2 * (o[:, 0] * x + o[:, 1] * y + o[:, 2] * z) + cameras.p_WC_sq[:, None]
    along = x * n_W[:, 0] + y * n_W[:, 1] + z * n_W[:, 2] - (o[:, 0] * n_W[:, 0] + o[:, 1] * n_W[:, 1]
                                                             + o[:, 2] * n_W[:, 2])
    oblique = along ** 2 < _GRAZING_COS ** 2 * ray_sq
    R = cameras.R_WC[:, :, :, None]  # the point in each camera's frame: (p - o) @ R, per axis
    x, y, z = x - o[:, 0], y - o[:, 1], z - o[:, 2]
    x_C, y_C, z = (x * R[:, 0, j] + y * R[:, 1, j] + z * R[:, 2, j] for j in range(3))
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.round(cameras.fx[:, None] * x_C / z + cameras.cx[:, None]).astype(np.int64, copy=False)
        v = np.round(cameras.fy[:, None] * y_C / z + cameras.cy[:, None]).astype(np.int64, copy=False)
    inside = ((z > 0) & (u >= 0) & (u < cameras.w[:, None]) & (v >= 0) & (v < cameras.h[:, None]) & ~oblique)
    measured = np.zeros(z.shape)
    for k, depth in enumerate(cameras.depth):
        measured[k, inside[k]] = depth[v[k, inside[k]], u[k, inside[k]]]
    with np.errstate(invalid="ignore"):  # no return (inf) proves nothing, nor does one too near (0)
        return np.any((measured > z + SEEN_THROUGH_M) & np.isfinite(measured), axis=0)


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
    cos, sin = np.cos(angles)[:, None], np.sin(angles)[:, None]
    along, across = cos * hull[:, 0] + sin * hull[:, 1], cos * hull[:, 1] - sin * hull[:, 0]  # (angles, vertices)
    low = np.column_stack([along.min(axis=1), across.min(axis=1)])
    high = np.column_stack([along.max(axis=1), across.max(axis=1)])
    k = int(np.argmin((high[:, 0] - low[:, 0]) * (high[:, 1] - low[:, 1])))  # the first of the smallest areas
    axes = np.array([[cos[k, 0], sin[k, 0]], [-sin[k, 0], cos[k, 0]]])
    low, high = low[k], high[k]
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


def side_hypotheses(faces: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[int, np.ndarray]]:
    """Upright blocks behind vertical faces (`vertical_faces`: points and horizontal normal, sign arbitrary): a
    block whose top face is hidden (under a leaning bar, or an overhang) may show a single side. Each face
    proposes, on either side of its plane (which side the cameras looked from is unknown), a cube at either end or
    the middle of the face, a bar along it likewise, and a bar across it; the block stands in the layer of the
    face's median height."""
    hypotheses = []
    for f, m in faces:
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


def tilted_side_hypotheses(faces: list[tuple[np.ndarray, np.ndarray]]) -> list[tuple[int, np.ndarray]]:
    """Blocks with six degrees of freedom behind vertical faces (`vertical_faces`): a block leaning in the plane of
    a side face (rolled about its short axis) whose top another block covers shows only its sides, tilted
    rectangles. Each face proposes `face_hypotheses` on either side of its plane, those tilted more than TILTED_RAD
    (an upright block's sides propose it upright: `side_hypotheses`)."""
    return [h for f, m in faces for sign in (-1.0, 1.0)
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


__all__ = ["MIN_PATCH", "TILTED_RAD", "box_sdf", "boxes_sdf", "boxes_sdf_near", "components", "face_hypotheses",
           "fit_box", "fit_boxes", "fit_each", "fit_jointly", "footprint_hypotheses", "half_size", "leans",
           "min_area_rectangle", "orientation_error", "pose", "seen_through", "seen_through_boxes", "side_hypotheses",
           "symmetries", "tilted_side_hypotheses", "vertical_faces"]
