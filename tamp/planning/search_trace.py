"""What a planning call considered and would otherwise drop, collected while it runs (opt-in).

    recorder = Recorder()
    with recording(recorder):
        result = plan("bilevel", models, X_init, X_goal, cfg)
    round = round_record(result, recorder, ...)   # tamp.planning.search_record

Inside `recording`, each continuous search keeps its tree (`Tree`: expansion order, duplicates dropped
per expansion, successors the kinematic check or a known refinement failure left out, the path found)
and Level 1's verifier keeps each checked candidate's Dynamics Model rollout and the kinematic verdict of
each of its actions. The active recorder is a context variable that each search and verifier reads
once, so the planners' signatures and the closed loop stay as they are; with none active they do no
more work than without this module. A recorder holds one planning call (a closed loop's round): the
last search's tree is the round's (a search again after a failed refinement, or a widened search,
replaces it; `searches` counts them); `reset` before the next round.
"""
from __future__ import annotations

from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Callable, Iterator, Sequence

import numpy as np


@dataclass
class Tree:
    """One continuous search as recorded. `nodes` is the search's own list of (positions (n, 3), parent
    index, action into it, g); a node's index is its id."""

    nodes: list
    goal: np.ndarray  # (n, 3) goal positions, metres
    heuristic: Callable[[np.ndarray, np.ndarray], np.ndarray]  # the search's h of (B, n, 3) states, their distances
    order: list[int] = field(default_factory=list)  # node ids in expansion order
    duplicates: dict[int, int] = field(default_factory=dict)  # expanded node id -> successors dropped as duplicates
    verdicts: dict[int, str] = field(default_factory=dict)  # node id -> why the kinematic check rejected it
    #   when it was taken from the frontier (its action, in its parent's predicted state)
    left_out: list[tuple[int, tuple, str, str, np.ndarray]] = field(default_factory=list)  # successors never
    #   made nodes: (parent id, action, verdict, reason, predicted positions (n, 3))
    path: list[int] = field(default_factory=list)  # solved: node ids from the root to the goal state
    closest: list[int] = field(default_factory=list)  # unsolved: to the expanded state closest to the goal
    generated: int = 0  # successors this search generated (the planning call's counters sum its searches)

    def expanded(self, index: int, duplicates: int) -> None:
        self.order.append(index)
        if duplicates:
            self.duplicates[index] = duplicates

    def end(self, index: int | None, closest: int, generated: int) -> None:
        """The search ended at goal node `index` (None: unsolved; `closest`: its closest expanded node)."""
        self.generated = generated
        ids = self.path if index is not None else self.closest
        at = index if index is not None else closest
        while at >= 0:
            ids.append(at)
            at = self.nodes[at][1]
        ids.reverse()


@dataclass
class Recorder:
    """What one planning call considered (see the module docstring)."""

    tree: Tree | None = None  # the last continuous search's
    searches: int = 0  # continuous searches the call ran

    def new_tree(self, nodes: list, goal: np.ndarray, heuristic: Callable[[np.ndarray, np.ndarray], np.ndarray]
                 ) -> Tree:
        self.searches += 1
        self.tree = Tree(nodes, goal, heuristic)
        return self.tree

    def reset(self) -> None:
        self.tree, self.searches = None, 0


_ACTIVE: ContextVar[Recorder | None] = ContextVar("tamp_search_recorder", default=None)


def active() -> Recorder | None:
    """The recorder of the planning call running now (None: not recording)."""
    return _ACTIVE.get()


@contextmanager
def recording(recorder: Recorder | None) -> Iterator[Recorder | None]:
    """Planning calls inside the block record into `recorder` (None: they do not)."""
    token = _ACTIVE.set(recorder)
    try:
        yield recorder
    finally:
        _ACTIVE.reset(token)


__all__: Sequence[str] = ["Recorder", "Tree", "active", "recording"]
