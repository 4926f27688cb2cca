"""Problem sets: random Drake scenes and goals after k random actions, stored as JSONL.

Problem (n, k, i) of a set with seed s has its own scene seed, drawn from (s, n, k, i) alone
(`scene_seed`); from it `tamp.app.problem.random_problem` makes the scene and the k random actions
that give X_goal in the fast world. Two protocols (`tamp.app.problem.PROTOCOLS`): `strict` redraws
actions that fail or move no block, with a cap, so k counts real steps (a scene that gets stuck is
replaced by the next seed of that problem); `paper` keeps every drawn action whatever its outcome,
as the paper's authors do, and records how many of the k moved something. Any one problem can
therefore be regenerated on its own, and the same arguments give a byte-identical file, for any
number of workers.

Several runs (the paper reports mean +- std over ten): run j of a file is the set of seed s + j, its
problems named "r{j}-n{n}-k{k}-{i:03d}" and marked `"run": j`. Each line of the file is one
`tamp plan --problem` object with its name ("n{n}-k{k}-{i:03d}" for a single run), seed, k, the
actions that generated the goal, the protocol and the count of actions that moved something.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from tamp.app.problem import MAX_K, PROTOCOLS, Problem, StuckScene, random_problem
from tamp.app.problem import read_problem_set as read_problems  # noqa: F401 (the set reader, here by its old name)
from tamp.errors import UserError
from tamp.inputs import SEED_LIMIT
from tamp.planning.validate import MAX_OBJECTS
from tamp.records import atomic_write_text

MAX_ATTEMPTS = 10  # scenes drawn per problem before giving up (see `generate_problems`)


def scene_seed(seed: int, n: int, k: int, i: int, attempt: int = 0) -> int:
    """The seed of problem (n, k, i) of the set with `seed` (a 32-bit integer); `attempt` > 0 gives
    the seeds of the scenes drawn after one that got stuck."""
    key = [seed, n, k, i] + ([attempt] if attempt else [])
    return int(np.random.SeedSequence(key).generate_state(1)[0])


Cell = tuple[int, int, int, int, int | None, str]  # n, k, i, set seed, run (None: a single run), protocol


def _problem(n: int, k: int, i: int, seed: int, world, run: int | None = None,
             protocol: str = "strict") -> Problem:
    """Problem (n, k, i): the first of its scenes in which k random actions change something (a scene
    can get stuck, e.g. when every remaining action fails), so the set stays regenerable."""
    name = problem_name(n, k, i, run)
    for attempt in range(MAX_ATTEMPTS):
        try:
            problem = random_problem(n, k, scene_seed(seed, n, k, i, attempt), world=world, name=name,
                                     protocol=protocol)
            return problem if run is None else dataclasses.replace(problem, run=run)
        except StuckScene:
            continue
    raise UserError(f"problem {name}: no scene out of {MAX_ATTEMPTS} allowed {k} "
                       "scene-changing random actions")


def problem_name(n: int, k: int, i: int, run: int | None = None) -> str:
    return f"n{n}-k{k}-{i:03d}" if run is None else f"r{run}-n{n}-k{k}-{i:03d}"


_WORLD = None  # the World of a worker process


def _cell_problem(cell: Cell) -> Problem:
    global _WORLD
    if _WORLD is None:
        from tamp.sim import World, WorldConfig

        _WORLD = World(WorldConfig())
    n, k, i, seed, run, protocol = cell
    return _problem(n, k, i, seed, _WORLD, run, protocol)


def generate_problems(ns: Sequence[int] = (2, 3, 4), ks: Sequence[int] = (1, 2, 3, 4, 5), per_cell: int = 10,
                      seed: int = 0, progress: bool = True, protocol: str = "strict", runs: int = 1,
                      workers: int = 1) -> list[Problem]:
    """`per_cell` problems for every n in `ns` objects and every k in `ks` random actions, n-major,
    for each of `runs` sets (run j has seed `seed + j`), drawn under `protocol`. `workers` processes
    share the cells; the problems do not depend on how many."""
    from tqdm import tqdm

    ns, ks = _counts(ns, "--objects", 1, MAX_OBJECTS), _counts(ks, "--actions", 1, MAX_K)
    if per_cell < 1:
        raise UserError(f"--per-cell must be a positive integer, got {per_cell}")
    if runs < 1:
        raise UserError(f"--runs must be a positive integer, got {runs}")
    if not (0 <= seed and seed + runs - 1 < SEED_LIMIT):
        raise UserError(f"--seed must be in [0, 2^63 - runs], got {seed}")
    if protocol not in PROTOCOLS:
        raise UserError(f"--protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    cells: list[Cell] = [(n, k, i, seed + j, None if runs == 1 else j, protocol)
                         for j in range(runs) for n in ns for k in ks for i in range(per_cell)]
    bar = dict(total=len(cells), desc="problems", unit="problem", disable=not progress)
    if workers <= 1 or len(cells) == 1:
        return list(tqdm(map(_cell_problem, cells), **bar))
    import multiprocessing as mp

    with mp.get_context("spawn").Pool(min(workers, len(cells))) as pool:
        return list(tqdm(pool.imap(_cell_problem, cells, chunksize=1), **bar))


def _counts(values: Iterable[int], option: str, low: int, high: int | None) -> tuple[int, ...]:
    values = tuple(int(v) for v in values)
    if not values:
        raise UserError(f"{option} needs at least one value")
    bad = [v for v in values if v < low or (high is not None and v > high)]
    if bad:
        limit = f"{low}..{high}" if high is not None else f">= {low}"
        raise UserError(f"{option}: values must be {limit}, got {bad[0]}")
    if len(set(values)) != len(values):
        raise UserError(f"{option} lists a value twice: {','.join(map(str, values))}")
    return values


def write_problems(path: str | Path, problems: Sequence[Problem]) -> Path:
    """Write a problem set as JSONL (one `tamp plan --problem` object per line), atomically."""
    seen: set[str] = set()
    for p in problems:
        if p.name is None:
            raise UserError("every problem of a set needs a name")
        if p.name in seen:
            raise UserError(f"duplicate problem name {p.name!r}")
        seen.add(p.name)
    text = "".join(json.dumps(p.to_dict()) + "\n" for p in problems)
    return atomic_write_text(path, text)


