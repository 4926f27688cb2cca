"""The symbolic transition dataset: (pre bits, action, post bits) with a variable number of objects."""

from __future__ import annotations

import numpy as np

from symbolic.structs import OFFSETS, SymbolicDataset


def make_dataset(unary_pre, rel_pre, actions, unary_post, rel_post, n_per_transition=None) -> SymbolicDataset:
    """Validate and pack transitions.

    Shapes: unary (T, n_max, d_z), relations (T, K, n_max, n_max), actions (T, 4), n_per_transition
    (T,) with 1 <= n[t] <= n_max (default: all n_max). Transition t uses objects 0..n[t]-1; padding
    entries beyond n[t] are ignored. Raises ValueError with the offending shape or index.
    """
    up, rp = np.asarray(unary_pre), np.asarray(rel_pre)
    uq, rq = np.asarray(unary_post), np.asarray(rel_post)
    a = np.asarray(actions)
    if up.ndim != 3:
        raise ValueError(f"unary_pre must have shape (T, n_max, d_z), got {up.shape}")
    T, n_max, _ = up.shape
    if T == 0:
        raise ValueError("empty dataset: no transitions")
    if rp.ndim != 4 or rp.shape[0] != T or rp.shape[2:] != (n_max, n_max):
        raise ValueError(f"rel_pre must have shape ({T}, K, {n_max}, {n_max}), got {rp.shape}")
    if uq.shape != up.shape:
        raise ValueError(f"unary_post shape {uq.shape} differs from unary_pre {up.shape}")
    if rq.shape != rp.shape:
        raise ValueError(f"rel_post shape {rq.shape} differs from rel_pre {rp.shape}")
    if a.shape != (T, 4):
        raise ValueError(f"actions must have shape ({T}, 4), got {a.shape}")
    if not np.issubdtype(a.dtype, np.integer):
        if not np.all(a == np.round(a)):
            raise ValueError("actions must be integers (pick, grasp_offset, place, release_offset)")
    a = a.astype(np.int64)
    n = np.full(T, n_max, np.int64) if n_per_transition is None else np.asarray(n_per_transition)
    if n.shape != (T,):
        raise ValueError(f"n_per_transition must have shape ({T},), got {n.shape}")
    n = n.astype(np.int64)
    if (n < 1).any() or (n > n_max).any():
        raise ValueError(f"n_per_transition must lie in 1..{n_max}")
    for name, arr in (("unary_pre", up), ("rel_pre", rp), ("unary_post", uq), ("rel_post", rq)):
        if arr.size and not np.isin(arr, (0, 1)).all():
            raise ValueError(f"{name} must hold binary bits (0/1); round the model's activations first")
    for col, what in ((0, "pick"), (2, "place")):
        bad = np.flatnonzero((a[:, col] < 0) | (a[:, col] >= n))
        if bad.size:
            t = int(bad[0])
            raise ValueError(f"transition {t}: {what} object {a[t, col]} outside 0..{n[t] - 1}")
    for col, what in ((1, "grasp_offset"), (3, "release_offset")):
        bad = np.flatnonzero(~np.isin(a[:, col], OFFSETS))
        if bad.size:
            t = int(bad[0])
            raise ValueError(f"transition {t}: {what} {a[t, col]} not in {OFFSETS}")
    return SymbolicDataset(up.astype(np.uint8), rp.astype(np.uint8), a, uq.astype(np.uint8),
                           rq.astype(np.uint8), n)


def split_dataset(data: SymbolicDataset, holdout: float,
                  seed: int = 0) -> tuple[SymbolicDataset, SymbolicDataset | None]:
    """Random train / held-out split; holdout is the held-out fraction in [0, 1)."""
    if not 0.0 <= holdout < 1.0:
        raise ValueError(f"holdout fraction must be in [0, 1), got {holdout}")
    if holdout == 0.0:
        return data, None
    perm = np.random.default_rng(seed).permutation(len(data))
    k = int(round(holdout * len(data)))
    if k == 0 or k == len(data):
        return data, None
    return data.subset(np.sort(perm[k:])), data.subset(np.sort(perm[:k]))


def restrict_to_involved(data: SymbolicDataset, core_from_all: bool = False) -> SymbolicDataset:
    """Each transition restricted to the objects it involves: the picked object, the target, and
    every object whose unary or relation bits change. Operators learned from the result mention
    only those objects, so they apply to any scene that contains such a sub-state (a frame
    assumption on the other objects), which keeps learned domains small when the full pre-state of
    every object would make nearly every transition its own operator.

    An operator of the picked and target objects alone then holds only the transitions in which no
    other object changed: in larger scenes mostly failed picks, so its outcomes lean to "nothing
    happens". With `core_from_all`, a transition that changed other objects also appears restricted
    to its picked and target objects (the others' changes ignored there), so that operator holds
    what the action does to those two whatever else it disturbed."""
    T, n_max, d_z = data.unary_pre.shape
    up = np.zeros_like(data.unary_pre)
    uq = np.zeros_like(data.unary_post)
    rp = np.zeros_like(data.rel_pre)
    rq = np.zeros_like(data.rel_post)
    actions = data.actions.copy()
    n_new = np.zeros(T, np.int64)
    for t in range(T):
        n = int(data.n[t])
        pick, place = int(data.actions[t, 0]), int(data.actions[t, 2])
        du = (data.unary_pre[t, :n] != data.unary_post[t, :n]).any(axis=1)
        dr = data.rel_pre[t, :, :n, :n] != data.rel_post[t, :, :n, :n]
        changed = du | dr.any(axis=(0, 2)) | dr.any(axis=(0, 1))
        objects = [pick] + ([place] if place != pick else [])
        objects += [o for o in range(n) if changed[o] and o not in objects]
        o = np.array(objects)
        m = len(objects)
        up[t, :m], uq[t, :m] = data.unary_pre[t, o], data.unary_post[t, o]
        rp[t, :, :m, :m] = data.rel_pre[t][:, o][:, :, o]
        rq[t, :, :m, :m] = data.rel_post[t][:, o][:, :, o]
        actions[t, 0], actions[t, 2] = 0, (0 if place == pick else 1)
        n_new[t] = m
    involved = SymbolicDataset(up, rp, actions, uq, rq, n_new)
    core = 1 + (data.actions[:, 0] != data.actions[:, 2]).astype(np.int64)  # the picked and target objects
    more = np.flatnonzero(n_new > core) if core_from_all else np.zeros(0, np.int64)
    if not len(more):
        return involved
    # the same transitions cut to their first `core` objects (the picked one, then the target)
    keep = np.arange(n_max)[None, :] < core[more][:, None]  # (E, n_max)
    pair = keep[:, :, None] & keep[:, None, :]
    cut_u = [u[more] * keep[..., None] for u in (up, uq)]
    cut_r = [r[more] * pair[:, None] for r in (rp, rq)]
    return SymbolicDataset(np.concatenate([up, cut_u[0]]), np.concatenate([rp, cut_r[0]]),
                           np.concatenate([actions, actions[more]]), np.concatenate([uq, cut_u[1]]),
                           np.concatenate([rq, cut_r[1]]), np.concatenate([n_new, core[more]]))
