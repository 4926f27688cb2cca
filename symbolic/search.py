"""In-process breadth-first search over a grounded task (the fast Level-1 backend).

Unit action costs, so BFS with the goal test at generation returns a shortest plan, the same length
as Fast Downward's optimal configurations (e.g. astar(lmcut())). Successors are generated in ground
action order, which makes the returned plan a deterministic function of the task and the effect
choice. The search records which operators it looked at (`touched`): any other domain that chooses
the same effects for those operators yields exactly the same search, so its result is reused.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from symbolic.grounding import GroundTask
from symbolic.structs import PlannerStatus


@dataclass
class SearchOutcome:
    status: PlannerStatus
    plan: list[int] | None  # ground action ids
    touched: np.ndarray  # operator ids whose effect choice the search depended on
    expanded: int
    message: str = ""


def bfs(task: GroundTask, choice: np.ndarray, init: int, goal: int,
        max_expansions: int = 200_000, time_limit: float | None = None,
        nonempty: bool = False) -> SearchOutcome:
    """Shortest plan from `init` to the full goal state `goal` with effect choice[op] per operator.

    With `nonempty`, a goal equal to `init` needs a plan of at least one action (a shortest cycle).
    """
    deadline = None if time_limit is None else time.perf_counter() + time_limit
    touched: set[int] = set()
    if init == goal and not nonempty:
        return SearchOutcome(PlannerStatus.SOLVED, [], np.empty(0, np.int64), 0)
    parent: dict[int, tuple[int, int] | None] = {init: None}
    frontier = deque([init])
    flips = task.flips
    ch = np.asarray(choice).tolist()
    expanded = 0
    while frontier:
        s = frontier.popleft()
        expanded += 1
        if expanded > max_expansions or (deadline is not None and expanded % 256 == 0
                                         and time.perf_counter() > deadline):
            return SearchOutcome(PlannerStatus.TIMEOUT, None, np.fromiter(touched, np.int64), expanded,
                                 f"search limit reached after {expanded} expansions")
        gs, opis = task.applicable(s)
        touched.update(opis)
        for g, oi in zip(gs, opis):
            t = s ^ flips[g][ch[oi]]
            if t == goal:  # tested before the duplicate check: the goal may be init (nonempty)
                plan, step = [g], parent[s]
                while step is not None:
                    u, g2 = step
                    plan.append(g2)
                    step = parent[u]
                return SearchOutcome(PlannerStatus.SOLVED, plan[::-1],
                                     np.array(sorted(touched), np.int64), expanded)
            if t in parent:
                continue
            parent[t] = (s, g)
            frontier.append(t)
    return SearchOutcome(PlannerStatus.UNSOLVABLE, None, np.array(sorted(touched), np.int64), expanded,
                         f"goal unreachable: {len(parent)} states explored")


def most_likely(task: GroundTask, choice: np.ndarray, init: int, goal: int, costs: list[list[float]],
                max_expansions: int = 200_000, time_limit: float | None = None,
                nonempty: bool = False) -> SearchOutcome:
    """The cheapest plan from `init` to `goal` (uniform-cost search), costs[op][effect] per action.

    With cost = 1 - log p(effect | operator) (`action_costs`), the plan is the most probable one
    per step taken: among plans that reach Sigma_goal in this domain it prefers operators that were
    seen to do what the plan needs, where breadth-first search takes whichever it generates first
    (e.g. a release offset that mostly lets the block fall). Ties go to the earlier-generated plan,
    so the result is a deterministic function of the task, the effect choice and the costs.
    """
    import heapq

    deadline = None if time_limit is None else time.perf_counter() + time_limit
    touched: set[int] = set()
    if init == goal and not nonempty:
        return SearchOutcome(PlannerStatus.SOLVED, [], np.empty(0, np.int64), 0)
    GOAL = -1  # the goal as a node of its own, so a nonempty plan back to init = goal can be found
    parent: dict[int, tuple[int, int] | None] = {init: None}
    best: dict[int, float] = {init: 0.0}
    heap: list[tuple[float, int, int, int, int]] = [(0.0, 0, init, -1, -1)]  # cost, tie, node, from, via
    flips = task.flips
    ch = np.asarray(choice).tolist()
    tie, expanded, closed = 1, 0, set()
    while heap:
        cost, _, node, s_from, g_via = heapq.heappop(heap)
        if node == GOAL:
            plan, step = [g_via], parent[s_from]
            while step is not None:
                u, g2 = step
                plan.append(g2)
                step = parent[u]
            return SearchOutcome(PlannerStatus.SOLVED, plan[::-1], np.array(sorted(touched), np.int64), expanded)
        if node in closed:
            continue
        closed.add(node)
        if s_from >= 0:
            parent[node] = (s_from, g_via)
        expanded += 1
        if expanded > max_expansions or (deadline is not None and expanded % 256 == 0
                                         and time.perf_counter() > deadline):
            return SearchOutcome(PlannerStatus.TIMEOUT, None, np.fromiter(touched, np.int64), expanded,
                                 f"search limit reached after {expanded} expansions")
        gs, opis = task.applicable(node)
        touched.update(opis)
        for g, oi in zip(gs, opis):
            e = ch[oi]
            t, c = node ^ flips[g][e], cost + costs[oi][e]
            key = GOAL if t == goal else t
            if key != GOAL and (t in closed or c >= best.get(t, np.inf)):
                continue
            if key == GOAL and c >= best.get(GOAL, np.inf):
                continue
            best[key] = c
            heapq.heappush(heap, (c, tie, key, node, g))
            tie += 1
    return SearchOutcome(PlannerStatus.UNSOLVABLE, None, np.array(sorted(touched), np.int64), expanded,
                         f"goal unreachable: {len(closed)} states explored")


def action_costs(probabilities: list[np.ndarray]) -> list[list[float]]:
    """costs[op][effect] = 1 - ln p(effect | op): one per step plus the step's surprisal."""
    return [[1.0 - float(np.log(p)) if p > 0 else np.inf for p in ps] for ps in probabilities]
