"""Lifted operators from symbolic transitions (paper, Background), their statistics and persistence.

Lifting. A transition in an n-object scene becomes an operator with n parameters: the picked
object, the target object (if different) and the n-1 or n-2 other objects. Transitions are grouped
by (n, pick == place, grasp offset, release offset, pre-state up to renaming of the other objects):
the other objects are put in the order that makes the pre-state code lexicographically smallest,
ties (symmetric objects) broken by the smallest effect code, so isomorphic transitions share one
operator and symmetric effects are counted as one. The precondition is the *full* pre-state over
the parameters: every unary bit of every parameter and every relation bit between parameters
(including r(x, x)), written as positive atoms ``u``/``not-u``, ``r``/``not-r``, plus pairwise
distinct parameters. The effect is the set difference to the post-state (bits that flip).

General operators (`general_bystanders`). The parameters besides the picked and target objects
are bystanders: a transition names them (with `involved_only`) because their relations to the moved
blocks changed. What happens to a bystander depends on where it stands relative to the moved blocks,
not on its own unary bits (where on the table it stands, its type) or on its relations to the other
bystanders. A transition that changed none of those bits is grouped with the bits left out: its
operator tests only the picked and target objects' bits and the relations that involve one of them
(`Operator.known_unary`, `known_rel`), and applies to every pre-state that agrees there. Transitions
that changed a bystander's own bits keep full operators.

Applicability in scenes of another size. Objects that are not parameters are neither tested nor
changed. An operator learned in an m-object scene therefore applies in an n >= m scene to every
m-subset of objects whose sub-state matches exactly (the published domain of the paper behaves the
same way), and never in a scene with fewer objects. `symbolic.grounding` also offers
``scope="exact"`` (only operators with arity == n), which keeps the frame assumption honest at the
price of coverage.
"""

from __future__ import annotations

import itertools
from collections import Counter, defaultdict
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from guarded import LARGE, Schema, atomic_write_text, dumps, read_json
from symbolic.structs import Effect, Operator, OperatorSet, SymbolicDataset

FORMAT = "symbolic-operators"
VERSION = 2  # 2: general operators carry known_unary / known_rel
READABLE = (1, 2)
_OFFSET_NAME = {-1: "m1", 0: "0", 1: "p1"}

GroupKey = tuple[int, bool, int, int, bool, bytes]  # (arity, same, grasp, release, general, canonical pre-state code)


def operator_name(index: int, grasp: int, release: int) -> str:
    return f"pp{index}_g{_OFFSET_NAME[grasp]}_r{_OFFSET_NAME[release]}"


def _canonicalize_group(U, R, Uq, Rq, pick, place, same):
    """Canonical parameter order for transitions with the same n and pick==place flag.

    Returns per transition: pre code (bytes), effect code (bytes) and the parameter order (T, n)
    mapping parameter index -> scene object.
    """
    T, n, _ = U.shape
    rows = np.arange(T)
    base = np.empty((T, n), np.int64)
    base[:, 0] = pick
    fixed = 1 if same else 2
    if not same:
        base[:, 1] = place
    objects = np.arange(n)
    for t in range(T):
        base[t, fixed:] = objects[(objects != pick[t]) & (objects != place[t])]
    best_pre: list[bytes | None] = [None] * T
    best_eff: list[bytes | None] = [None] * T
    best_order = base.copy()
    for perm in itertools.permutations(range(fixed, n)):
        order = np.concatenate([base[:, :fixed], base[:, list(perm)]], axis=1)
        u = U[rows[:, None], order]
        r = np.moveaxis(R[rows[:, None, None], :, order[:, :, None], order[:, None, :]], -1, 1)
        uq = Uq[rows[:, None], order]
        rq = np.moveaxis(Rq[rows[:, None, None], :, order[:, :, None], order[:, None, :]], -1, 1)
        pre = np.packbits(np.concatenate([u.reshape(T, -1), r.reshape(T, -1)], axis=1), axis=1)
        eff = np.packbits(np.concatenate([(u != uq).reshape(T, -1), (r != rq).reshape(T, -1)], axis=1), axis=1)
        for t in range(T):
            p, e = pre[t].tobytes(), eff[t].tobytes()
            if best_pre[t] is None or (p, e) < (best_pre[t], best_eff[t]):
                best_pre[t], best_eff[t], best_order[t] = p, e, order[t]
    return best_pre, best_eff, best_order


def _bystanders(data: SymbolicDataset) -> tuple[np.ndarray, np.ndarray]:
    """Per transition, the bits a general operator leaves out: each bystander's unary bits (T, n_max,
    d_z) and the relations between two distinct bystanders (T, K, n_max, n_max); bystanders are the
    objects other than the picked and target ones."""
    T, n_max, d = data.unary_pre.shape
    index = np.arange(n_max)[None, :]
    bystander = (index < data.n[:, None]) & (index != data.actions[:, :1]) & (index != data.actions[:, 2:3])
    unary = np.repeat(bystander[:, :, None], d, axis=2)
    pair = bystander[:, :, None] & bystander[:, None, :] & ~np.eye(n_max, dtype=bool)[None]
    return unary, np.repeat(pair[:, None], data.n_relations, axis=1)


def generalize(data: SymbolicDataset) -> tuple[SymbolicDataset, np.ndarray]:
    """The transitions with the bits a general operator leaves out set to 0 before and after, and
    which transitions are general: those that changed none of those bits (the others are returned
    unchanged and keep full operators)."""
    unary, rel = _bystanders(data)
    changed = ((data.unary_pre != data.unary_post) & unary).any(axis=(1, 2)) | \
        ((data.rel_pre != data.rel_post) & rel).any(axis=(1, 2, 3))
    general = ~changed
    return _zeroed(data, unary & general[:, None, None], rel & general[:, None, None, None]), general


def _zeroed(data: SymbolicDataset, unary: np.ndarray, rel: np.ndarray) -> SymbolicDataset:
    """The transitions with the given unary (T, n_max, d_z) and relation (T, K, n_max, n_max) bits
    set to 0 before and after."""
    def zero(bits: np.ndarray, where: np.ndarray) -> np.ndarray:
        return np.where(where, 0, bits).astype(np.uint8)

    return SymbolicDataset(zero(data.unary_pre, unary), zero(data.rel_pre, rel), data.actions,
                           zero(data.unary_post, unary), zero(data.rel_post, rel), data.n)


def _known(arity: int, same: bool, n_unary: int, n_relations: int) -> tuple[np.ndarray, np.ndarray]:
    """The bits a general operator of `arity` tests: all but its bystanders' (parameters from 1, or
    from 2 when pick != place) unary bits and the relations between two distinct bystanders."""
    first = 1 if same else 2
    unary = np.ones((arity, n_unary), dtype=bool)
    unary[first:] = False
    rel = np.ones((n_relations, arity, arity), dtype=bool)
    by = np.arange(arity) >= first
    rel[:, by[:, None] & by[None, :] & ~np.eye(arity, dtype=bool)] = False
    return unary, rel


def canonical_transitions(data: SymbolicDataset, general: np.ndarray | None = None
                          ) -> tuple[list[GroupKey], list[bytes], np.ndarray]:
    """Group key, effect code and parameter order (padded with -1) of every transition. `general`
    (bool per transition, from `generalize`, whose bits `data` must come from) marks the keys of
    general operators."""
    T = len(data)
    general = np.zeros(T, dtype=bool) if general is None else general
    keys: list[GroupKey | None] = [None] * T
    effs: list[bytes | None] = [None] * T
    orders = np.full((T, data.unary_pre.shape[1]), -1, np.int64)
    a = data.actions
    same_all = a[:, 0] == a[:, 2]
    for n in np.unique(data.n):
        for same in (True, False):
            idx = np.flatnonzero((data.n == n) & (same_all == same))
            if idx.size == 0:
                continue
            if not same and n < 2:
                raise ValueError("pick != place needs at least two objects")
            sl = slice(0, int(n))
            pre, eff, order = _canonicalize_group(
                data.unary_pre[idx, sl], data.rel_pre[idx][:, :, sl, sl],
                data.unary_post[idx, sl], data.rel_post[idx][:, :, sl, sl],
                a[idx, 0], a[idx, 2], same)
            for j, t in enumerate(idx):
                keys[t] = (int(n), bool(same), int(a[t, 1]), int(a[t, 3]), bool(general[t]), pre[j])
                effs[t] = eff[j]
                orders[t, : int(n)] = order[j]
    return keys, effs, orders  # type: ignore[return-value]


def _lifted(data: SymbolicDataset, t: int, order: np.ndarray):
    n = int(data.n[t])
    o = order[:n]
    u, r = data.unary_pre[t][o], data.rel_pre[t][:, o][:, :, o]
    uq, rq = data.unary_post[t][o], data.rel_post[t][:, o][:, :, o]
    effect = Effect(tuple((int(i), int(k)) for i, k in zip(*np.nonzero(u != uq))),
                    tuple((int(k), int(i), int(j)) for k, i, j in zip(*np.nonzero(r != rq))))
    return u, r, effect


def learn_operators(data: SymbolicDataset, general_bystanders: bool = False) -> OperatorSet:
    """Group transitions into lifted operators with their empirical effect distributions; with
    `general_bystanders`, the transitions that left their bystanders' own bits alone into general
    operators (module docstring)."""
    if len(data) == 0:
        raise ValueError("empty dataset: no transitions to learn operators from")
    general = None
    if general_bystanders:
        data, general = generalize(data)
    keys, effs, orders = canonical_transitions(data, general)
    members: dict[GroupKey, list[int]] = defaultdict(list)
    for t, key in enumerate(keys):
        members[key].append(t)
    groups = sorted(members.items(), key=lambda kv: (-len(kv[1]), kv[0]))
    operators = []
    for index, (key, ts) in enumerate(groups):
        arity, same, grasp, release, is_general, _ = key
        counts: Counter = Counter()
        decoded: dict[bytes, Effect] = {}
        for t in ts:
            code = effs[t]
            if code not in decoded:
                decoded[code] = _lifted(data, t, orders[t])[2]
            counts[decoded[code]] += 1
        pre_u, pre_r, _ = _lifted(data, ts[0], orders[ts[0]])
        ranked = sorted(counts.items(), key=lambda ec: (-ec[1], ec[0]))
        known_u: np.ndarray | None = None
        known_r: np.ndarray | None = None
        if is_general and arity > (1 if same else 2):  # with no bystander, nothing is left out
            known_u, known_r = _known(arity, same, data.n_unary, data.n_relations)
        operators.append(Operator(
            name=operator_name(index, grasp, release), arity=arity, same=same, grasp=grasp,
            release=release, pre_unary=pre_u, pre_rel=pre_r,
            effects=tuple(e for e, _ in ranked), counts=tuple(c for _, c in ranked),
            known_unary=known_u, known_rel=known_r))
    return OperatorSet(operators, data.n_unary, data.n_relations)


def filter_operators(ops: OperatorSet, min_count: int = 0, min_prob: float = 0.0) -> OperatorSet:
    """The operators seen at least `min_count` times, each without the effects of empirical
    probability below `min_prob` (the rest renormalised, i.e. their counts kept). The paper's
    authors keep operators seen more than 50 times and effects with p >= 0.1: rare pre-states and
    rare outcomes are mostly symbol noise, and each one is a way for a plan to go wrong."""
    if min_count < 0 or not 0.0 <= min_prob <= 1.0:
        raise ValueError(f"min_count must be >= 0 and min_prob in [0, 1], got {min_count}, {min_prob}")
    kept = []
    for op in ops.operators:
        if op.count < min_count:
            continue
        keep = [i for i, p in enumerate(op.probabilities) if p >= min_prob] or [0]
        kept.append(replace(op, effects=tuple(op.effects[i] for i in keep), counts=tuple(op.counts[i] for i in keep)))
    return OperatorSet(kept, ops.n_unary, ops.n_relations)


def operator_key(op: Operator) -> GroupKey:
    code = np.packbits(np.concatenate([op.pre_unary.ravel(), op.pre_rel.ravel()]).astype(np.uint8))
    return (op.arity, op.same, op.grasp, op.release, op.is_general, code.tobytes())


def coverage(ops: OperatorSet, data: SymbolicDataset) -> dict[str, float | int]:
    """How well operators explain (held-out) transitions.

    matched: fraction whose lifted pre-state + action is the precondition of an operator;
    effect_predicted: fraction whose observed effect is among that operator's effects (PPDDL);
    effect_is_mode: fraction whose observed effect is the operator's most frequent one (PDDL).
    """
    if len(data) == 0:
        raise ValueError("empty dataset: nothing to measure coverage on")
    if (data.n_unary, data.n_relations) != (ops.n_unary, ops.n_relations):
        raise ValueError(f"dataset has d_z={data.n_unary}, K={data.n_relations}; operators were "
                         f"learned with d_z={ops.n_unary}, K={ops.n_relations}")
    table = {operator_key(op): op for op in ops.operators}
    keys, _, orders = canonical_transitions(data)
    # the key of the general operator each pre-state would match, whatever the transition changed
    seen_general = _zeroed(data, *_bystanders(data))
    _, is_general = generalize(data)
    any_general = any(op.is_general for op in ops.operators)
    general_keys, _, general_orders = canonical_transitions(seen_general, np.ones(len(data), dtype=bool)) \
        if any_general else (keys, None, orders)
    matched = predicted = mode = 0
    for t, key in enumerate(keys):
        outcomes = []  # (operator, the transition's effect in its parameter order, or None if it has none)
        if key in table:
            outcomes.append((table[key], _lifted(data, t, orders[t])[2]))
        if any_general and general_keys[t] in table:
            effect = _lifted(seen_general, t, general_orders[t])[2] if is_general[t] else None
            outcomes.append((table[general_keys[t]], effect))
        if not outcomes:
            continue
        matched += 1
        predicted += any(effect in op.effects for op, effect in outcomes)
        mode += any(effect == op.effects[0] for op, effect in outcomes)
    T = len(data)
    return {"transitions": T, "matched": matched / T, "effect_predicted": predicted / T,
            "effect_is_mode": mode / T}


def stats(ops: OperatorSet) -> dict:
    """Number of operators, effects per operator, arities, supporting transitions."""
    n_eff = np.array([len(op.effects) for op in ops.operators], dtype=int)
    return {
        "n_operators": len(ops),
        "n_probabilistic": int((n_eff > 1).sum()),
        "n_unary": ops.n_unary,
        "n_relations": ops.n_relations,
        "operators_by_arity": {str(k): v for k, v in sorted(Counter(op.arity for op in ops.operators).items())},
        "effects_per_operator": {
            "mean": float(n_eff.mean()) if n_eff.size else 0.0,
            "max": int(n_eff.max()) if n_eff.size else 0,
            "histogram": {str(k): v for k, v in sorted(Counter(n_eff.tolist()).items())},
        },
        "transitions": int(sum(op.count for op in ops.operators)),
    }


def to_json(ops: OperatorSet) -> dict:
    return {
        "format": FORMAT, "version": VERSION, "n_unary": ops.n_unary, "n_relations": ops.n_relations,
        "operators": [{
            "name": op.name, "arity": op.arity, "same": op.same, "grasp": op.grasp, "release": op.release,
            "pre_unary": op.pre_unary.tolist(), "pre_rel": op.pre_rel.tolist(),
            **({} if op.known_unary is None or op.known_rel is None else
               {"known_unary": op.known_unary.astype(int).tolist(), "known_rel": op.known_rel.astype(int).tolist()}),
            "effects": [{"unary_flips": [list(f) for f in e.unary_flips],
                         "rel_flips": [list(f) for f in e.rel_flips], "count": c}
                        for e, c in zip(op.effects, op.counts)],
        } for op in ops.operators],
    }


_BITS = {"type": "array", "items": {"type": "array", "items": {"enum": [0, 1]}}}
_FLIPS = {"type": "array", "items": {"type": "array", "items": {"type": "integer", "minimum": 0}}}
# the structure of an operators file; shapes and flip indices against n_unary, n_relations and arity are
# checked after it (`_operator`)
SCHEMA = Schema({
    "type": "object", "required": ["n_unary", "n_relations", "operators"],
    "properties": {"n_unary": {"type": "integer", "minimum": 0, "maximum": 1024},
                   "n_relations": {"type": "integer", "minimum": 0, "maximum": 64},
                   "operators": {"type": "array", "items": {
                       "type": "object",
                       "required": ["name", "arity", "same", "grasp", "release", "pre_unary", "pre_rel", "effects"],
                       "properties": {
                           "name": {"type": "string"}, "arity": {"type": "integer", "minimum": 1, "maximum": 16},
                           "same": {"type": "boolean"}, "grasp": {"enum": [-1, 0, 1]}, "release": {"enum": [-1, 0, 1]},
                           "pre_unary": _BITS, "pre_rel": {"type": "array", "items": _BITS},
                           "known_unary": _BITS, "known_rel": {"type": "array", "items": _BITS},
                           "effects": {"type": "array", "minItems": 1, "items": {
                               "type": "object", "required": ["unary_flips", "rel_flips", "count"],
                               "properties": {"unary_flips": _FLIPS, "rel_flips": _FLIPS,
                                              "count": {"type": "integer", "minimum": 0}}}}}}}}})


def _bits(value: list, shape: tuple[int, ...], where: str, dtype: type = np.uint8) -> np.ndarray:
    """A schema-checked nest of 0/1 lists as an array of `shape`; ValueError naming `where` otherwise."""
    try:
        array: np.ndarray = np.array(value, dtype=dtype)
    except ValueError:  # ragged
        array = np.zeros(0)
    if array.shape != shape:
        raise ValueError(f"{where}: expected {' x '.join(map(str, shape))} bits")
    return array


def _flips(value: list, bounds: tuple[int, ...], where: str) -> Any:
    """Schema-checked flips as a tuple of index tuples, each of len(bounds) indices below `bounds`."""
    for i, flip in enumerate(value):
        if len(flip) != len(bounds) or any(v >= b for v, b in zip(flip, bounds)):
            raise ValueError(f"{where}[{i}]: expected {len(bounds)} indices below {list(bounds)}, got {flip}")
    return tuple(tuple(f) for f in value)


def _operator(o: dict, d: int, K: int, where: str) -> Operator:
    a = o["arity"]
    known = "known_unary" in o
    if known != ("known_rel" in o):
        raise ValueError(f"{where}: known_unary and known_rel come together")
    effects = tuple(Effect(_flips(e["unary_flips"], (a, d), f"{where}.effects[{i}].unary_flips"),
                           _flips(e["rel_flips"], (K, a, a), f"{where}.effects[{i}].rel_flips"))
                    for i, e in enumerate(o["effects"]))
    return Operator(o["name"], a, o["same"], o["grasp"], o["release"],
                    _bits(o["pre_unary"], (a, d), f"{where}.pre_unary"),
                    _bits(o["pre_rel"], (K, a, a), f"{where}.pre_rel"), effects,
                    tuple(e["count"] for e in o["effects"]),
                    _bits(o["known_unary"], (a, d), f"{where}.known_unary", bool) if known else None,
                    _bits(o["known_rel"], (K, a, a), f"{where}.known_rel", bool) if known else None)


def from_json(doc: Any, where: str = "operators") -> OperatorSet:
    """The OperatorSet of a parsed operators file: format and version, `SCHEMA`, then every operator's
    shapes and flips; ValueError naming `where` and the field otherwise."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        got = doc.get("format") if isinstance(doc, dict) else type(doc).__name__
        raise ValueError(f"{where}: not an operators file (format {str(got)[:40]!r}, expected {FORMAT!r})")
    if doc.get("version") not in READABLE:
        raise ValueError(f"{where}: operators.json version {str(doc.get('version'))[:40]} unsupported "
                         f"(expected one of {READABLE})")
    SCHEMA.check(doc, where)
    d, K = doc["n_unary"], doc["n_relations"]
    return OperatorSet([_operator(o, d, K, f"{where}: operators[{i}]") for i, o in enumerate(doc["operators"])], d, K)


def save_operators(ops: OperatorSet, path: str | Path) -> None:
    """Write `ops` as an operators.json, atomically."""
    atomic_write_text(path, dumps(to_json(ops), separators=(",", ":")))


def load_operators(path: str | Path) -> OperatorSet:
    """Operators of an operators.json (or .json.gz), through the guarded reader; a missing, damaged or
    malformed file is a ValueError (`guarded.InputError` for the reader's and schema's findings) naming it."""
    return from_json(read_json(path, "operators file", LARGE), str(path))
