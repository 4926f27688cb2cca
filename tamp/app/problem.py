"""Planning problems and their file format.

A problem file is one JSON object (a problem set is one such object per line, JSONL):

    {"X_init": [[0.60, 0.15, 0.025, 1, 0], [0.70, -0.10, 0.025, 0, 1]],
     "X_goal": [[0.70, -0.10, 0.075, 1, 0], [0.70, -0.10, 0.025, 0, 1]],
     "k": 1, "seed": 7}

`X_init` and `X_goal` are (n, 5): x, y, z in metres and a one-hot type (small cube, large bar), the
same objects in the same order (types must agree). `k` (optional, positive integer) is the number of
actions that generated the goal (at most MAX_K); closed-loop replanning uses up to k - 1 rounds. `seed`
(optional, an integer in [0, 2^63), as every --seed) seeds the sampled symbolic domains. `name`
(optional string) names the problem within a set, `actions` (optional) are the actions that generated
the goal, each naming blocks of the scene. Generated problems also say how they were made: `protocol`
("strict" or "paper", see `PROTOCOLS`), `moved` (how many of the k actions moved a block) and `run`
(which of several problem sets of one file). Files are read by the guarded reader (`guarded`) and
checked against `PROBLEM` (a JSON Schema) before anything else; errors name the file (and line) and
the field. The scenes are then checked by `tamp.planning.validate.check_problem` (reach, resting, no
overlap).
`random_problem(n, k, seed)` makes one from a random scene and k random actions in the fast world.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from guarded import Schema, atomic_write_text, dumps, read_json, read_jsonl
from tamp.errors import UserError
from tamp.inputs import ACTION, SCENE, SEED, blocks_out_of_range
from tamp.planning.validate import check_problem

if TYPE_CHECKING:
    from tamp.sim.world import World

MOVED_M = 0.01  # metres: a goal-generating action counts when some block moved at least this far
# How the k goal-generating actions are drawn (uniformly among the 9 n^2 actions of the scene):
#   strict  an action that fails or moves no block by MOVED_M is redrawn, so every one of the k is real
#   paper   every drawn action is kept whatever its outcome, as the paper's authors do
#           (sym_learning scripts/test.py; about half of them move nothing in our world)
PROTOCOLS = ("strict", "paper")
MAX_K = 100  # goal-generating actions a problem may name (sets have 1..5)


@dataclass(frozen=True)
class Problem:
    X_init: np.ndarray  # (n, 5)
    X_goal: np.ndarray  # (n, 5)
    k: int | None = None  # actions used to generate X_goal, if known
    seed: int = 0
    name: str | None = None  # unique within a problem set
    actions: tuple[tuple[int, int, int, int], ...] = ()  # the actions that generated X_goal, if known
    protocol: str | None = None  # how the actions were drawn (PROTOCOLS), if generated
    moved: int | None = None  # how many of the k actions moved a block by MOVED_M, if known
    run: int | None = None  # which problem set of a file with several runs (0, 1, ...)

    @property
    def n(self) -> int:
        return int(self.X_init.shape[0])

    def to_dict(self) -> dict:
        d = {"X_init": np.round(self.X_init, 5).tolist(), "X_goal": np.round(self.X_goal, 5).tolist(),
             "seed": int(self.seed)}
        if self.k is not None:
            d["k"] = int(self.k)
        if self.name is not None:
            d = {"name": self.name, **d}
        if self.actions:
            d["actions"] = [list(a) for a in self.actions]
        for key in ("protocol", "moved", "run"):
            if getattr(self, key) is not None:
                d[key] = getattr(self, key)
        return d


PROBLEM = Schema({
    "type": "object", "required": ["X_init", "X_goal"], "additionalProperties": False,
    "properties": {"X_init": SCENE, "X_goal": SCENE, "k": {"type": "integer", "minimum": 1, "maximum": MAX_K},
                   "seed": SEED, "name": {"type": "string", "maxLength": 200},
                   "actions": {"type": "array", "maxItems": MAX_K, "items": ACTION},
                   "protocol": {"enum": list(PROTOCOLS)}, "moved": {"type": "integer", "minimum": 0},
                   "run": {"type": "integer", "minimum": 0}}})


def _state(data: dict, field: str, where: str) -> np.ndarray:
    X = np.array(data[field], dtype=float)
    if not np.all(np.isfinite(X)):  # (a file's numbers are finite; a dict from Python may hold nan)
        raise UserError(f"{where}: field '{field}' contains a non-finite number")
    onehot = X[:, 3:]
    bad = np.flatnonzero(~(np.isin(onehot, (0.0, 1.0)).all(axis=1) & (onehot.sum(axis=1) == 1)))
    if bad.size:
        raise UserError(f"{where}: field '{field}' row {bad[0]}: the type must be one-hot "
                         f"[1, 0] (small) or [0, 1] (large), got {onehot[bad[0]].tolist()}")
    return X


def problem_from_dict(data: object, where: str = "problem") -> Problem:
    """Check a parsed problem object (the schema, then the scenes); UserError naming `where` and the field."""
    PROBLEM.check(data, where)
    assert isinstance(data, dict)
    X_init, X_goal = _state(data, "X_init", where), _state(data, "X_goal", where)
    if X_goal.shape != X_init.shape:
        raise UserError(f"{where}: field 'X_goal' has {len(X_goal)} objects, 'X_init' has {len(X_init)}")
    differs = np.flatnonzero(np.any(X_goal[:, 3:] != X_init[:, 3:], axis=1))
    if differs.size:
        raise UserError(f"{where}: field 'X_goal' row {differs[0]} has another block type than in 'X_init'")
    k, moved, actions, n = data.get("k"), data.get("moved"), data.get("actions", []), len(X_init)
    if (bad := blocks_out_of_range(actions, n)) is not None:
        raise UserError(f"{where}: actions[{bad}]: {actions[bad]} names a block beyond the scene's {n} (0..{n - 1})")
    if moved is not None and k is not None and moved > k:
        raise UserError(f"{where}: field 'moved' is {moved}, more than the k = {k} actions")
    check_problem(X_init, X_goal, where)
    return Problem(X_init, X_goal, k, data.get("seed", 0), data.get("name"), tuple(tuple(a) for a in actions),
                   data.get("protocol"), moved, data.get("run"))


def load_problem(path: str | Path) -> Problem:
    """Read one problem file (JSON, through the guarded reader)."""
    return problem_from_dict(read_json(path, "problem file"), str(path))


def pick_problem(path: str | Path, name: str | None = None) -> Problem:
    """One problem: a problem file, or the problem `name` of a problem set (JSON Lines, `tamp problems`; a set of
    one problem needs no name). Errors name the file and, for a set without a name, its first problems."""
    path = Path(path)
    if name is None:
        try:
            return load_problem(path)
        except ValueError as single:  # not one problem (a UserError or the reader's InputError): a set, perhaps
            try:
                problems = read_problem_set(path)
            except ValueError:
                if ".jsonl" in path.suffixes:  # meant as a set: its own fault (a line, a duplicate name) says more
                    raise
                raise single from None
    else:
        problems = read_problem_set(path)
    if name is None:
        if len(problems) == 1:
            return problems[0]
        shown = ", ".join(str(p.name) for p in problems[:3])
        raise UserError(f"{path} is a problem set of {len(problems)} problems: pick one with --name (e.g. {shown})")
    for problem in problems:
        if problem.name == name:
            return problem
    raise UserError(f"{path}: no problem named {name!r} among its {len(problems)} (e.g. {problems[0].name})")


def save_problem(path: str | Path, problem: Problem) -> None:
    """Write `problem` as a problem file, atomically."""
    atomic_write_text(path, dumps(problem.to_dict()) + "\n")


def read_problem_set(path: str | Path) -> list[Problem]:
    """Read a problem set; errors name the file, the line and the field. Names must be unique."""
    path = Path(path)
    lines = read_jsonl(path, "problem set")
    problems: list[Problem] = []
    first_line: dict[str, int] = {}
    for number, data in lines.values:
        where = f"{path} line {number}"
        problem = problem_from_dict(data, where)
        if problem.name is None:
            raise UserError(f"{where}: missing field 'name' (every problem of a set is named)")
        if problem.name in first_line:
            raise UserError(f"{where}: duplicate problem name {problem.name!r} (also on line "
                             f"{first_line[problem.name]})")
        first_line[problem.name] = number
        problems.append(problem)
    if not problems:
        raise UserError(f"{path}: no problems in the file")
    return problems


class StuckScene(UserError):
    """A random scene in which too few random actions change anything (e.g. every one fails)."""


def random_problem(n: int, k: int, seed: int, world: "World | None" = None, name: str | None = None,
                   max_tries: int = 200, protocol: str = "strict") -> Problem:
    """A random scene of n blocks and the goal after k random actions (see `PROTOCOLS`).

    Everything depends on `seed` alone (the scene, the drawn actions and their simulated outcomes in
    the fast world), so any one problem of a set can be regenerated on its own. Under the `strict`
    protocol actions that fail or move no block by `MOVED_M` are redrawn (at most `max_tries` draws,
    else RuntimeError), so k counts real steps; under `paper` the first k draws are kept whatever
    they do. `seed` also seeds the sampled symbolic domains when the problem is planned.
    """
    from tamp.sim.world import World
    from tamp.sim.world_types import WorldConfig

    if n < 1 or k < 1:
        raise UserError(f"a random problem needs n >= 1 objects and k >= 1 actions, got n={n}, k={k}")
    if protocol not in PROTOCOLS:
        raise UserError(f"protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    world = world or World(WorldConfig())
    X_init = world.reset(n_objects=n, seed=seed)
    rng = np.random.default_rng([seed, 1])  # the actions' stream, apart from the scene's
    kept: list[tuple[int, int, int, int]] = []
    moved = 0
    for _ in range(max_tries if protocol == "strict" else k):
        if len(kept) == k:
            break
        X = world.X
        candidates = world.actions()
        pick, grasp_offset, place, release_offset = (int(v) for v in candidates[rng.integers(len(candidates))])
        action = (pick, grasp_offset, place, release_offset)
        X_next, info = world.step(action)
        changed = info.status == "ok" and np.max(np.linalg.norm(X_next[:, :3] - X[:, :3], axis=1)) >= MOVED_M
        if changed or protocol == "paper":
            kept.append(action)
            moved += int(changed)
    if len(kept) < k:
        raise StuckScene(f"seed {seed}: only {len(kept)} of {k} random actions changed the scene "
                         f"in {max_tries} draws; try another seed")
    return Problem(X_init, world.X, k, seed, name, tuple(kept), protocol, moved)
