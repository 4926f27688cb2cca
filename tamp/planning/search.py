"""Continuous Forward Search (paper, Level 2): weighted A* in the continuous state space.

A node is (X, g, plan); f = g + w h(X) with g = number of actions, w = 1.5 and
h(X) = sum_i ||pos_i(X) - pos_i(X_goal)||_2 in metres (the paper's formula). From `greedy_from` blocks
on (our extension) h counts in units of `GREEDY_H_UNIT_M` (0.5 m), so that an action weighs less against
the distance still to go, plus `GREEDY_PER_MISPLACED` (0.3) per block still off its goal in 2-D. The
Dynamics Model is the transition, X' = X + e_hat; all successors of one expansion are predicted in one
batched `predict_effect` call.

Goal-oriented action pruning (paper, with our targets): `tamp.planning.pruning`.

Goal test at generation: every object within `eps` (5 cm) of its goal in 3-D. A goal state whose
worst object is predicted farther than `confident` (3.5 cm; both `VerifyConfig`'s, as is `misplaced`,
what counts as the goal for every stage) is kept as a candidate while the search
looks on, for at most `look_on` more expansions, for one within `confident` reached with no more
actions; then the closest candidate is returned (our extension: the Dynamics Model's plans predicted
to end 4-5 cm from the goal failed in execution about as often as they succeeded). With an ensemble
Dynamics Model (`max_doubt`, our extension), a goal state whose plan has a step that may miss by more
than `max_doubt` (its 95 % bound, `verify.doubt`) is a candidate too, ranked after every goal state
without such a step.

Duplicate detection:
positions rounded to a `resolution` grid; a state is pushed again only when reached with fewer
actions. Limits: expansions, wall-clock time and plan depth; the result says which one ended it.

Stagnation (our extension): a search whose closest expanded state (least h) has not come closer to the goal
for `stall` expansions ends, counted in expansions so that the cut never depends on the machine's load.
Searches that end without a plan stop improving early and spend most of their budget on a plateau. Below
`greedy_from` blocks, where h counts in metres, most searches that find a plan plateau for a few hundred
expansions, but not all, so `stall` is off unless set; the closed loop's rounds use it (`LoopConfig.stall`),
since a round that fails has a widened search and the next round behind it. From `greedy_from` blocks on,
where h is greedier, `greedy_stall` (800) takes its place: there a search finds its plan soon after its
last progress or not at all (docs/beyond-the-paper.md).
"""
from __future__ import annotations

import heapq
import time
from collections import Counter
from dataclasses import dataclass, field
from enum import StrEnum
from typing import AbstractSet, Callable, Hashable

import numpy as np

from tamp.errors import UserError
from tamp.planning.pruning import all_actions, goal_oriented_actions
from tamp.planning.search_trace import active
from tamp.planning.verify import DynamicsModel, VerifyConfig, doubt, states_pair

WEIGHT = 1.5  # w in f = g + w h (the paper's)
GREEDY_H_UNIT_M = 0.5  # metres per unit of h from greedy_from blocks on: the distance to go weighs twice
GREEDY_PER_MISPLACED = 0.3  # units of h per block off its goal (2-D), from greedy_from blocks on


@dataclass(frozen=True)
class SearchConfig:
    """Level 2's own settings; what counts as the goal (eps, confident, misplaced) is `VerifyConfig`'s."""

    greedy_from: int | None = 5  # from this many blocks on, h in half metres and per block off its goal: deeper
    resolution: float = 0.02  # metres: duplicate-detection grid (the Dynamics Model is good to about 1 cm)
    max_expansions: int = 1500  # node budget: it decides, so a result does not depend on the machine's load
    time_limit: float | None = None  # seconds of wall clock per planning call (off: budgets decide, load-free)
    max_depth: int = 10  # longest plan considered
    stall: int | None = None  # below greedy_from blocks, expansions without progress before the search ends
    greedy_stall: int | None = 800  # from greedy_from blocks on, the stall cut: there a plan comes soon or never
    look_on: int = 30  # expansions spent looking for a confident goal state after a less confident one
    release_targets: bool = True  # also target the closest release point and the block below a raised goal
    max_doubt: float | None = None  # metres: an ensemble's 95 % step bound a plan taken at once may not exceed

    def __post_init__(self) -> None:
        for name in ("stall", "greedy_stall"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise UserError(f"the continuous search's {name} must be a positive number of expansions (or None), "
                                f"got {getattr(self, name)}")
        if self.time_limit is not None and not self.time_limit > 0 or self.max_expansions < 1 or self.max_depth < 1:
            raise UserError(f"the continuous search needs a positive time limit, node limit and depth, got "
                            f"{self.time_limit} s, {self.max_expansions} nodes, depth {self.max_depth}")
        if self.max_doubt is not None and not self.max_doubt > 0:
            raise UserError(f"the continuous search's max_doubt must be a positive distance (or None), got "
                            f"{self.max_doubt} m")
        if self.greedy_from is not None and self.greedy_from < 1:
            raise UserError(f"the continuous search's greedy_from must be at least 1 block (or None), got "
                            f"{self.greedy_from}")
        if self.look_on < 0:
            raise UserError(f"the continuous search needs look_on >= 0, got {self.look_on}")
        if not 0 < self.resolution <= 0.05:
            raise UserError(f"the continuous search's duplicate grid must be more than 0 and at most 5 cm, got "
                            f"{self.resolution} m")


class SearchStatus(StrEnum):
    """How a continuous search ended."""

    SOLVED = "solved"
    EXHAUSTED = "exhausted"  # every state within max_depth actions was expanded
    NODE_LIMIT = "node_limit"
    STALLED = "stalled"  # no state closer to the goal for `stall` expansions
    TIME_LIMIT = "time_limit"
    REFINEMENT_BUDGET = "refinement_budget"  # its plans kept failing refinement (bilevel with kinematics)


@dataclass
class SearchResult:
    status: SearchStatus
    plan: list[tuple[int, int, int, int]] | None
    trajectory: np.ndarray | None  # (len(plan) + 1, n, 5) predicted states along the plan
    reason: str
    expanded: int = 0
    generated: int = 0
    duplicates: int = 0
    predict_calls: int = 0  # Dynamics Model calls for successors
    # metres: smallest max-object goal distance among generated states, a goal state once its last action passed the
    #   kinematic check (the rejected ones: `goals_rejected`)
    best_error: float = float("inf")
    time: float = 0.0  # seconds
    rejected: Counter = field(default_factory=Counter)  # reason -> successors the feasibility check pruned
    pruned: int = 0  # successors left out as (state, action) pairs known to fail refinement
    ungraspable: int = 0  # actions left out before their prediction: the jaws cannot hold the block there (`graspable`)
    # goal states generated whose last action the kinematic check rejected (the model's way to the goal is blocked:
    #   a lift into a neighbour, a block resting on the one picked), and the closest of them (metres)
    goals_rejected: int = 0
    rejected_goal_error: float = float("inf")
    # unsolved: the path to the expanded state closest to the goal (least h), if closer than X_init; a closed
    # loop may take its first action to make progress from where the world is (`closed_loop.widened_search`)
    closest_plan: list[tuple[int, int, int, int]] | None = None
    closest_trajectory: np.ndarray | None = None


    @property
    def solved(self) -> bool:
        return self.status == SearchStatus.SOLVED


# feasible(X, action) -> None if the action is feasible in the predicted scene X, else why not (a reason)
FeasibilityFn = Callable[[np.ndarray, tuple[int, int, int, int]], Hashable | None]


def predict_positions(model: DynamicsModel, X: np.ndarray, actions: np.ndarray, batched: bool = True
                      ) -> tuple[np.ndarray, int]:
    """Successor positions (B, n, 3) and the number of predict_effect calls made."""
    if batched:
        return X[None, :, :3] + model.predict_effect(X, actions), 1
    e = [model.predict_effect(X, actions[b:b + 1])[0] for b in range(len(actions))]
    return X[None, :, :3] + np.array(e).reshape(len(actions), len(X), 3), len(actions)


def goal_states(count: int) -> str:
    """"1 goal state", "2 goal states": a count of goal states in words."""
    return f"{count} goal state{'s' if count != 1 else ''}"


def state_key(P: np.ndarray, resolution: float) -> bytes:
    """Duplicate-detection key of positions P (n, 3): the grid cell of every coordinate."""
    return np.round(np.asarray(P)[:, :3] / resolution).astype(np.int64).tobytes()


Node = tuple[np.ndarray, int, "tuple | None", int]  # (positions (n, 3), parent index, action into it, g)


class ContinuousSearch:
    """Weighted A* from X_init to X_goal with the Dynamics Model as the transition; `run` returns its result.

    `feasible` (optional, e.g. the kinematic check of tamp.sim.kinematic_checker) prunes successors whose action
    is infeasible in its parent's predicted state. It is called lazily, when a successor is expanded
    or reaches the goal, so only the edges the search actually follows are checked (a few per
    expansion instead of every generated successor). `pruned` holds (state_key(X), action) pairs left
    out altogether (e.g. known to fail refinement). `graspable` ((n, 3) bool per object and grasp offset
    -1, 0, +1; `KinematicFeasibility.graspable`) leaves out, before they are predicted, the actions whose
    grasp can never hold the picked block (a cube grasped off its centre): `feasible` would reject every
    one of them. `config.time_limit` counts from `started` (time.perf_counter() when the planning call
    began; default: now). `every_action`: all 9 n^2 actions instead of the goal-oriented ones (a closed loop's
    widened search); `batched`: one predict_effect call per expansion (False: one per action, the benchmark's
    baseline)."""

    def __init__(self, model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray,
                 config: SearchConfig = SearchConfig(), goal: VerifyConfig = VerifyConfig(),
                 feasible: FeasibilityFn | None = None, pruned: AbstractSet[tuple[bytes, tuple]] = frozenset(),
                 started: float | None = None, graspable: np.ndarray | None = None, every_action: bool = False,
                 batched: bool = True):
        self.t0 = time.perf_counter()
        self.every_action, self.batched = every_action, batched
        self.model, self.config, self.tolerance, self.feasible = model, config, goal, feasible
        self.pruned, self.graspable = pruned, graspable
        self.deadline = float("inf") if config.time_limit is None else \
            (self.t0 if started is None else started) + config.time_limit
        self.X_init, self.X_goal = states_pair(X_init, X_goal)
        self.goal = self.X_goal[:, :3]
        self.types = self.X_init[:, 3:]
        self.nodes: list[Node] = [(self.X_init[:, :3].copy(), -1, None, 0)]
        self.d0 = np.linalg.norm(self.X_init[:, :3] - self.goal, axis=1)
        self.out = SearchResult(SearchStatus.EXHAUSTED, None, None, "", best_error=float(self.d0.max(initial=0.0)))
        self.best_g = {self.key(self.X_init[:, :3]): 0}
        # (doubtful, worst object's predicted error, node): the best goal state that did not end the search
        self.candidate: tuple[bool, float, int] | None = None
        self.look_until = config.max_expansions  # expansions after which the candidate is returned
        greedy = config.greedy_from is not None and len(self.X_init) >= config.greedy_from
        self.h_unit = GREEDY_H_UNIT_M if greedy else 1.0  # metres per unit of h
        self.per_misplaced = GREEDY_PER_MISPLACED if greedy else 0.0
        self.stall = config.greedy_stall if greedy else config.stall
        h0 = float(self.heuristic(self.X_init[None, :, :3], self.d0[None])[0])
        self.frontier = [(WEIGHT * h0, h0, 0)]  # (f, h, node index)
        self.closest = (h0, 0)  # (h, node index) of the expanded state closest to the goal
        self.closer_at = 0  # expansions when the closest state last came closer
        self.every = all_actions(len(self.X_init))
        recorder = active()  # the search record's (`tamp.planning.search_trace`); None: not recording
        self.tree = None if recorder is None else recorder.new_tree(self.nodes, self.goal, self.heuristic)

    # --- states, keys, paths --------------------------------------------------------------------
    def full(self, P: np.ndarray) -> np.ndarray:
        return np.concatenate([P, self.types], axis=1)

    def key(self, P: np.ndarray) -> bytes:
        return state_key(P, self.config.resolution)

    def keys_of(self, Ps: np.ndarray) -> list[bytes]:
        """key() of each of the (B, n, 3) states, in one vectorized rounding."""
        grid = np.ascontiguousarray(np.round(Ps / self.config.resolution).astype(np.int64).reshape(len(Ps), -1))
        return [row.tobytes() for row in grid]

    def path(self, index: int) -> tuple[list[tuple], list[np.ndarray]]:
        """The actions and the states from X_init to node `index`."""
        plan, states = [], []
        while index >= 0:
            P, parent, action, _ = self.nodes[index]
            states.append(self.full(P))
            if action is not None:
                plan.append(action)
            index = parent
        return plan[::-1], states[::-1]

    def heuristic(self, Ps: np.ndarray, dist: np.ndarray) -> np.ndarray:
        """h of the (B, n, 3) states whose (B, n) distances to the goal are `dist`."""
        h = dist.sum(axis=1) / self.h_unit
        if self.per_misplaced:
            off = np.linalg.norm(Ps[:, :, :2] - self.goal[None, :, :2], axis=2) > self.tolerance.misplaced
            h = h + self.per_misplaced * off.sum(1)
        return h

    # --- the checks on a node -------------------------------------------------------------------
    def infeasible(self, index: int) -> Hashable | None:
        """Why the action into node `index` fails the check in its parent's state (counted); None: it passes."""
        _, parent, action, _ = self.nodes[index]
        if self.feasible is None or action is None:
            return None
        reason = self.feasible(self.full(self.nodes[parent][0]), action)
        if reason is not None:
            self.out.rejected[reason] += 1
        return reason

    def doubtful(self, index: int) -> bool:
        """Whether a step of the plan into node `index` may miss by more than config.max_doubt (`verify.doubt`)."""
        if self.config.max_doubt is None:
            return False
        plan, states = self.path(index)
        return doubt(self.model, np.stack(states), plan) > self.config.max_doubt

    # --- ending ---------------------------------------------------------------------------------
    def finish(self, status: SearchStatus, reason: str, index: int | None = None) -> SearchResult:
        out = self.out
        out.status, out.reason, out.time = status, reason, time.perf_counter() - self.t0
        if index is not None:
            plan, states = self.path(index)
            out.plan, out.trajectory = plan, np.stack(states)
        elif self.closest[1] > 0:
            plan, states = self.path(self.closest[1])
            out.closest_plan, out.closest_trajectory = plan, np.stack(states)
        if self.tree is not None:
            self.tree.end(index, self.closest[1], out.generated)
        return out

    def stop(self, status: SearchStatus, reason: str) -> SearchResult:
        """End at a limit: the candidate goal state if there is one."""
        if self.candidate is None:
            return self.finish(status, reason)
        unsure, error, index = self.candidate
        cfg, expanded, actions = self.config, self.out.expanded, self.nodes[index][3]
        if unsure:
            limit = (cfg.max_doubt or 0.0) * 100
            return self.finish(SearchStatus.SOLVED, f"solved: {actions} actions, predicted {error * 100:.1f} cm "
                               f"from the goal, a step's 95 % bound over {limit:g} cm (no goal state without one "
                               f"after {expanded} expansions)", index)
        confident = self.tolerance.confident * 100
        return self.finish(SearchStatus.SOLVED, f"solved: {actions} actions, predicted {error * 100:.1f} cm "
                           f"from the goal (no goal state within {confident:g} cm after {expanded} expansions)", index)

    def closest_words(self) -> str:
        """How close the search came, for an unsolved search's reason."""
        out = self.out
        words = f"closest predicted state {out.best_error * 100:.1f} cm from the goal"
        if out.goals_rejected:
            words += (f"; {goal_states(out.goals_rejected)} reached only by actions the kinematic check rejects, the "
                      f"closest {out.rejected_goal_error * 100:.1f} cm")
        return words

    def limit_reached(self) -> SearchResult | None:
        """The result when a limit ends the search before the next expansion (None: go on)."""
        out, cfg = self.out, self.config
        if self.candidate is not None and out.expanded >= self.look_until:
            return self.stop(SearchStatus.SOLVED, "")
        closest = self.closest_words()
        if out.expanded >= cfg.max_expansions:
            return self.stop(SearchStatus.NODE_LIMIT, f"node limit: {out.expanded} expansions without reaching the "
                             f"goal ({closest})")
        if self.stall is not None and out.expanded - self.closer_at >= self.stall:
            return self.stop(SearchStatus.STALLED, f"stalled: no state closer to the goal in {self.stall} expansions "
                             f"({out.expanded} in all; {closest})")
        if time.perf_counter() > self.deadline:
            return self.stop(SearchStatus.TIME_LIMIT, f"time limit: {cfg.time_limit:g} s ({out.expanded} "
                             f"expansions) without reaching the goal ({closest})")
        return None

    # --- the search -----------------------------------------------------------------------------
    def run(self) -> SearchResult:
        if np.all(self.d0 < self.tolerance.eps):
            return self.finish(SearchStatus.SOLVED, "the initial state is already within eps of the goal", 0)
        while self.frontier:
            ended = self.limit_reached()
            if ended is not None:
                return ended
            _, h_here, index = heapq.heappop(self.frontier)
            P, _, _, g = self.nodes[index]
            if self.best_g.get(self.key(P), -1) < g or g >= self.config.max_depth:
                continue  # reached again with fewer actions since it was pushed / too deep
            why = self.infeasible(index)
            if why is not None:
                del self.best_g[self.key(P)]  # the state may still be reached by a feasible action
                if self.tree is not None:
                    self.tree.verdicts[index] = str(why)
                continue
            self.out.expanded += 1
            if h_here < self.closest[0]:
                self.closest, self.closer_at = (h_here, index), self.out.expanded
            duplicates = self.out.duplicates
            solved = self.expand(index)
            if self.tree is not None:
                self.tree.expanded(index, self.out.duplicates - duplicates)
            if solved is not None:
                return solved
        cfg, out = self.config, self.out
        offered = "all actions" if self.every_action else "goal-oriented actions"
        return self.stop(SearchStatus.EXHAUSTED, f"exhausted: every state reachable within {cfg.max_depth} actions "
                         f"({offered}, {cfg.resolution * 100:g} cm grid) expanded, {out.expanded} expansions; "
                         f"{self.closest_words()}")

    def actions(self, P: np.ndarray) -> np.ndarray:
        """The actions from positions P: goal-oriented (or all) and, with `graspable`, only grasps that hold."""
        tol = self.tolerance
        actions = self.every if self.every_action else goal_oriented_actions(
            self.full(P), self.X_goal, tol.misplaced, tol.eps, self.config.release_targets)
        return self.holding(actions)

    def holding(self, actions: np.ndarray) -> np.ndarray:
        """`actions` without those whose grasp cannot hold the block (with `graspable`)."""
        if self.graspable is None:
            return actions
        holds = self.graspable[actions[:, 0], actions[:, 1] + 1]
        self.out.ungraspable += len(actions) - int(holds.sum())
        return actions[holds]

    def expand(self, index: int) -> SearchResult | None:
        """Generate node `index`'s successors in one batched prediction; the result if one ends the search."""
        out, cfg = self.out, self.config
        P, _, _, g = self.nodes[index]
        actions = self.actions(P)
        if len(actions) == 0:
            return None
        succ, calls = predict_positions(self.model, self.full(P), actions, self.batched)
        out.predict_calls += calls
        out.generated += len(actions)
        dist = np.linalg.norm(succ - self.goal[None], axis=2)  # (B, n)
        worst = dist.max(axis=1)
        goal = worst < self.tolerance.eps
        if not goal.all():  # a goal state counts once its last action has passed the check
            out.best_error = min(out.best_error, float(worst[~goal].min()))
        h = self.heuristic(succ, dist).tolist()
        reached = goal.tolist()
        keys = self.keys_of(succ)
        here = self.key(P) if self.pruned else b""
        nodes, best_g, pruned, frontier = self.nodes, self.best_g, self.pruned, self.frontier  # the hot loop's
        too_deep, weight = cfg.max_depth + 1, WEIGHT
        for b, action in enumerate(actions.tolist()):
            k = keys[b]
            if best_g.get(k, too_deep) <= g + 1:
                out.duplicates += 1
                continue
            if pruned and (here, tuple(action)) in pruned:
                out.pruned += 1
                if self.tree is not None:
                    self.tree.left_out.append((index, tuple(action), "pruned", "known to fail refinement here, or "
                                               "taken from here before by the closed loop", succ[b]))
                continue
            nodes.append((succ[b], index, tuple(action), g + 1))
            if reached[b] and (why := self.infeasible(len(nodes) - 1)) is not None:
                nodes.pop()
                if self.tree is not None:
                    self.tree.left_out.append((index, tuple(action), str(why), "a goal state whose action the "
                                               "kinematic check rejects", succ[b]))
                out.goals_rejected += 1
                out.rejected_goal_error = min(out.rejected_goal_error, float(worst[b]))
                continue
            if not reached[b]:
                best_g[k] = g + 1
                heapq.heappush(frontier, (g + 1 + weight * h[b], h[b], len(nodes) - 1))
                continue
            out.best_error = min(out.best_error, float(worst[b]))
            solved = self.reach_goal(k, g + 1, float(worst[b]))
            if solved is not None:
                return solved
        return None

    def reach_goal(self, k: bytes, g: int, worst: float) -> SearchResult | None:
        """The newest node is a goal state of `g` actions, its worst block predicted `worst` metres off: it
        ends the search when confident and not doubtful, else it may become the candidate (not expanded)."""
        cfg, index = self.config, len(self.nodes) - 1
        if self.candidate is not None and g > self.nodes[self.candidate[2]][3]:
            self.best_g[k] = g
            return None  # a goal state of a longer plan than the candidate's: more actions to go wrong
        if cfg.look_on == 0:
            return self.finish(SearchStatus.SOLVED, f"solved: {g} actions after {self.out.expanded} expansions", index)
        unsure = self.doubtful(index)
        if worst < self.tolerance.confident and not unsure:
            return self.finish(SearchStatus.SOLVED, f"solved: {g} actions after {self.out.expanded} expansions", index)
        if not unsure:  # a doubtful goal state stays open to other actions: another grasp may reach it surely
            self.best_g[k] = g
        if self.candidate is None:
            self.look_until = min(self.look_until, self.out.expanded + cfg.look_on)
        if self.candidate is None or (unsure, worst) < self.candidate[:2]:
            self.candidate = (unsure, worst, index)
        return None


def continuous_search(model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray,
                      config: SearchConfig = SearchConfig(), goal: VerifyConfig = VerifyConfig(), *,
                      feasible: FeasibilityFn | None = None, pruned: AbstractSet[tuple[bytes, tuple]] = frozenset(),
                      started: float | None = None, graspable: np.ndarray | None = None, every_action: bool = False,
                      batched: bool = True) -> SearchResult:
    """`ContinuousSearch(...).run()`: weighted A* from X_init to X_goal (see the class)."""
    return ContinuousSearch(model, X_init, X_goal, config, goal, feasible, pruned, started, graspable, every_action,
                            batched).run()
