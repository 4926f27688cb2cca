"""From depth images to the world's point cloud: each camera's returns back-projected into the world, cropped to
the table's workspace above the table, fused per voxel; and the normals of the fused points' local planes.
`tamp.sim.perception` finds the blocks in it."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

CROP_M = ((0.1, 1.3), (-0.75, 0.75), (0.006, 0.6))  # metres, world x, y, z: the table's workspace; z > 6 mm
NEIGHBOURS = 10  # points of a normal's neighbourhood


@dataclass(frozen=True)
class DepthView:
    """One camera's depth image and where it was taken from."""

    name: str
    depth: np.ndarray  # (H, W) float, metres along the optical axis; inf or 0 where nothing returned
    intrinsics: tuple[float, float, float, float]  # fx, fy, cx, cy in pixels
    X_WC: np.ndarray  # (4, 4) Drake camera frame in the world: +z forward, +x right, +y down the image


def world_points(view: DepthView) -> np.ndarray:
    """The view's returns as points in the world (k, 3), inside CROP_M. The height is computed first, for every
    pixel, so that only the few pixels above the table are back-projected in full."""
    fx, fy, cx, cy = view.intrinsics
    h, w = view.depth.shape
    R, t = view.X_WC[:3, :3], view.X_WC[:3, 3]
    x_ray = ((np.arange(w) - cx) / fx).astype(np.float32)
    y_ray = ((np.arange(h) - cy) / fy).astype(np.float32)
    with np.errstate(invalid="ignore"):  # inf * 0 where a ray is level
        height = view.depth * _rise(view.intrinsics, (h, w), tuple(R[2])) + t[2]
    pixel = np.flatnonzero((height > CROP_M[2][0]) & (height < CROP_M[2][1]) & (view.depth > 0))  # np.nonzero's
    #   (rows, columns) take twenty times as long
    v, u = pixel // w, pixel % w
    z = view.depth[v, u].astype(float)
    x, y = x_ray[u] * z, y_ray[v] * z
    p_W = np.column_stack([R[k, 0] * x + R[k, 1] * y + R[k, 2] * z + t[k] for k in range(3)])  # not a matmul: a
    #   (k, 3) one takes OpenBLAS's threads, which wait for each other on a busy machine
    inside = np.all([(p_W[:, k] > lo) & (p_W[:, k] < hi) for k, (lo, hi) in enumerate(CROP_M)], axis=0)
    return p_W[inside]


@lru_cache(maxsize=16)
def _rise(intrinsics: tuple[float, float, float, float], shape: tuple[int, int],
          R_z: tuple[float, float, float]) -> np.ndarray:
    """(H, W) float32: the world height gained per metre of depth along each pixel's ray, for a camera whose
    rotation's last row is R_z (a fixed camera's, computed once)."""
    fx, fy, cx, cy = intrinsics
    x_ray = ((np.arange(shape[1]) - cx) / fx).astype(np.float32)
    y_ray = ((np.arange(shape[0]) - cy) / fy).astype(np.float32)
    return R_z[0] * x_ray[None, :] + R_z[1] * y_ray[:, None] + np.float32(R_z[2])


def fused_cloud(views: list[DepthView], voxel_m: float) -> np.ndarray:
    """Every view's points above the table, averaged per voxel_m cube (N, 3)."""
    p = np.concatenate([world_points(v) for v in views] or [np.zeros((0, 3))])
    if not len(p):
        return p
    keys = np.floor(p / voxel_m).astype(np.int64)
    keys -= keys.min(axis=0)
    span = keys.max(axis=0) + 1
    _, voxel, counts = np.unique((keys[:, 0] * span[1] + keys[:, 1]) * span[2] + keys[:, 2], return_inverse=True,
                                 return_counts=True)
    return np.stack([np.bincount(voxel, p[:, k]) for k in range(3)], axis=1) / counts[:, None]


def smallest_eigenvectors(C: np.ndarray) -> np.ndarray:
    """Unit eigenvectors (k, 3) of the smallest eigenvalues of the symmetric (k, 3, 3) matrices C, in closed form:
    the eigenvalue by the trigonometric formula, the vector as the longest cross product of two rows of C less it
    (written per entry: a fifth of the time of LAPACK's `eigh`, one small matrix at a time)."""
    a, b, c, d, e, f = C[:, 0, 0], C[:, 1, 1], C[:, 2, 2], C[:, 0, 1], C[:, 0, 2], C[:, 1, 2]
    mean = (a + b + c) / 3
    spread = np.sqrt(((a - mean) ** 2 + (b - mean) ** 2 + (c - mean) ** 2 + 2 * (d * d + e * e + f * f)) / 6)
    s = np.where(spread > 0, spread, 1.0)
    A, B, S, D, E, F = (a - mean) / s, (b - mean) / s, (c - mean) / s, d / s, e / s, f / s  # (C - mean I) / spread
    det = A * (B * S - F * F) - D * (D * S - F * E) + E * (D * F - B * E)
    smallest = mean + 2 * spread * np.cos(np.arccos(np.clip(det / 2, -1.0, 1.0)) / 3 + 2 * np.pi / 3)
    a, b, c = a - smallest, b - smallest, c - smallest  # the rows of C less it: (a, d, e), (d, b, f), (e, f, c)
    crossed = np.stack([np.stack([d * f - e * b, e * d - a * f, a * b - d * d], axis=1),
                        np.stack([d * c - e * f, e * e - a * c, a * f - d * e], axis=1),
                        np.stack([b * c - f * f, f * e - d * c, d * f - b * e], axis=1)], axis=1)
    length = np.sqrt(np.einsum("kij,kij->ki", crossed, crossed))
    best = np.argmax(length, axis=1)
    rows = np.arange(len(C))
    vector = crossed[rows, best] / np.where(length[rows, best] > 0, length[rows, best], 1.0)[:, None]
    vector[length[rows, best] == 0] = (0.0, 0.0, 1.0)  # an isotropic neighbourhood: no plane
    return vector


class Normals:
    """Unit normals of the fused points' local planes (PCA of each one's NEIGHBOURS nearest points), sign
    arbitrary; each point's is computed once, when first asked for."""

    def __init__(self, p: np.ndarray, tree: cKDTree) -> None:
        self.p, self.tree = p, tree
        self._normals = np.zeros((len(p), 3))
        self._known = np.zeros(len(p), dtype=bool)

    def __call__(self, which: np.ndarray) -> np.ndarray:
        """The normals (k, 3) of the points p[which]."""
        new = np.unique(which[~self._known[which]])
        if len(new):
            _, near = self.tree.query(self.p[new], k=min(NEIGHBOURS, len(self.p)))
            axes = [self.p[near, k] for k in range(3)]  # (points, neighbours) per axis
            axes = [v - v.mean(axis=1, keepdims=True) for v in axes]
            C = np.empty((len(new), 3, 3))
            for i in range(3):
                for j in range(i, 3):
                    C[:, i, j] = C[:, j, i] = np.einsum("kn,kn->k", axes[i], axes[j])
            self._normals[new] = smallest_eigenvectors(C)
            self._known[new] = True
        return self._normals[which]


__all__ = ["CROP_M", "NEIGHBOURS", "DepthView", "Normals", "fused_cloud", "smallest_eigenvectors", "world_points"]
