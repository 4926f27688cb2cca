"""Lifted successor generation: the applicable ground actions of a state without grounding the task.

An operator's precondition fixes every bit of its parameters (their unary bits and every relation
among them; a general operator, every bit it tests), so in a state each ordered tuple of distinct
objects matches exactly the operators whose pre-state equals the tuple's sub-state on those bits:
one lookup per tuple and group of operators that test the same bits, P(n, a) tuples of arity a
(516 at n = 6), instead of testing every ground action (1.27 million for the bundled domain at
n = 6). Regression works the same way with the post-states (pre-state XOR effect): the predecessors
of a state, used for the search's distance bounds.

Ground actions are (operator, tuple) pairs, ordered by operator index, then by the tuple in
`itertools.permutations` order: the order in which a grounded task numbers them, which decides
which of several shortest plans a breadth-first search returns. A ground action is identified by
one int, ``operator * n_tuples + tuple``, which sorts in that order. A state is a Python int in the
bit layout of `atoms.py`; its expansion is computed with numpy and cached per state.
"""

from __future__ import annotations

import copy
import itertools
from dataclasses import dataclass

import numpy as np

from symbolic.atoms import n_bits, object_name
from symbolic.structs import Action, OperatorSet, PlanStep

GroundAction = int  # operator * n_tuples + tuple index: sorts in ground-action order
MAX_PRECONDITION_BITS = 58  # an operator's sub-state code and its group tag share one int64 key
TAG_BITS = 5  # a key's low bits: the group (arity and tested bits) of the operators it is for
MAX_GROUPS = 1 << TAG_BITS


def max_arity(n_unary: int, n_relations: int, given_diagonal: bool = False) -> int:
    """The largest operator arity a lifted search takes: a * n_unary + n_relations * a^2 precondition
    bits at most `MAX_PRECONDITION_BITS` (4 for the bundled 1 unary bit and 3 relations). With
    `given_diagonal` (pairwise relations: r_k(i, i) = 1 always) the a diagonal bits of each relation
    are no part of the key (`LiftedTask`), so a * n_unary + n_relations * a * (a - 1) bits count."""
    def width(a: int) -> int:
        return a * n_unary + n_relations * a * (a - 1 if given_diagonal else a)

    a = 0
    while width(a + 1) <= MAX_PRECONDITION_BITS:
        a += 1
    return a


def _key_layout(operators: list, arity: int, known: np.ndarray, n_unary: int, n_relations: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which local bits of a group's operators (one arity, the same `known` tested bits) enter their
    key: all tested bits when they fit in `MAX_PRECONDITION_BITS`, else all but the relations'
    diagonal r_k(i, i) when it is the same in every precondition and every outcome (pairwise
    relations: always set); a state's tuple must then have those values besides its key. Returns
    (key bits, fixed bits, their values), local indices ascending."""
    every = np.flatnonzero(known)
    none = (every, every[:0], every[:0])
    if len(every) <= MAX_PRECONDITION_BITS or not operators:
        return none
    diagonal = np.array([arity * n_unary + k * arity * arity + i * arity + i
                         for k in range(n_relations) for i in range(arity)], dtype=np.int64)
    diagonal = diagonal[known[diagonal]]
    pres = [np.concatenate([op.pre_unary.ravel(), op.pre_rel.ravel()]).astype(np.int64) for op in operators]
    posts = [_flipped(pre, _local_flips(e, arity, n_unary)) for op, pre in zip(operators, pres) for e in op.effects]
    states = np.array(pres + posts)[:, diagonal]
    if not np.all(states == states[:1]):
        return none
    return np.setdiff1d(every, diagonal), diagonal, states[0]


@dataclass(frozen=True)
class Expansion:
    """What the applicable ground actions of a state do, independent of any sampled domain.

    Events, in ground-action order (parallel lists): for every distinct successor, the (ground
    action, effect) pairs leading to it up to and including the first whose operator is
    deterministic (`event_op` -1: it leads there in every domain, so no later pair comes first).
    A breadth-first search in any one domain generates the successors in the order of these events.
    """

    successors: list[int]  # distinct successor states (the state itself when an action changes nothing)
    event_successor: list[int]  # index into successors
    event_op: list[int]  # operator index, -1 if deterministic
    event_effect: list[int]  # effect index of the operator
    event_action: list[int]  # GroundAction
    successor_of_event: np.ndarray  # event_successor as an array, for vectorised filtering


class _CodeIndex:
    """Sorted keys (group-tagged sub-state codes) -> effect rows in CSR form, for vectorised lookups."""

    def __init__(self, keys: list[int], rows: list[list[int]]):
        order = np.argsort(np.array(keys, dtype=np.int64), kind="stable")
        self.keys = np.array(keys, dtype=np.int64)[order]
        lists = [rows[i] for i in order.tolist()]
        self.start = np.concatenate([[0], np.cumsum([len(r) for r in lists])]).astype(np.int64)
        self.rows = np.array([r for rs in lists for r in rs], dtype=np.int64)

    def match(self, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(positions in `keys`, effect rows) of every match, positions ascending, rows in stored order."""
        if len(self.keys) == 0:
            return np.empty(0, np.int64), np.empty(0, np.int64)
        idx = np.minimum(np.searchsorted(self.keys, keys), len(self.keys) - 1)
        hit = np.flatnonzero(self.keys[idx] == keys)
        lo, hi = self.start[idx[hit]], self.start[idx[hit] + 1]
        counts = hi - lo
        total = int(counts.sum())
        ramp = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
        return np.repeat(hit, counts), self.rows[np.repeat(lo, counts) + ramp]


class LiftedTask:
    """The ground actions of an operator set in an n-object scene, generated per state.

    scope="subset": operators of arity <= n bind to any ordered tuple of distinct objects (objects
    that are not parameters are untouched); scope="exact": only operators of arity == n.
    """

    def __init__(self, ops: OperatorSet, n: int, scope: str = "subset"):
        if scope not in ("subset", "exact"):
            raise ValueError(f"scope must be 'subset' or 'exact', got {scope!r}")
        self.ops, self.n, self.scope = ops, n, scope
        d, K = ops.n_unary, ops.n_relations
        self.n_bits = n_bits(n, d, K)
        self.words = max((self.n_bits + 63) // 64, 1)  # uint64 words of a state (64 bits at n = 4: one word)
        n_effects = [len(op.effects) for op in ops.operators]
        self.effect_start = np.concatenate([[0], np.cumsum(n_effects)]).astype(np.int64)
        self.effect_op = np.repeat(np.arange(len(ops)), n_effects)
        self.effect_index = np.arange(len(self.effect_op)) - self.effect_start[self.effect_op]
        self.deterministic = np.array(n_effects, dtype=np.int64)[self.effect_op] == 1
        allowed = [op.arity <= n if scope == "subset" else op.arity == n for op in ops.operators]
        self.arities = sorted({op.arity for op, ok in zip(ops.operators, allowed) if ok})
        group_of = self._group_operators(allowed, d, K)
        self._tuple_table(n, d, K)
        self._effect_rows(group_of, d)
        self._cache: dict[int, Expansion] = {}

    def _group_operators(self, allowed: list[bool], d: int, K: int) -> list[int]:
        """Operators in groups of one arity and the same tested bits (general operators test fewer), by
        arity; each group has its own tuples, key layout and tag. Returns each operator's group (-1: not
        allowed in this scene)."""
        ops = self.ops
        names: dict[tuple[int, bytes], int] = {}
        for op in sorted((op for op, ok in zip(ops.operators, allowed) if ok), key=lambda o: o.arity):
            names.setdefault((op.arity, op.known_bits().tobytes()), len(names))
        if len(names) > MAX_GROUPS:
            raise ValueError(f"operators test {len(names)} different sets of bits; at most {MAX_GROUPS} are supported")
        self.groups = [(a, np.frombuffer(known, dtype=bool)) for a, known in names]
        group_of = [names[(op.arity, op.known_bits().tobytes())] if ok else -1
                    for op, ok in zip(ops.operators, allowed)]
        # per group, the local bits of the key and the fixed ones (`_key_layout`)
        self._layout: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        for g, (a, known) in enumerate(self.groups):
            of_g = [op for op, group in zip(ops.operators, group_of) if group == g]
            self._layout[g] = keep, _, _ = _key_layout(of_g, a, known, d, K)
            if len(keep) > MAX_PRECONDITION_BITS:
                given = len(keep) < int(known.sum())
                raise ValueError(f"operators of arity {a} ({len(keep)} precondition bits) are not supported: at "
                                 f"most arity {max_arity(d, K, given)} ({MAX_PRECONDITION_BITS} bits); learn the domain"
                                 " again with `tamp domain`, whose --max-arity keeps to that limit by default")
        return group_of

    def _tuple_table(self, n: int, d: int, K: int) -> None:
        """The ground tuples of every group's arity, their bits' positions in the state and their keys'."""
        # Tuples of every arity in one table: their local bits' global positions, padded with n_bits
        # (a bit that is always 0), and the tuple's arity; the positions of their key bits and of
        # their fixed bits (padded alike), with the values the fixed ones must have.
        L_max = max((a * d + K * a * a for a in self.arities), default=0)
        Lk_max = max((len(layout[0]) for layout in self._layout.values()), default=0)
        F_max = max((len(layout[1]) for layout in self._layout.values()), default=0)
        tuples, positions, key_positions, fixed_positions, fixed_values, tag_of = [], [], [], [], [], []
        for g, (a, _) in enumerate(self.groups):
            perms = np.array(list(itertools.permutations(range(n), a)), dtype=np.int64).reshape(-1, a)
            cols = [perms[:, i] * d + k for i in range(a) for k in range(d)]
            cols += [n * d + k * n * n + perms[:, i] * n + perms[:, j]
                     for k in range(K) for i in range(a) for j in range(a)]
            pos = np.full((len(perms), L_max + 1), self.n_bits, dtype=np.int64)
            if cols:
                pos[:, : len(cols)] = np.stack(cols, axis=1)
            keep, fixed, values = self._layout[g]
            kpos = np.full((len(perms), Lk_max), self.n_bits, dtype=np.int64)
            kpos[:, : len(keep)] = pos[:, keep]
            fpos = np.full((len(perms), F_max), self.n_bits, dtype=np.int64)
            fpos[:, : len(fixed)] = pos[:, fixed]
            fval = np.zeros((len(perms), F_max), dtype=np.int64)
            fval[:, : len(fixed)] = values
            tuples.append(perms)
            positions.append(pos)
            key_positions.append(kpos)
            fixed_positions.append(fpos)
            fixed_values.append(fval)
            tag_of.append(np.full(len(perms), g, dtype=np.int64))
        self.tuples = [tuple(int(v) for v in row) for perms in tuples for row in perms]
        self.n_tuples = max(len(self.tuples), 1)
        self.positions = np.concatenate(positions) if positions else np.zeros((0, 1), np.int64)
        self._key_positions = np.concatenate(key_positions) if key_positions else np.zeros((0, 0), np.int64)
        self._fixed_positions = np.concatenate(fixed_positions) if fixed_positions else np.zeros((0, 0), np.int64)
        self._fixed_values = np.concatenate(fixed_values) if fixed_values else np.zeros((0, 0), np.int64)
        self._tuple_tag = np.concatenate(tag_of) if tag_of else np.zeros(0, np.int64)
        self._shift = np.arange(Lk_max, dtype=np.int64)
        # per word of the state, the value of each local bit of each tuple (0 for the padding column)
        self._bit_value = []
        for w in range(self.words):
            inside = (self.positions >> 6) == w
            value = np.left_shift(np.uint64(1), (self.positions & 63).astype(np.uint64))
            self._bit_value.append(np.where(inside & (self.positions < self.n_bits), value, np.uint64(0)))

    def _effect_rows(self, group_of: list[int], d: int) -> None:
        """Every effect row's local flips, and the indexes from a tuple's key to the rows that apply (all,
        the first per distinct flip) and to the rows that lead to it."""
        ops = self.ops
        # Local flip positions of every effect row (padded with -1: the padding column of `positions`).
        F = max((len(e.unary_flips) + len(e.rel_flips) for op in ops.operators for e in op.effects), default=0)
        self.effect_local = np.full((len(self.effect_op), max(F, 1)), -1, dtype=np.int64)
        pre_groups: dict[int, list[int]] = {}  # key -> effect rows in (operator, effect) order
        post_groups: dict[int, dict[bytes, int]] = {}  # key -> one row per distinct local flip
        local_flip: list[bytes] = []  # per effect row: its arity and sorted local flip positions
        flip_ids: dict[bytes, int] = {}
        for oi, (op, group) in enumerate(zip(ops.operators, group_of)):
            a = op.arity
            pre = np.concatenate([op.pre_unary.ravel(), op.pre_rel.ravel()]).astype(np.int64)
            for j, e in enumerate(op.effects):
                local = _local_flips(e, a, d)
                row = int(self.effect_start[oi]) + j
                self.effect_local[row, : len(local)] = local
                local_flip.append(bytes([a]) + bytes(sorted(local)))
                flip_ids.setdefault(local_flip[-1], len(flip_ids))
                if group < 0:
                    continue
                keep = self._layout[group][0]
                pre_groups.setdefault(_key(pre[keep], group), []).append(row)
                post_groups.setdefault(_key(_flipped(pre, local)[keep], group), {}).setdefault(local_flip[-1], row)
        self.flip_id = np.array([flip_ids[f] for f in local_flip], dtype=np.int64)
        self._n_flip_ids = max(len(flip_ids), 1)
        # The first rows: per pre-state and distinct local flip, the rows up to the first deterministic
        # one (a later row of the same tuple and flip never comes first in any domain).
        first_groups: dict[int, list[int]] = {}
        for key, rows in pre_groups.items():
            done: set[bytes] = set()
            first_groups[key] = []
            for r in rows:
                if local_flip[r] in done:
                    continue
                first_groups[key].append(r)
                if self.deterministic[r]:
                    done.add(local_flip[r])
        self._all = _CodeIndex(list(pre_groups), list(pre_groups.values()))
        self._first = _CodeIndex(list(first_groups), list(first_groups.values()))
        self._post = _CodeIndex(list(post_groups), [list(g.values()) for g in post_groups.values()])

    def restricted(self, movable: tuple[int, ...]) -> LiftedTask:
        """The task whose ground actions pick only objects in `movable`: the tuples whose first
        object (the picked one) is in it, in the same order. Operator tables are shared; ground
        action numbers are the restricted task's own."""
        sub = copy.copy(self)
        keep = np.array([t[0] in movable for t in self.tuples], dtype=bool)
        sub.tuples = [t for t, k in zip(self.tuples, keep.tolist()) if k]
        sub.n_tuples = max(len(sub.tuples), 1)
        sub.positions = self.positions[keep]
        sub._key_positions = self._key_positions[keep]
        sub._fixed_positions, sub._fixed_values = self._fixed_positions[keep], self._fixed_values[keep]
        sub._tuple_tag = self._tuple_tag[keep]
        sub._bit_value = [v[keep] for v in self._bit_value]
        sub._cache = {}
        return sub

    # ---- state helpers ---------------------------------------------------------------------------
    def _keys(self, state: int) -> np.ndarray:
        """Group-tagged sub-state code of every tuple in `state`; -1 (no operator's) for a tuple whose
        fixed bits (`_key_layout`) differ from every operator's."""
        # one spare byte: the padding position n_bits reads 0 even when the state fills its words
        raw = np.frombuffer(state.to_bytes(self.words * 8 + 1, "little"), dtype=np.uint8)
        bits = np.unpackbits(raw, bitorder="little").astype(np.int64)
        codes = (bits[self._key_positions] << self._shift).sum(axis=1) * MAX_GROUPS + self._tuple_tag
        if self._fixed_positions.shape[1]:
            codes[(bits[self._fixed_positions] != self._fixed_values).any(axis=1)] = -1
        return codes

    def _flips(self, tuple_idx: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """(R, words) uint64 XOR masks of effect rows applied to tuples."""
        local = self.effect_local[rows]
        return np.stack([table[tuple_idx[:, None], local].sum(axis=1) for table in self._bit_value], axis=1)

    def _successors(self, state: int, tuple_idx: np.ndarray, rows: np.ndarray) -> tuple[list[int], np.ndarray]:
        """Distinct states reached by effect rows applied to tuples, in order of the first row that
        reaches each, and the successor index of every row. Global flips are computed once per
        distinct (tuple, local flip): operators that differ only in their offsets share effects."""
        pair = tuple_idx * self._n_flip_ids + self.flip_id[rows]
        _, first_row, pair_of_row = np.unique(pair, return_index=True, return_inverse=True)
        flips = self._flips(tuple_idx[first_row], rows[first_row])
        # distinct global flips (several tuples can flip the same bits)
        order = np.lexsort(flips.T[::-1]) if self.words > 1 else np.argsort(flips[:, 0], kind="stable")
        ordered = flips[order]
        new = np.ones(len(order), bool)
        new[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
        flip_of_pair = np.empty(len(order), np.int64)
        flip_of_pair[order] = np.cumsum(new) - 1
        flip_of_row = flip_of_pair[pair_of_row.ravel()]
        # number the successors by their first row
        n_flips = int(new.sum())
        first = np.full(n_flips, len(rows), np.int64)
        np.minimum.at(first, flip_of_row, np.arange(len(rows)))
        by_first = np.argsort(first, kind="stable")
        rank = np.empty(n_flips, np.int64)
        rank[by_first] = np.arange(n_flips)
        chosen = flips[pair_of_row.ravel()[first[by_first]]]  # each successor's (tuple, local flip)
        if self.words == 1:
            states = [state ^ f for f in chosen[:, 0].tolist()]
        else:
            raw, width = chosen.tobytes(), 8 * self.words
            states = [state ^ int.from_bytes(raw[i: i + width], "little") for i in range(0, len(raw), width)]
        return states, rank[flip_of_row]

    # ---- forward and backward --------------------------------------------------------------------
    def expand(self, state: int) -> Expansion:
        """The applicable ground actions of `state` and the states they lead to (cached per state)."""
        hit = self._cache.get(state)
        if hit is not None:
            return hit
        tuple_idx, rows = self._first.match(self._keys(state))
        if len(rows) == 0:
            hit = Expansion([], [], [], [], [], np.empty(0, np.int64))
        else:
            op = self.effect_op[rows]
            action = op * self.n_tuples + tuple_idx
            order = np.argsort(action, kind="stable")  # ground-action order; effects stay in order
            tuple_idx, rows, op, action = tuple_idx[order], rows[order], op[order], action[order]
            successors, succ = self._successors(state, tuple_idx, rows)
            # per successor, the events up to its first deterministic one
            det = self.deterministic[rows]
            first_det = np.full(len(successors), len(rows), dtype=np.int64)
            det_rows = np.flatnonzero(det)
            np.minimum.at(first_det, succ[det_rows], det_rows)
            keep = np.flatnonzero(np.arange(len(rows)) <= first_det[succ])
            hit = Expansion(successors, succ[keep].tolist(), np.where(det[keep], -1, op[keep]).tolist(),
                            self.effect_index[rows[keep]].tolist(), action[keep].tolist(), succ[keep])
        self._cache[state] = hit
        return hit

    def predecessors(self, state: int) -> list[int]:
        """Every other state from which some ground action, with any of its effects, leads to `state`."""
        tuple_idx, rows = self._post.match(self._keys(state))
        if len(rows) == 0:
            return []
        states, _ = self._successors(state, tuple_idx, rows)
        return [s for s in states if s != state]

    def applicable(self, state: int) -> list[GroundAction]:
        """Every ground action whose operator's precondition holds in `state`, in ground-action order."""
        tuple_idx, rows = self._all.match(self._keys(state))
        return sorted(set((self.effect_op[rows] * self.n_tuples + tuple_idx).tolist()))

    def clear_cache(self) -> None:
        """Forget the expansions cached per state."""
        self._cache.clear()

    @property
    def cached_states(self) -> int:
        return len(self._cache)

    # ---- ground actions --------------------------------------------------------------------------
    def operator(self, g: GroundAction) -> int:
        return g // self.n_tuples

    def binding(self, g: GroundAction) -> tuple[int, ...]:
        return self.tuples[g % self.n_tuples]

    def step(self, g: GroundAction) -> PlanStep:
        return self.ops.operators[self.operator(g)].name, tuple(object_name(o) for o in self.binding(g))

    def action(self, g: GroundAction) -> Action:
        return self.ops.operators[self.operator(g)].action(self.binding(g))



def _local_flips(effect, arity: int, n_unary: int) -> list[int]:
    """An effect's flipped bits in the local layout of an operator of `arity` (unary, then relations)."""
    return [i * n_unary + k for i, k in effect.unary_flips] + \
        [arity * n_unary + k * arity * arity + i * arity + j for k, i, j in effect.rel_flips]


def _flipped(bits: np.ndarray, local: list[int]) -> np.ndarray:
    out = bits.copy()
    out[local] ^= 1
    return out


def _key(bits: np.ndarray, group: int) -> int:
    return sum(int(b) << i for i, b in enumerate(bits.tolist())) * MAX_GROUPS + group
