"""One breadth-first search for all N sampled domains (the fast Level-1 backend).

What it computes is the paper's "plan in each of the N domains" with a breadth-first search per
domain: for every domain, the first shortest plan in ground-action order (Fast Downward's optimal
configurations return plans of the same length). How it computes it is shared:

- **Domains as bit masks.** A search node carries the set of domains (an int, bit k = domain k) in
  which its state is first reached at its depth. Expanding it once serves all of them: a ground
  action's effect e of operator o leads to the successor in the domains `node & masks(o)[e]`, new
  only in those that have not reached the successor before. Nodes are expanded layer by layer, in
  the order each domain's own search would generate them, so every domain gets exactly its own plan
  (`tests/test_symbolic_search.py` checks this against N separate searches).
- **Distance bounds.** Distances to the goal in the all-outcomes domain (any effect of any operator)
  are lower bounds in every sampled domain. They are computed backwards from the goal by regression
  (`LiftedTask.predecessors`) up to a radius; beyond it R + 1 is a bound. Searching with a depth bound
  D, a state at depth g whose bound exceeds D - g is on no plan of length D and is not generated;
  D grows from 1 until every domain has its plan. Pruning keeps every state on every shortest plan,
  so the plans are those of the unbounded search.
- **Lifted successors.** States are expanded by `LiftedTask`, without grounding the task.

Budgets: `max_expansions` counts expanded states (forward nodes and backward states), a deterministic
measure; `deadline` (seconds, `time.perf_counter`) is a safety net. Domains without a plan when either
runs out are TIMEOUT; a domain whose bounded search was not cut anywhere has no plan (UNSOLVABLE).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from symbolic.lifted import GroundAction, LiftedTask
from symbolic.sampling import DomainSet
from symbolic.structs import PlannerStatus

INFINITE = 1 << 30


@dataclass
class SearchOutcome:
    """Per domain, its plan (index into `plans`, -1 for none) and status."""

    plans: list[tuple[GroundAction, ...]]
    states: list[tuple[int, ...]]  # packed states along each plan (len + 1)
    plan_of: list[int]
    status: list[PlannerStatus]
    expanded: int = 0  # forward nodes and backward states expanded
    depth: int = 0  # the last depth bound searched
    message: str = ""
    timings: dict[str, float] = field(default_factory=dict)  # seconds: forward, backward


class _Distances:
    """Exact distances to the goal in the all-outcomes domain up to `radius`; a lower bound beyond."""

    def __init__(self, task: LiftedTask, goal: int):
        self.task, self.dist, self.frontier = task, {goal: 0}, [goal]
        self.radius, self.complete = 0, False

    def grow(self, radius: int, budget: int) -> int:
        """Extend to `radius` (whole layers only, while `budget` expansions last); returns expansions."""
        used = 0
        while self.radius < radius and not self.complete and used + len(self.frontier) <= budget:
            layer, nxt = self.radius + 1, []
            for t in self.frontier:
                for s in self.task.predecessors(t):
                    if s not in self.dist:
                        self.dist[s] = layer
                        nxt.append(s)
            used += len(self.frontier)
            self.radius, self.frontier = layer, nxt
            self.complete = not nxt
        return used

    @property
    def beyond(self) -> int:
        """The bound of a state outside the distances computed so far."""
        return INFINITE if self.complete else self.radius + 1

    def bound(self, state: int) -> int:
        """A lower bound on the number of actions from `state` to the goal (INFINITE: unreachable)."""
        return self.dist.get(state, self.beyond)


def search_domains(task: LiftedTask, domains: DomainSet, init: int, goal: int, max_expansions: int = 200_000,
                   deadline: float | None = None, nonempty: bool = False) -> SearchOutcome:
    """For each of the domains, its first shortest plan from `init` to the full goal state `goal`.

    With `nonempty`, a goal equal to `init` needs a plan of at least one action (a shortest cycle).
    """
    N, full = domains.n, domains.full
    out = SearchOutcome([], [], [-1] * N, [PlannerStatus.TIMEOUT] * N)
    if init == goal and not nonempty:
        out.plans, out.states = [()], [(init,)]
        out.plan_of, out.status = [0] * N, [PlannerStatus.SOLVED] * N
        return out
    distances = _Distances(task, goal)
    active = full  # domains without a plan yet
    masks = domains.table  # operator -> domains per effect, filled by `prepare` for each new state
    t_back = 0.0
    D = 1
    while active:
        t = time.perf_counter()
        out.expanded += distances.grow(_radius(D), max_expansions - out.expanded)
        bounds_of: dict[int, np.ndarray] = {}  # per state, its successors' bounds at this radius
        t_back += time.perf_counter() - t
        if distances.bound(init) >= INFINITE:
            break  # the goal cannot be reached from init in any domain
        out.depth = D
        # forward, depth bound D; nodes are (state, domains, parent node, ground action)
        node_state, node_parent, node_action = [init], [-1], [-1]
        layer = [(0, active)]
        seen: dict[int, int] = {init: active}
        cut = 0  # domains in which some state was left out for the bound (not proven unsolvable)
        for depth in range(D):
            remaining = D - depth - 1  # actions left after the successor
            bounded = remaining <= distances.radius or distances.complete
            nxt: list[tuple[int, int]] = []
            for e, mask in layer:
                here = mask & active
                if not here:
                    continue
                if out.expanded >= max_expansions or (deadline is not None and out.expanded % 64 == 0
                                                      and time.perf_counter() > deadline):
                    out.message = f"search limit reached after {out.expanded} expansions (depth bound {D})"
                    out.timings.update(backward=t_back)
                    return out
                out.expanded += 1
                s = node_state[e]
                x = task.expand(s)
                events: range | list[int] = range(len(x.event_action))
                if bounded and x.successors:
                    bounds = bounds_of.get(s)
                    if bounds is None:
                        dist, beyond = distances.dist, distances.beyond
                        bounds = bounds_of[s] = np.array([dist.get(u, beyond) for u in x.successors])
                    allowed = bounds <= remaining
                    if not allowed.all():
                        if (~allowed & (bounds < INFINITE)).any():
                            cut |= here
                        events = np.flatnonzero(allowed[x.successor_of_event]).tolist()
                succ, ev_op, ev_eff, ev_act, ev_succ = (x.successors, x.event_op, x.event_effect,
                                                         x.event_action, x.event_successor)
                for i in events:
                    o = ev_op[i]
                    if o < 0:
                        m = here
                    else:
                        if o not in masks:  # draw effects only for the operators met, all N domains at once
                            domains.prepare([ev_op[i] for i in events])
                        m = here & masks[o][ev_eff[i]]
                    if not m:
                        continue
                    u = succ[ev_succ[i]]
                    if u == goal:  # tested before the duplicate check: the goal may be init (nonempty)
                        _solved(out, node_state, node_parent, node_action, e, ev_act[i], goal, m)
                        active &= ~m
                        here &= ~m
                        if not here:
                            break
                        continue
                    new = m & ~seen.get(u, 0)
                    if new:
                        seen[u] = seen.get(u, 0) | new
                        node_state.append(u)
                        node_parent.append(e)
                        node_action.append(ev_act[i])
                        nxt.append((len(node_state) - 1, new))
            layer = nxt
            if not layer:
                break
        unsolvable = active & ~cut
        for k in _bits(unsolvable):
            out.status[k] = PlannerStatus.UNSOLVABLE
        active &= ~unsolvable
        D += 1
    for k in _bits(active):
        out.status[k] = PlannerStatus.UNSOLVABLE  # the goal is unreachable from init
    out.timings.update(backward=t_back)
    return out


def _radius(depth_bound: int) -> int:
    """How far the backward distances reach for a depth bound D: D - 1 up to D = 3 (the forward
    search then expands only states on shortest plans: regression is cheaper per state than a
    forward expansion, which serves every domain), about D / 2 beyond (a backward layer grows with
    the branching factor, as a forward one)."""
    return depth_bound - 1 if depth_bound <= 3 else (depth_bound + 1) // 2


def _solved(out: SearchOutcome, node_state, node_parent, node_action, e: int, last: GroundAction,
            goal: int, domains: int) -> None:
    actions, states = [last], [goal]
    while e >= 0:
        states.append(node_state[e])
        if node_parent[e] >= 0:
            actions.append(node_action[e])
        e = node_parent[e]
    out.plans.append(tuple(actions[::-1]))
    out.states.append(tuple(states[::-1]))
    index = len(out.plans) - 1
    for k in _bits(domains):
        out.plan_of[k] = index
        out.status[k] = PlannerStatus.SOLVED


def _bits(mask: int) -> list[int]:
    out = []
    while mask:
        low = mask & -mask
        out.append(low.bit_length() - 1)
        mask ^= low
    return out
