"""Steps beside the plan: from every state a practice round visited, the world runs other actions the planner
would consider there.

A round of `tamp practice` executes a few hundred steps; a model fitted to them learns those steps and little
else (the steps of the next round, on new problems, land as far from its prediction as before). Yet the
outcome of a step is, in the fast world, a function of the observed state (`bench/replay_steps.py`): the
misses are the model's, and more steps of the kind the planner takes teach it. Each visited state X (before
an executed action) with its problem's goal gives the goal-oriented actions of the continuous search
(`tamp.planning.pruning.goal_oriented_actions`: every misplaced block onto the objects nearest its goal and
onto itself, all offsets); up to `per_state` of them, drawn with a seed of the round, state and problem, are
run from X in the collection's world (blocks upright and axis-aligned, as X says; a state whose blocks would
then overlap, tilted ones, is left out). About 20 transitions per executed step, at the cost of a collected
one each, written in `tamp collect`'s format and world, so that they combine with the random data.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from tamp.errors import UserError
from tamp.records import atomic_write_text, made_by_tool, output_dir


@dataclass(frozen=True)
class StateTask:
    """One visited state: X (n, 5) and the actions to run from it."""
    index: int  # the task's place: the dataset is written in this order, whatever order the workers finish in
    X: np.ndarray
    actions: np.ndarray  # (m, 4) int64
    seed: int


def beside_actions(X: np.ndarray, X_goal: np.ndarray, taken: Sequence[int], per_state: int,
                   rng: np.random.Generator) -> np.ndarray:
    """Up to `per_state` goal-oriented actions from X other than the one `taken`, drawn without replacement."""
    from tamp.planning.pruning import goal_oriented_actions

    options = [a for a in goal_oriented_actions(X, X_goal).tolist() if tuple(a) != tuple(taken)]
    if not options:
        return np.zeros((0, 4), np.int64)
    pick = rng.choice(len(options), size=min(per_state, len(options)), replace=False)
    return np.asarray([options[i] for i in sorted(pick)], dtype=np.int64)


def state_tasks(rows: Sequence[dict], goals: dict[str, np.ndarray], per_state: int, seed: int) -> list[StateTask]:
    """One task per executed transition of the rows (its state before), with its problem's goal."""
    tasks: list[StateTask] = []
    for p, row in enumerate(sorted(rows, key=lambda r: r["problem"])):
        for k, t in enumerate(row.get("transitions") or []):
            X = np.asarray(t["X"], dtype=float)
            rng = np.random.default_rng([seed, p, k])
            actions = beside_actions(X, goals[row["problem"]], t["action"], per_state, rng)
            if len(actions):
                tasks.append(StateTask(len(tasks), X, actions, int(rng.integers(2**31 - 1))))
    return tasks


class StateWorker:
    """One worker's World of the collection's settings, kept for its lifetime."""

    def __init__(self) -> None:
        from tamp.sim import World, WorldConfig

        self.world = World(WorldConfig())

    def run(self, task: StateTask) -> tuple[int, list[dict[str, Any]]]:
        from tamp.app.collect import STATUS_CODES
        from tamp.sim.world_types import StepStatus

        world = self.world
        try:
            X = world.reset(X=task.X, seed=task.seed)
        except UserError:  # tilted or rotated blocks: X cannot be set up as it says
            return task.index, []
        scene, q = world.scene, world.q.copy()
        out = []
        for action in task.actions:
            world.set_scene(scene, q, motion_seed=task.seed)
            X_next, info = world.step(tuple(int(v) for v in action))
            out.append({"X": X, "action": [int(v) for v in action], "X_next": X_next,
                        "grasped": info.grasped if info.status == StepStatus.OK else -1,
                        "status": STATUS_CODES[info.status]})
        return task.index, out


def explore(rows_path: Path, problems_path: Path, directory: Path, per_state: int, seed: int, workers: int,
            backend: str = "local", progress: bool = True) -> int:
    """The steps beside the plans of the rows at `rows_path` as a dataset at `directory` (written once; a
    directory left half-written is written again); returns their number."""
    import shutil

    from tqdm import tqdm

    from learned.dataset import DatasetWriter, load_transitions
    from tamp.app.collect import STATUS_CODES
    from tamp.app.parallel import run_tasks
    from tamp.app.problem import read_problem_set
    from tamp.planning.validate import MAX_OBJECTS
    from tamp.sim import WorldConfig

    from .run import read_rows

    done = directory / ".complete"
    if done.is_file():
        return len(load_transitions(directory)) if any(directory.glob("shard-*.npz")) else 0
    if directory.exists():
        if not made_by_tool(directory):
            raise UserError(f"{directory}: an unfinished exploration in a folder the tool did not make; give "
                            "a new folder")
        shutil.rmtree(directory)  # an unfinished exploration of ours: made again from its rows
    goals = {str(p.name): p.X_goal for p in read_problem_set(problems_path)}
    tasks = state_tasks(read_rows(rows_path), goals, per_state, seed)
    results: dict[int, list[dict[str, Any]]] = {}
    with tqdm(total=len(tasks), desc="explore", unit="state", disable=not progress) as bar:
        for index, samples in run_tasks(tasks, StateWorker, (), workers=workers, backend=backend):
            results[index] = samples
            bar.update()
    samples = [s for index in sorted(results) for s in results[index]]
    with output_dir(directory, "the exploration folder"):  # marked: an unfinished one is ours to make again
        if samples:
            with DatasetWriter(directory, n_max=MAX_OBJECTS, world_config=WorldConfig().to_dict(), seed=seed,
                               status_codes=STATUS_CODES, shard_size=1000,
                               extra_meta={"collection": {"source": f"steps beside the plans of {rows_path}",
                                                          "per_state": per_state}}) as writer:
                for s in samples:
                    writer.add(s["X"], s["action"], s["X_next"], s["grasped"], s["status"])
        atomic_write_text(done, "")
    return len(samples)
