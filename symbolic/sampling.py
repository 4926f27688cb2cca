"""Sampling N deterministic domains from the probabilistic operators (Alg. 1, line 6).

Domain k draws one effect per operator, independently across operators, with its own generator
``np.random.default_rng([seed, k])``: domain k is the same whatever N is, and domains never share
random streams. A sampled domain is represented by its effect-choice vector (one index per operator).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from symbolic.pddl import DomainWriter, effect_probabilities
from symbolic.structs import OperatorSet


def sample_choices(ops: OperatorSet, n_domains: int, seed: int = 0, min_prob: float = 0.0) -> np.ndarray:
    """(n_domains, n_operators) effect indices."""
    if n_domains < 1:
        raise ValueError(f"n_domains must be >= 1, got {n_domains}")
    m = len(ops)
    width = max((len(op.effects) for op in ops.operators), default=1)
    cum = np.ones((m, width))
    for i, op in enumerate(ops.operators):
        c = np.cumsum(effect_probabilities(op, min_prob))
        cum[i, : len(c)] = c
        cum[i, len(c) - 1:] = np.inf  # guards against round-off: the last effect takes the rest
    choices = np.empty((n_domains, m), np.int64)
    for k in range(n_domains):
        u = np.random.default_rng([seed, k]).random(m)
        choices[k] = (u[:, None] >= cum).sum(axis=1)
    return choices


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
    out.mkdir(parents=True, exist_ok=True)
    choices = sample_choices(ops, n_domains, seed, min_prob)
    reps, counts, _ = dedup_choices(choices)
    writer = DomainWriter(ops)
    written = []
    for j, (k, c) in enumerate(zip(reps, counts)):
        path = out / f"domain_{j:03d}.pddl"
        path.write_text(writer.pddl(choices[k]))
        written.append((path, int(c)))
    (out / "sampled.json").write_text(json.dumps({
        "n_domains": n_domains, "seed": seed, "min_prob": min_prob,
        "domains": [{"file": p.name, "count": c, "first_index": int(k)} for (p, c), k in zip(written, reps)],
    }, indent=1))
    return written
