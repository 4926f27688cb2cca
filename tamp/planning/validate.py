"""Is a scene one the world can hold? The one check of every scene given from outside.

A scene X is (n, 5): block centres x, y, z in metres and a one-hot type (small cube, large bar). X
holds no orientation, so the check is exact for what it can know and lenient for the rest:

- count: 1..MAX_OBJECTS blocks (the world's limit), and at most the models' `n_max` when given;
- reach: every centre on the table top (TABLE_X, TABLE_Y), outside the arm's base (BASE_CLEARANCE)
  and within ARM_REACH_M of the base axis, where the arm can still grasp a block from above;
- resting: every block on the table top (z = 0) or on another block within RESTING_TOLERANCE_M,
  for some height the block can rest at (a cube at its half size; a bar anywhere from flat,
  half height 2.5 cm, to standing on its end, 12.5 cm, which covers bars leaning on a block);
- interpenetration: no two blocks whose centres are so close that they must overlap whatever
  their orientation (closer than the sum of their smallest half sizes, less the tolerance).

`upright=True` is for a scene that will be placed as given, every block upright and axis-aligned
(`World.reset(X=...)`: the initial scene of a problem or plan file): then the heights are exact and
two blocks overlap when their axis-aligned boxes do. Errors are ValueErrors (the CLI's user error)
naming `where` (the file), the field and the row (the block).
"""
from __future__ import annotations

import numpy as np

from tamp.errors import UserError
from tamp.planning.vocabulary import BLOCK_SIZES

MAX_OBJECTS = 8  # blocks the world builds plants for
TABLE_TOP_Z_M = 0.0  # the world frame is the table top (drake_models/table.sdf)
TABLE_X, TABLE_Y = (-0.5, 1.9), (-1.2, 1.2)  # table top extent (drake_models/table.sdf), metres
BASE_CLEARANCE = 0.15  # metres: no block centre this close to the arm's base axis
# Metres from the base axis within which the UR10e reaches a top-down grasp of a block on the table
# and its pre-grasp 12 cm above (measured with tamp.sim.kinematics.analytic_ik: 1.31 m at the grasp,
# 1.295 m at the pre-grasp; tests/test_input_validation.py checks it against the IK).
ARM_REACH_M = 1.29
# Metres a block may sink into or float above its support, and two blocks may overlap: the tolerance the
# world already used at reset. Measured on generated scenes (300 problems of both protocols, 3000
# collected transitions of 2-6 blocks after physics), the largest one needed is 0.02 mm (hydroelastic
# sinking): tilted blocks are covered by their height range, not by this tolerance.
RESTING_TOLERANCE_M = 0.01

_HALF = {t: np.array(size) / 2 for t, size in BLOCK_SIZES.items()}


def _half_heights(t: int, upright: bool) -> tuple[float, float]:
    """(lowest, highest) half height block type t can rest at, metres."""
    half = _HALF[t]
    return (float(half[2]), float(half[2])) if upright else (float(half.min()), float(half.max()))


def _footprint_radius(t: int) -> float:
    """Metres: the largest horizontal distance from a block's centre to a point of its top face,
    in any orientation (half the diagonal of its largest face)."""
    a, b = sorted(_HALF[t])[-2:]
    return float(np.hypot(a, b))


def check_scene(X: np.ndarray, *, where: str = "scene", field: str = "X", upright: bool = False,
                n_max: int | None = None, within_reach: bool = True,
                tolerance_m: float = RESTING_TOLERANCE_M) -> None:
    """Raise ValueError naming `where`, `field` and the row if X is not a scene the world can hold.

    X must already be a well-formed (n, 5) array of finite numbers with one-hot types (see
    `tamp.app.problem.problem_from_dict`); this checks the geometry. `n_max`: the models' limit.
    `within_reach=False` accepts blocks on the table beyond the arm's reach (the simulator holds them;
    an action on one fails its IK).
    """
    X = np.asarray(X, dtype=float)
    if X.ndim != 2 or X.shape[1] != 5 or not np.all(np.isfinite(X)):
        raise UserError(f"{where}: field '{field}' must be an (n, 5) array of finite numbers, got shape {X.shape}")
    onehot = X[:, 3:5]
    bad = np.flatnonzero(~(np.isin(onehot, (0.0, 1.0)).all(axis=1) & (onehot.sum(axis=1) == 1)))
    if bad.size:
        raise UserError(f"{where}: field '{field}' row {bad[0]}: the type must be one-hot [1, 0] (small) or "
                         f"[0, 1] (large), got {onehot[bad[0]].tolist()}")
    n = len(X)
    limit = MAX_OBJECTS if n_max is None else min(MAX_OBJECTS, n_max)
    if not 1 <= n <= limit:
        by = "the world holds" if n_max is None or n_max >= MAX_OBJECTS else "the models were trained for"
        raise UserError(f"{where}: field '{field}' has {n} blocks, but {by} 1..{limit}")
    types = np.argmax(X[:, 3:5], axis=1)
    p = X[:, :3]
    for i in range(n):
        x, y, z = p[i]
        row = f"{where}: field '{field}' row {i}: block at ({x:.3f}, {y:.3f}, {z:.3f}) m"
        if not (TABLE_X[0] <= x <= TABLE_X[1] and TABLE_Y[0] <= y <= TABLE_Y[1]):
            raise UserError(f"{row} is off the table (x in {TABLE_X}, y in {TABLE_Y})")
        r = float(np.hypot(x, y))
        if r < BASE_CLEARANCE:
            raise UserError(f"{row} is inside the robot's base (closer than {BASE_CLEARANCE} m to its axis)")
        if within_reach and r > ARM_REACH_M:
            raise UserError(f"{row} is out of the arm's reach ({r:.3f} m from its base, at most {ARM_REACH_M} m)")
        low, _ = _half_heights(types[i], upright)
        if z - low < TABLE_TOP_Z_M - tolerance_m:
            raise UserError(f"{row} is inside the table (its centre must be at least {low:.3f} m above the table top)")
    for i in range(n):
        for j in range(i):
            if _interpenetrate(p[i], types[i], p[j], types[j], upright, tolerance_m):
                raise UserError(f"{where}: field '{field}' rows {j} and {i}: blocks at "
                                 f"({p[j, 0]:.3f}, {p[j, 1]:.3f}, {p[j, 2]:.3f}) m and "
                                 f"({p[i, 0]:.3f}, {p[i, 1]:.3f}, {p[i, 2]:.3f}) m overlap (interpenetrate)")
    supported = _supported(p, types, upright, tolerance_m)
    for i in range(n):
        if not supported[i]:
            low, high = _half_heights(types[i], upright)
            raise UserError(f"{where}: field '{field}' row {i}: block at ({p[i, 0]:.3f}, {p[i, 1]:.3f}, "
                             f"{p[i, 2]:.3f}) m rests neither on the table nor on a block that does (its "
                             f"bottom would be {p[i, 2] - high:.3f}..{p[i, 2] - low:.3f} m above the table top)")


def _interpenetrate(p_i: np.ndarray, t_i: int, p_j: np.ndarray, t_j: int, upright: bool, tolerance_m: float) -> bool:
    """Must blocks i and j overlap (by more than the tolerance)?"""
    if upright:  # axis-aligned boxes: overlap along every axis
        return bool(np.all(_HALF[t_i] + _HALF[t_j] - np.abs(p_i - p_j) > tolerance_m))
    # any orientation: each block contains the ball of its smallest half size around its centre
    return bool(np.linalg.norm(p_i - p_j) < _HALF[t_i].min() + _HALF[t_j].min() - tolerance_m)


def _supported(p: np.ndarray, types: np.ndarray, upright: bool, tolerance_m: float) -> list[bool]:
    """Per block: does it rest on the table top, or on a block that (recursively) does?

    Block i rests on block j when i's bottom can touch j's top: upright, j's top is z_j + 2.5 cm
    under i's footprint; in any orientation, j's top surface can lie anywhere within j's vertical
    extent (a tilted bar's upper face slopes over up to its half length) under i's reach.
    """
    n = len(p)
    bottoms = []
    for i in range(n):
        low, high = _half_heights(types[i], upright)
        bottoms.append((p[i, 2] - high - tolerance_m, p[i, 2] - low + tolerance_m))
    supported = [lo <= TABLE_TOP_Z_M <= hi for lo, hi in bottoms]
    changed = True
    while changed:
        changed = False
        for i in range(n):
            if supported[i]:
                continue
            for j in range(n):
                if j == i or not supported[j]:
                    continue
                if upright:
                    near = bool(np.all(np.abs(p[i, :2] - p[j, :2]) < _HALF[types[i]][:2] + _HALF[types[j]][:2]))
                    top_lo = top_hi = p[j, 2] + _HALF[types[j]][2]
                else:
                    radii = _footprint_radius(types[i]) + _footprint_radius(types[j])
                    near = bool(np.hypot(*(p[i, :2] - p[j, :2])) < radii)
                    _, j_high = _half_heights(types[j], upright)
                    top_lo, top_hi = p[j, 2] - j_high, p[j, 2] + j_high
                if near and bottoms[i][0] <= top_hi and top_lo <= bottoms[i][1]:
                    supported[i] = changed = True
                    break
    return supported


def check_problem(X_init: np.ndarray, X_goal: np.ndarray, where: str = "problem", n_max: int | None = None,
                  init_upright: bool = True) -> None:
    """Both scenes of a problem; X_init is placed as given (upright) unless `init_upright` is False."""
    check_scene(X_init, where=where, field="X_init", upright=init_upright, n_max=n_max)
    check_scene(X_goal, where=where, field="X_goal", n_max=n_max)


__all__ = ["ARM_REACH_M", "BASE_CLEARANCE", "MAX_OBJECTS", "RESTING_TOLERANCE_M", "TABLE_TOP_Z_M", "TABLE_X",
           "TABLE_Y", "check_problem", "check_scene"]
