"""Top-level entry points used by the CLI: build a domain from bits, and load it again."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from guarded import atomic_write_text, dumps, make_dirs
from symbolic.atoms import check_bits
from symbolic.dataset import make_dataset, restrict_to_involved, split_dataset
from symbolic.lifted import max_arity as lifted_max_arity
from symbolic.operators import coverage, filter_operators, learn_operators, load_operators, save_operators, stats
from symbolic.pddl import write_domains
from symbolic.sampling import write_sampled_domains
from symbolic.structs import OperatorSet, SymbolicDataset, SymbolicProblem


def build_domain(unary_pre, rel_pre, actions, unary_post, rel_post, n_per_transition, out_dir,
                 holdout: float | SymbolicDataset = 0.1, seed: int = 0, min_prob: float = 0.0,
                 sampled_domains: int = 0, involved_only: bool = False, min_count: int = 0,
                 max_arity: int | None = None, core_from_all: bool = False,
                 general_bystanders: bool = False) -> dict:
    """Learn operators from symbolic transitions and write the domain files.

    Inputs: padded bit arrays unary (T, n_max, d_z), relations (T, K, n_max, n_max), actions (T, 4),
    n_per_transition (T,). holdout: fraction of transitions held out for coverage (seeded split), or
    an explicit held-out `SymbolicDataset`. Writes into out_dir: domain.pddl (most frequent effects),
    domain.ppddl, operators.json, stats.json, and with sampled_domains = N > 0 the distinct sampled
    PDDL domains in sampled/ (sampled.json has their multiplicities). Returns the statistics dict.
    With `involved_only`, operators mention only the objects a transition involves (picked, target,
    and those whose bits change; see `restrict_to_involved`, also for `core_from_all`) instead of every
    object in the scene.
    With `general_bystanders`, a transition that left its bystanders' own bits alone teaches a general
    operator, which does not test them (`symbolic.operators`).
    `min_count` and `min_prob` drop rare operators and rare effects (`filter_operators`).
    `max_arity` (default: the most the lifted search takes, `symbolic.lifted.max_arity`) leaves out the
    training transitions that involve more objects: no operator is learned from them, and held-out ones
    count as not covered.
    """
    data = make_dataset(unary_pre, rel_pre, actions, unary_post, rel_post, n_per_transition)
    if core_from_all and not involved_only:
        raise ValueError("core_from_all needs involved_only (it adds the picked and target objects' operators)")
    if involved_only:
        data = restrict_to_involved(data, core_from_all)
        if isinstance(holdout, SymbolicDataset):
            holdout = restrict_to_involved(holdout)
    held: SymbolicDataset | None
    if isinstance(holdout, SymbolicDataset):
        train, held = data, holdout
    else:
        train, held = split_dataset(data, float(holdout), seed)
    limit = lifted_max_arity(data.n_unary, data.n_relations, _constant_diagonal(data)) if max_arity is None \
        else max_arity
    if limit < 1:
        raise ValueError(f"max_arity must be at least 1, got {limit}")
    over = int((train.n > limit).sum())
    train = train.subset(np.flatnonzero(train.n <= limit))
    if len(train) == 0:
        raise ValueError(f"every training transition involves more than {limit} objects: raise max_arity")
    learned = learn_operators(train, general_bystanders)
    ops = filter_operators(learned, min_count, min_prob)
    if len(ops) == 0:
        raise ValueError(f"no operator was seen {min_count} times or more: lower min_count")
    out = Path(out_dir)
    make_dirs(out)
    paths = write_domains(ops, out)
    save_operators(ops, out / "operators.json")
    report = stats(ops)
    report["train_transitions"] = len(train)
    report["involved_only"] = involved_only
    report["core_from_all"] = core_from_all
    report["general_bystanders"] = general_bystanders
    report["n_general"] = sum(op.is_general for op in ops.operators)
    report["max_arity"] = {"limit": limit, "transitions_left_out": over}
    report["filters"] = {"min_count": min_count, "min_prob": min_prob, "operators_learned": len(learned),
                         "operators_kept": len(ops)}
    report["coverage_train"] = coverage(ops, train)
    report["coverage_holdout"] = coverage(ops, held) if held is not None and len(held) else None
    report["files"] = {k: p.name for k, p in paths.items()} | {"operators": "operators.json"}
    report["ppddl_bytes"] = paths["ppddl"].stat().st_size
    if sampled_domains > 0:
        written = write_sampled_domains(ops, out / "sampled", sampled_domains, seed)
        report["sampled_domains"] = {"n": sampled_domains, "distinct": len(written)}
    atomic_write_text(out / "stats.json", dumps(report, indent=1))
    return report


def _constant_diagonal(data: SymbolicDataset) -> bool:
    """The relations' diagonal r_k(i, i) is the same in every transition, before and after (pairwise
    relations set it always): the lifted search then leaves it out of its keys (`symbolic.lifted.max_arity`)."""
    real = np.arange(data.unary_pre.shape[1])[None, :] < data.n[:, None]  # (T, n_max)
    diagonal = np.concatenate([np.diagonal(data.rel_pre, axis1=2, axis2=3)[:, :, None],
                               np.diagonal(data.rel_post, axis1=2, axis2=3)[:, :, None]], axis=2)  # (T, K, 2, n_max)
    values = diagonal.transpose(0, 3, 1, 2)[real]  # (real objects, K, 2)
    return bool(len(values)) and bool(np.all(values == values[:1]))


def operators_file(domain_dir: str | Path) -> Path:
    """The operators file of a domain directory: operators.json, or operators.json.gz (bundled domains
    ship gzipped: a learned domain's JSON shrinks about 18 times); operators.json when neither exists."""
    plain = Path(domain_dir) / "operators.json"
    packed = plain.with_name(plain.name + ".gz")
    return packed if not plain.is_file() and packed.is_file() else plain


def load_domain(domain_dir: str | Path) -> OperatorSet:
    """Operators written by `build_domain` (`operators_file`)."""
    return load_operators(operators_file(domain_dir))


def make_problem(init_unary, init_rel, goal_unary, goal_rel, nonempty: bool = False,
                 movable: Sequence[int] | None = None) -> SymbolicProblem:
    """Sigma_init / Sigma_goal bits -> problem (shapes checked against each other); `nonempty` and
    `movable`: see SymbolicProblem."""
    iu, ir, gu, gr = (np.asarray(x) for x in (init_unary, init_rel, goal_unary, goal_rel))
    iu, ir = check_bits(iu, ir, "init")
    gu, gr = check_bits(gu, gr, "goal", iu.shape[1], ir.shape[0])
    if gu.shape != iu.shape:
        raise ValueError(f"goal has {gu.shape[0]} objects, init has {iu.shape[0]}")
    if movable is not None:
        movable = tuple(sorted({int(o) for o in movable}))
        if any(not 0 <= o < iu.shape[0] for o in movable):
            raise ValueError(f"movable objects {movable} are not all among the {iu.shape[0]} objects")
    return SymbolicProblem(iu, ir, gu, gr, nonempty, movable)
