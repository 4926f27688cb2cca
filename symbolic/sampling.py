"""Sampling N deterministic domains from the probabilistic operators (Alg. 1, line 6).

Domain k draws one effect per operator, independently across operators: operator o takes the effect
whose cumulative probability first exceeds u(seed, k, o), a uniform number computed by hashing
(seed, k, o) (splitmix64). Domain k is therefore the same whatever N is, no two (domain, operator)
pairs share a draw, and a draw costs nothing until an operator is used: the planner samples only the
operators its search meets, for all N domains at once (`DomainSet.masks`). The cumulative tables are
built once per operator set (`EffectSampler`), not per problem.

A set of N domains is represented either by its effect-choice matrix (N, n_operators), used to write
PDDL files and by the Fast Downward backends, or by bit masks (`DomainSet`): for an operator, one
Python int per effect whose bit k says that domain k chose it, so that one search serves every domain.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from guarded import atomic_write_text, dumps
from symbolic.pddl import DomainWriter, effect_probabilities
from symbolic.structs import OperatorSet

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def uniforms(seed: int, domains: np.ndarray, operators: np.ndarray) -> np.ndarray:
    """u(seed, k, o) in [0, 1) for every (domain k, operator o): array (len(domains), len(operators))."""
    with np.errstate(over="ignore"):
        x = (np.uint64(seed & 0xFFFFFFFFFFFFFFFF) * _GOLDEN
             + np.asarray(domains, np.uint64)[:, None] * np.uint64(0xD1B54A32D192ED03)
             + np.asarray(operators, np.uint64)[None, :] * np.uint64(0x8CB92BA72F3D8DD7))
        for _ in range(2):  # splitmix64's finaliser, twice: neighbouring (k, o) decorrelate fully
            x = x + _GOLDEN
            x = (x ^ (x >> np.uint64(30))) * _M1
            x = (x ^ (x >> np.uint64(27))) * _M2
            x = x ^ (x >> np.uint64(31))
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))


class EffectSampler:
    """Cumulative effect probabilities of an operator set, built once; draws effects for N domains."""

    def __init__(self, ops: OperatorSet, min_prob: float = 0.0):
        self.ops, self.min_prob = ops, min_prob
        width = max((len(op.effects) for op in ops.operators), default=1)
        self.n_effects = np.array([len(op.effects) for op in ops.operators], dtype=np.int64)
        self.cumulative = np.ones((len(ops), width))
        for i, op in enumerate(ops.operators):
            c = np.cumsum(effect_probabilities(op, min_prob))
            self.cumulative[i, : len(c)] = c
            self.cumulative[i, len(c) - 1:] = np.inf  # round-off guard: the last effect takes the rest
        self.probabilistic = np.flatnonzero(self.n_effects > 1)
        # every operator's inner cumulative bounds, shifted by 2 * operator into one sorted array: one
        # searchsorted draws the effects of any set of operators at once
        inner = [2.0 * i + self.cumulative[i, : n - 1] for i, n in enumerate(self.n_effects.tolist())]
        self._bounds = np.concatenate(inner) if inner else np.zeros(0)
        self._first_bound = np.searchsorted(self._bounds, 2.0 * np.arange(len(ops)), side="left")

    def choices(self, n_domains: int, seed: int, operators: np.ndarray | None = None) -> np.ndarray:
        """(n_domains, len(operators)) effect indices (all operators by default)."""
        if n_domains < 1:
            raise ValueError(f"n_domains must be >= 1, got {n_domains}")
        ops = np.arange(len(self.ops)) if operators is None else np.asarray(operators, np.int64)
        u = uniforms(seed, np.arange(n_domains), ops)  # (N, len(ops))
        return np.searchsorted(self._bounds, 2.0 * ops + u, side="right") - self._first_bound[ops]


def sample_choices(ops: OperatorSet, n_domains: int, seed: int = 0, min_prob: float = 0.0) -> np.ndarray:
    """(n_domains, n_operators) effect indices."""
    return EffectSampler(ops, min_prob).choices(n_domains, seed)


class DomainSet:
    """N deterministic domains as bit masks: bit k of `masks(o)[j]` says domain k uses effect j of o.

    Built from a sampler and a seed (effects drawn on first use, for all N domains at once) or from an
    explicit choice matrix (N, n_operators). `full` has every domain's bit: a deterministic operator's
    one effect is every domain's.
    """

    def __init__(self, n_effects: np.ndarray, n_domains: int, sampler: EffectSampler | None = None,
                 seed: int = 0, choices: np.ndarray | None = None):
        if n_domains < 1:
            raise ValueError(f"n_domains must be >= 1, got {n_domains}")
        self.n, self.n_effects = n_domains, n_effects
        self.full = (1 << n_domains) - 1
        self._sampler, self._seed, self._choices = sampler, seed, choices
        self.table: dict[int, tuple[int, ...]] = {}  # operator -> mask per effect (prepared ones)
        self.seconds = 0.0  # spent drawing effects

    @classmethod
    def sampled(cls, sampler: EffectSampler, n_domains: int, seed: int) -> "DomainSet":
        return cls(sampler.n_effects, n_domains, sampler=sampler, seed=seed)

    @classmethod
    def of_choices(cls, ops: OperatorSet, choices: np.ndarray) -> "DomainSet":
        choices = np.atleast_2d(np.asarray(choices, np.int64))
        if choices.shape[1] != len(ops):
            raise ValueError(f"a choice per operator is needed: {len(ops)}, got {choices.shape[1]}")
        n_effects = np.array([len(op.effects) for op in ops.operators], dtype=np.int64)
        if (choices < 0).any() or (choices >= n_effects[None]).any():
            raise ValueError("effect choices out of range")
        return cls(n_effects, len(choices), choices=choices)

    def prepare(self, operators) -> None:
        """Draw the effects of these operators (those not drawn yet; -1 ignored) for all N domains."""
        new = [o for o in dict.fromkeys(operators) if o >= 0 and o not in self.table]
        if not new:
            return
        start = time.perf_counter()
        if self._choices is not None:
            columns = self._choices[:, new]
        else:
            assert self._sampler is not None
            columns = self._sampler.choices(self.n, self._seed, np.array(new, np.int64))
        width = int(self.n_effects[new].max())
        chosen = columns[:, :, None] == np.arange(width)  # (N, ops, effects)
        packed = np.packbits(chosen, axis=0, bitorder="little").transpose(1, 2, 0)  # (ops, effects, bytes)
        size = packed.shape[2]
        raw = np.ascontiguousarray(packed).tobytes()
        for i, o in enumerate(new):
            base = i * width * size
            self.table[o] = tuple(int.from_bytes(raw[base + j * size: base + (j + 1) * size], "little")
                                  for j in range(int(self.n_effects[o])))
        self.seconds += time.perf_counter() - start

    def masks(self, operator: int) -> tuple[int, ...]:
        """Per effect of a (prepared or not) operator, the mask of the domains that use it."""
        hit = self.table.get(operator)
        if hit is None:
            self.prepare([operator])
            hit = self.table[operator]
        return hit


def dedup_choices(choices: np.ndarray, columns: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Identical domains (restricted to `columns` if given) merged, in order of first occurrence.

    Returns (index of the first domain of each group, group size, group of every domain).
    """
    view = choices if columns is None else choices[:, columns]
    first: dict[bytes, int] = {}
    group = np.empty(len(choices), np.int64)
    reps: list[int] = []
    for k, row in enumerate(np.ascontiguousarray(view)):
        key = row.tobytes()
        if key not in first:
            first[key] = len(reps)
            reps.append(k)
        group[k] = first[key]
    return np.array(reps, np.int64), np.bincount(group, minlength=len(reps)), group


def write_sampled_domains(ops: OperatorSet, out_dir: str | Path, n_domains: int, seed: int = 0,
                          min_prob: float = 0.0) -> list[tuple[Path, int]]:
    """Write the distinct sampled domains as domain_XXX.pddl plus sampled.json (multiplicities)."""
    out = Path(out_dir)
    choices = sample_choices(ops, n_domains, seed, min_prob)
    reps, counts, _ = dedup_choices(choices)
    writer = DomainWriter(ops)
    written = []
    for j, (k, c) in enumerate(zip(reps, counts)):
        path = out / f"domain_{j:03d}.pddl"
        atomic_write_text(path, writer.pddl(choices[k]))
        written.append((path, int(c)))
    atomic_write_text(out / "sampled.json", dumps({
        "n_domains": n_domains, "seed": seed, "min_prob": min_prob,
        "domains": [{"file": p.name, "count": c, "first_index": int(k)} for (p, c), k in zip(written, reps)],
    }, indent=1))
    return written
