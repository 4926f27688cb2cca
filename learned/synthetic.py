"""Toy, physics-free pick-place rules mimicking the skill, for tests and benchmarks without Drake.

Rules (metres, blocks axis-aligned, 5 cm tall; small = 5 x 5 cm, large = 5 x 25 cm along y):
the gripper descends top-down at ``g = p_pick + d_grasp * 0.075 y_hat`` and grasps the topmost
block whose footprint contains ``g`` (none: nothing moves, status ``nothing_grasped``). It
carries that block (and the blocks resting on it), keeping their offset to the gripper, to
``p_place + d_release * 0.075 y_hat`` and releases it; then every block settles, lowest first,
onto the highest block under its centre (or the table). A little Gaussian noise on the landing xy stands in for physics.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .dataset import DatasetWriter, Transitions, pack_samples
from .effects import OFFSET_M

STATUS_CODES = {"ok": 0, "ik_failure": 1, "motion_failure": 2, "nothing_grasped": 3}
"""The world's outcome codes (tamp.sim.world_types.STATUSES order); the toy rules emit 0 and 3 only."""
HALF_XY = np.array([[0.025, 0.025], [0.025, 0.125]])
"""Footprint half extents (x, y) in metres by type index (small, large)."""
HALF_Z = 0.025
WORKSPACE = ((0.45, 0.85), (-0.35, 0.35))
"""x and y ranges (metres) for random block centres."""


def _half(X: np.ndarray) -> np.ndarray:
    return HALF_XY[np.argmax(X[:, 3:5], axis=1)]


def _settle(X: np.ndarray, order: np.ndarray) -> None:
    """Drop blocks in ``order`` onto the highest already-settled block under their centre."""
    half = _half(X)
    done: list[int] = []
    for i in order:
        tops = [X[k, 2] + HALF_Z for k in done
                if np.all(np.abs(X[i, :2] - X[k, :2]) <= half[k])]
        X[i, 2] = max(tops, default=0.0) + HALF_Z
        done.append(i)


def _carried(X: np.ndarray, grasped: int) -> list[int]:
    """The grasped block and, recursively, the blocks resting on it (lowest first)."""
    half, out = _half(X), [grasped]
    for i in out:
        out += [k for k in range(len(X)) if k not in out and abs(X[k, 2] - X[i, 2] - 2 * HALF_Z) < 1e-3
                and np.all(np.abs(X[k, :2] - X[i, :2]) <= half[i])]
    return out


def apply_action(X: np.ndarray, action, rng: np.random.Generator | None = None,
                 noise_m: float = 0.0) -> tuple[np.ndarray, int, int]:
    """Toy outcome of one pick-place: (X_next, grasped index or -1, status code)."""
    pick, d_grasp, place, d_release = (int(v) for v in action)
    X = np.array(X, dtype=np.float64)
    g = X[pick, :2] + (0.0, d_grasp * OFFSET_M)
    under = np.all(np.abs(g - X[:, :2]) <= _half(X), axis=1)
    if not under.any():
        return X, -1, STATUS_CODES["nothing_grasped"]
    grasped = int(np.flatnonzero(under)[np.argmax(X[under, 2])])
    carried = _carried(X, grasped)
    target = X[place, :2] + (0.0, d_release * OFFSET_M)
    shift = target - g
    if rng is not None and noise_m > 0:
        shift = shift + rng.normal(0.0, noise_m, 2)
    X[carried, :2] += shift
    z = X[:, 2].copy()
    z[carried] = 1e3 + np.arange(len(carried))  # released above everything else, in order
    _settle(X, np.argsort(z, kind="stable"))
    return X, grasped, STATUS_CODES["ok"]


def random_scene(rng: np.random.Generator, n: int, stack_prob: float = 0.3) -> np.ndarray:
    """n non-overlapping blocks on the table; with ``stack_prob`` one random move stacks blocks."""
    X = np.zeros((n, 5))
    for i in range(n):
        X[i, 3 + rng.integers(2)] = 1.0
        for _ in range(1000):
            X[i, 0] = rng.uniform(*WORKSPACE[0])
            X[i, 1] = rng.uniform(*WORKSPACE[1])
            gap = np.abs(X[:i, :2] - X[i, :2]) - _half(X[:i]) - _half(X[i:i + 1])
            if i == 0 or np.all(np.any(gap > 0.01, axis=1)):
                break
        X[i, 2] = HALF_Z
    if rng.random() < stack_prob:
        a, b = rng.choice(n, 2, replace=False)
        X, _, _ = apply_action(X, (a, 0, b, 0))
    return X


def random_action(rng: np.random.Generator, n: int) -> tuple[int, int, int, int]:
    """Uniform over the 9 n^2 actions."""
    return (int(rng.integers(n)), int(rng.integers(-1, 2)), int(rng.integers(n)),
            int(rng.integers(-1, 2)))


def generate(num_samples: int, seed: int = 0, n_choices=(2, 3, 4), n_max: int = 4,
             noise_m: float = 0.002) -> Transitions:
    """Random scenes and random actions under the toy rules, padded to ``n_max``."""
    rng = np.random.default_rng(seed)
    samples = []
    for _ in range(num_samples):
        n = int(rng.choice(n_choices))
        X = random_scene(rng, n)
        a = random_action(rng, n)
        X_next, grasped, status = apply_action(X, a, rng, noise_m)
        samples.append({"X": X, "action": a, "X_next": X_next, "grasped": grasped,
                        "status": status})
    meta = {"format": "tamp-transitions/1", "n_max": n_max, "seed": seed,
            "status_codes": STATUS_CODES, "world_config": {"synthetic": True}}
    arrays: dict[str, Any] = pack_samples(samples, n_max)
    return Transitions(**arrays, meta=meta)


def write_synthetic_dataset(directory: str | Path, num_samples: int, seed: int = 0,
                            shard_size: int = 1000, n_max: int = 4, n_choices=(2, 3, 4)) -> Path:
    """Write a toy dataset in the on-disk format (exercises the same writer as the collector)."""
    data = generate(num_samples, seed, n_choices, n_max=n_max)
    with DatasetWriter(directory, n_max=n_max, seed=seed, status_codes=STATUS_CODES,
                       world_config={"synthetic": True, "noise_m": 0.002},
                       shard_size=shard_size) as w:
        for s in range(len(data)):
            n = int(data.n[s])
            w.add(data.X[s, :n], data.action[s], data.X_next[s, :n], int(data.grasped[s]),
                  int(data.status[s]))
    return Path(directory)
