"""Closed-loop planning: execute an action, observe the world, plan again.

Two loops share one round (`_round`: plan, or keep the rest of the last plan while it is on course);
`plan_closed_loop` picks one by `rounds`, and each ends with a `LoopStop`:

- `paper_loop` (`rounds` = k - 1): the paper's replanning variant (`bilevel_replan`, Table IV).
  Plan, execute the first action with a caller-given `step` (a World, or any simulator), observe and
  plan again, up to `rounds` replanning rounds; the last plan is executed to its end. It stops at the
  goal, and when a round finds no plan or an empty one. (The paper executes the whole plan first and
  replans only if it failed; with a deterministic simulator that differs only in plans that would
  have succeeded anyway being replaced, and it needs no rollback of the world, which a real robot
  cannot do.)
- `loop_until_goal` (`rounds` None): the loop that does not know k (`bilevel_loop`, the default of
  `tamp plan --replan` and `tamp demo`). Every round executes one action and observes; it goes on
  until the observed state is within eps of the goal or `LoopConfig.max_actions` actions were sent, so
  a plan that ends short of the goal is followed by another round. A round that finds no plan, or
  only the empty plan while a block is off its goal, widens the search (`widened_search`: every one of
  the 9 n^2 actions, so blocks can be moved out of the way, unstacked, or moved although at their
  goal); when that finds none either (or the search budget has nothing left to widen with), it takes
  the first action toward the closest state either search expanded (`toward_closest`), if that is
  `PROGRESS_M` closer (the world may do better than the model predicts, and the next round
  plans from there). Back at a state it observed before (`revisits`), it
  leaves out the actions it took from there, which would start the same cycle again in a deterministic world.
  An action that misses what the loop expected twice alike is from then on predicted as the world did it
  (`REMEMBER_M`, `tamp.planning.experience`), so the loop stops trying a move the world keeps undoing.
  With noisy observations (`LoopConfig.stop_margin`, set from `tamp evaluate --noise`) it stops only that far
  inside eps; within eps but short of that, it takes a step only on a plan predicted within
  `verify.confident` (`aimed_inside`, `_closer_than`), and otherwise stops at what it observes.

Keeping a plan (`LoopConfig.keep_plan`, our extension, both loops): a round keeps the rest of the last
plan when it refines and still ends within `verify.confident` of the goal: as the plan predicted, if
the observed state is where the plan predicted it (every block within `ON_COURSE_M`), else
rolled out from the observed state; only otherwise does it plan again, so a plan on course is not
traded for another one. The loop that does not know k keeps a plan on course while its own prediction
still ends within eps (the plan was taken by that prediction, and the world is doing what it said);
when that end is over `verify.confident` it plans again, and a new plan replaces the kept one only if
it is predicted within `verify.confident` (`LoopConfig.commit`; else: if it is predicted closer): a loop
that traded its plan for one a few millimetres closer wandered between near-equal plans, each step as
predicted, until its actions ran out.
"""
from __future__ import annotations

import itertools
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from tamp.planning.config import PlanConfig
from tamp.planning.experience import Experience, remembers
from tamp.planning.kinematic_check import Feasibility
from tamp.planning.models import Models
from tamp.planning.planners import METHODS, plan, plan_cfs
from tamp.planning.results import Candidate, Clock, PlanResult, assemble, take_plan
from tamp.planning.search import SearchResult, state_key
from tamp.planning.verify import Verification, at_goal, goal_error, goal_errors, verify
from tamp.planning.vocabulary import KinematicFeasibility, LoopStop, Outcome, PickPlace

WIDEN_EXPANSIONS = 400  # node budget of a widened search (over all 9 n^2 actions)
PROGRESS_M = 0.02  # metres over blocks: without a plan, step toward the closest state only if it is this closer
REVISIT_M = 0.01  # metres: back this close to an observed state, leave out the actions taken from there
ON_COURSE_M = 0.015  # metres: blocks this close to a kept plan's prediction keep its prediction (`keep_rest`)
REMEMBER_M = 0.02  # metres: a step missing its prediction this far is remembered (`tamp.planning.experience`)
REMEMBER_ALIKE = 2  # misses alike before the loop trusts one: one outcome may be scatter


@dataclass
class ClosedLoopResult:
    rounds: list[PlanResult]  # one planning call per round, the first from X_init
    executed: list[PickPlace]  # actions sent to `step`, in order
    states: list[np.ndarray]  # observed states: X_init, then after each executed action
    X_goal: np.ndarray
    eps: float
    reason: str = ""
    stop: LoopStop | None = None  # how the loop ended
    experience: Experience | None = None  # the misses the loop that does not know k remembers (`REMEMBER_M`)
    expected: list[np.ndarray] = field(default_factory=list)  # with experience: the (n, 3) positions, metres, the
    #   loop expected after each executed action (the Dynamics Model with the misses it trusted then)

    @property
    def X_final(self) -> np.ndarray:
        return self.states[-1]

    @property
    def error(self) -> float:
        """Metres: max per-object distance of the observed final state to the goal."""
        return goal_error(self.X_final, self.X_goal)

    @property
    def success(self) -> bool:
        return self.error < self.eps

    def end(self, stop: LoopStop, reason: str) -> ClosedLoopResult:
        self.stop, self.reason = stop, reason
        return self

    def execute(self, actions: Sequence[PickPlace], step: Callable[[PickPlace], np.ndarray]) -> None:
        """Send `actions` to the world one by one, observing the state after each."""
        for action in actions:
            self.executed.append(action)
            self.states.append(np.asarray(step(action), dtype=float))


def loop_outcome(loop: ClosedLoopResult, error: float | None = None) -> Outcome:
    """A closed loop's outcome, judged by where it ended: success, no plan (nothing executed) or wrong plan.
    `error` (metres): the world's final distance to the goal, when the loop observed the world with noise
    (default: the observed one, `loop.error`)."""
    if (loop.error if error is None else error) < loop.eps:
        return Outcome.SUCCESS
    return Outcome.NO_PLAN if not loop.executed else Outcome.WRONG_PLAN


Step = Callable[[PickPlace], np.ndarray]  # executes one action in the world, returns the observed (n, 5) state
Look = Callable[[], np.ndarray]  # observes the world again without acting: the observed (n, 5) state
Margin = Callable[[], float]  # metres inside eps the loop stops, as its observations have taught it so far


def plan_closed_loop(method: str, models: Models, X_init, X_goal, step: Step, rounds: int | None,
                     cfg: PlanConfig = PlanConfig(),
                     on_round: Callable[[int, PlanResult], None] | None = None,
                     planner: Callable[..., PlanResult] | None = None,
                     kinematics: KinematicFeasibility | None = None, look: Look | None = None,
                     margin: Margin | None = None) -> ClosedLoopResult:
    """Plan, execute, observe, plan again; see the module doc. `rounds`: the paper's loop with that many
    replanning rounds (k - 1, `replan_rounds`: `paper_loop`); None: the loop that does not know k
    (`loop_until_goal`, cfg.loop).

    `step(action)` executes one action in the real (simulated) world and returns the observed (n, 5)
    state; `on_round(r, result)` is called after each planning call, before anything is executed.
    `planner` (default `plan`, same signature) lets a caller reuse a plan it already has.
    `kinematics` is passed to every planning call; `step` must let it observe the new scene
    (`FeasibilityChecker.observe`), since only the simulator knows the blocks' orientations. `look()`
    observes the scene again without acting (the loop that does not know k, cfg.loop.looks). `margin()`, if
    given, is that loop's stop margin, asked every round in place of cfg.loop.stop_margin (an observer that
    learns its error as it observes).
    """
    if rounds is None:
        return loop_until_goal(method, models, X_init, X_goal, step, cfg, on_round, planner, kinematics, look,
                               margin)
    return paper_loop(method, models, X_init, X_goal, step, rounds, cfg, on_round, planner, kinematics)


def paper_loop(method: str, models: Models, X_init, X_goal, step: Step, rounds: int, cfg: PlanConfig = PlanConfig(),
               on_round: Callable[[int, PlanResult], None] | None = None,
               planner: Callable[..., PlanResult] | None = None,
               kinematics: KinematicFeasibility | None = None) -> ClosedLoopResult:
    """The paper's replanning (`bilevel_replan`, Table IV): plan, execute the first action, observe, plan
    again, for `rounds` replanning rounds; the last plan is executed to its end."""
    out = ClosedLoopResult([], [], [np.asarray(X_init, dtype=float)], np.asarray(X_goal, dtype=float), cfg.verify.eps)
    for r in range(rounds + 1):
        if at_goal(out.X_final, out.X_goal, cfg.verify.eps):
            return out.end(LoopStop.GOAL, "the observed state is within eps of the goal")
        result = _round(method, models, out.X_final, out.X_goal, out, cfg, planner, kinematics)
        ended = _planned(out, r, result, on_round)
        if ended is not None:
            return ended
        assert result.plan is not None  # `_planned` ended the loop otherwise
        if r == rounds:
            out.execute(result.plan, step)
            return out.end(LoopStop.ROUNDS, f"executed the plan of round {r} to its end (no replanning rounds left)")
        out.execute(result.plan[:1], step)
    raise AssertionError("the last round executes its plan to its end")


def loop_until_goal(method: str, models: Models, X_init, X_goal, step: Step, cfg: PlanConfig = PlanConfig(),
                    on_round: Callable[[int, PlanResult], None] | None = None,
                    planner: Callable[..., PlanResult] | None = None,
                    kinematics: KinematicFeasibility | None = None, look: Look | None = None,
                    margin: Margin | None = None) -> ClosedLoopResult:
    """The loop that does not know k (`bilevel_loop`): one action a round until the goal, within the action
    and search budgets of cfg.loop; a round without a plan widens its search, else steps toward the closest
    state its searches found, else (with `look`, up to cfg.loop.looks times) observes the scene again and plans
    from that; actions that led back to an observed state are left out (`revisits`). `margin()`: the stop
    margin of each round, in place of cfg.loop.stop_margin."""
    out = ClosedLoopResult([], [], [np.asarray(X_init, dtype=float)], np.asarray(X_goal, dtype=float), cfg.verify.eps,
                           experience=Experience(REMEMBER_M, REMEMBER_ALIKE))
    inside = aimed_inside(cfg)
    budget = cfg.loop.search_budget_for(len(out.X_goal), cfg.search.greedy_from)
    spent = 0  # continuous-search expansions of every round so far
    remembered: list[str] = []  # the miss the last executed action added to the loop's experience, said once
    looked = 0  # observations again after a round without a plan
    for r in itertools.count():
        X = out.X_final
        if margin is not None:  # the margin the observations have taught so far
            cfg = replace(cfg, loop=replace(cfg.loop, stop_margin=margin()))
            inside = aimed_inside(cfg)
        if at_goal(X, out.X_goal, inside.verify.eps):
            within = "within eps" if cfg.loop.margin == 0 else f"{cfg.loop.margin * 100:.2g} cm inside eps"
            return out.end(LoopStop.GOAL, f"the observed state is {within} of the goal")
        if len(out.executed) >= cfg.loop.max_actions:
            return out.end(LoopStop.BUDGET, f"{cfg.loop.max_actions} actions sent without reaching the goal "
                                            f"(the loop's action budget)")
        if spent >= budget:
            return out.end(LoopStop.BUDGET, f"{spent} search expansions spent without reaching the goal (the "
                                            f"loop's search budget)")
        avoid = revisits(out, cfg)
        seen = experienced(models, out.experience)  # the Dynamics Model with the misses the loop trusts
        if at_goal(X, out.X_goal, cfg.verify.eps):  # within eps, not within the stop margin: one clearly closer step
            result = _round(method, seen, X, out.X_goal, out, _within(inside, WIDEN_EXPANSIONS,
                                                                        budget - spent), planner, kinematics, avoid,
                            until_goal=True)
            spent += _expanded(result)
            result = _with_reasons(result, remembered)
            out.rounds.append(result)
            if on_round is not None:
                on_round(r, result)
            bar = _closer_than(X, out.X_goal, inside)
            if not (result.solved and result.plan and result.predicted_error is not None
                    and result.predicted_error < bar):
                return out.end(LoopStop.GOAL, f"the observed state is within eps of the goal "
                                              f"({goal_error(X, out.X_goal) * 100:.1f} cm), and no plan is predicted "
                                              f"closer than {bar * 100:.1f} cm")
            remembered = _execute_one(out, result.plan[0], step, models)
            continue
        result = _round(method, seen, X, out.X_goal, out, _within(cfg, cfg.search.max_expansions, budget - spent),
                        planner, kinematics, avoid, until_goal=True)
        spent += _expanded(result)
        if cfg.loop.widen and not (result.solved and result.plan):
            if spent < budget:
                result = widened_search(method, seen, X, out.X_goal,
                                        _within(cfg, WIDEN_EXPANSIONS, budget - spent), kinematics, result,
                                        avoid)
                spent += _expanded(result)
            else:  # no budget left to widen: what the round's search found may still bring the blocks closer
                result = toward_closest(X, out.X_goal, cfg, result, [result.search])
        if not result.solved and look is not None and looked < cfg.loop.looks_again and spent < budget:
            looked += 1
            out.rounds.append(_with_reasons(result, remembered))
            if on_round is not None:
                on_round(r, out.rounds[-1])
            out.states[-1] = np.asarray(look(), dtype=float)  # the state the next action starts from, seen again
            remembered = [f"no plan from the last observation: the scene observed again ({looked} of "
                          f"{cfg.loop.looks_again})"]
            continue
        ended = _planned(out, r, _with_reasons(result, remembered), on_round, budget if spent >= budget else None)
        if ended is not None:
            return ended
        assert result.plan is not None  # `_planned` ended the loop otherwise
        remembered = _execute_one(out, result.plan[0], step, models)
    raise AssertionError("unreachable")


def experienced(models: Models, experience: Experience | None) -> Models:
    """`models` whose Dynamics Model predicts what the world did where the loop missed before (`experience`)."""
    if experience is None or not experience.trusted or models.dynamics is None:
        return models
    return replace(models, dynamics=experience.over(models.dynamics))


def _execute_one(out: ClosedLoopResult, action: PickPlace, step: Step, models: Models) -> list[str]:
    """Send one action to the world and observe; remember it if the Dynamics Model (of `models`, with the loop's
    experience) missed it. The sentence that says so for the next round's reasons (none: not missed)."""
    if out.experience is None or models.dynamics is None:
        out.execute([action], step)
        return []
    X = out.states[-1]
    out.expected.append(out.experience.expect(models.dynamics, X, action))
    out.execute([action], step)
    miss = out.experience.remember(models.dynamics, X, action, out.states[-1], expected=out.expected[-1])
    return [miss.describe()] if out.experience.trusts(miss) and miss is not None else []


def _with_reasons(result: PlanResult, first: list[str]) -> PlanResult:
    return replace(result, reasons=[*first, *result.reasons]) if first else result


def _closer_than(X: np.ndarray, X_goal: np.ndarray, inside: PlanConfig) -> float:
    """Metres: how close to the goal a plan from X, observed within eps but short of the stop margin, must be
    predicted to end for the loop to take a step: within `verify.confident` and the stop margin closer than X (a
    step from within eps must be worth its risk)."""
    return min(inside.verify.confident, goal_error(X, X_goal) - inside.loop.margin)


def aimed_inside(cfg: PlanConfig) -> PlanConfig:
    """cfg whose goal tolerances (eps, misplaced, confident) lie `LoopConfig.stop_margin` inside the user's: the
    loop that does not know k stops there, and from a state within eps but not within that it takes one step more
    only if a plan aimed there is predicted clearly closer (`_closer_than`), so that an observation whose noise
    puts the blocks within eps does not end the loop while they are not (the outcome is judged on the world at
    the user's eps)."""
    margin = cfg.loop.margin
    if margin == 0:
        return cfg
    v = cfg.verify
    eps = v.eps - margin
    return replace(cfg, verify=replace(v, eps=eps, confident=min(v.confident, eps)))


def _planned(out: ClosedLoopResult, r: int, result: PlanResult, on_round: Callable[[int, PlanResult], None] | None,
             spent_budget: int | None = None) -> ClosedLoopResult | None:
    """Record round r's plan; the loop's end if the round found no plan or an empty one (None: go on).
    `spent_budget`: the search budget the loop has spent, if it has."""
    out.rounds.append(result)
    if on_round is not None:
        on_round(r, result)
    if not result.solved:
        reason = f"round {r}: no plan ({'; '.join(result.reasons)})"
        if spent_budget is not None:
            return out.end(LoopStop.BUDGET, reason + f"; the loop's search budget ({spent_budget} expansions) is spent")
        return out.end(LoopStop.NO_PLAN, reason)
    if not result.plan:
        return out.end(LoopStop.EMPTY_PLAN, f"round {r}: the planner returned an empty plan")
    return None


def _within(cfg: PlanConfig, expansions: int, left: int) -> PlanConfig:
    """cfg with a continuous search of at most `expansions` nodes, and no more than the `left` expansions of the
    loop's search budget, stalling after cfg.loop.stall expansions at any number of blocks (if set; else the
    search's own `stall` and `greedy_stall`)."""
    allowed = max(1, min(expansions, left))
    search = replace(cfg.search, max_expansions=allowed)
    if cfg.loop.stall is not None:
        search = replace(search, stall=cfg.loop.stall, greedy_stall=cfg.loop.stall)
    return cfg if search == cfg.search else replace(cfg, search=search)


def _expanded(result: PlanResult) -> int:
    """The continuous-search expansions a round's planning call spent (0: it did not search)."""
    return 0 if result.search is None else result.search.expanded


def revisits(out: ClosedLoopResult, cfg: PlanConfig) -> frozenset[tuple[bytes, tuple]]:
    """The (state key of the observed state, action) pairs to leave out: the actions the loop executed from
    an earlier observed state that every block is within `REVISIT_M` of now (it came back, and the
    same action would start the same cycle again)."""
    X = out.states[-1]
    key = state_key(X, cfg.search.resolution)
    return frozenset((key, tuple(int(v) for v in action)) for before, action in zip(out.states, out.executed)
                     if np.linalg.norm(before[:, :3] - X[:, :3], axis=1).max() < REVISIT_M)


def _round(method: str, models: Models, X: np.ndarray, X_goal: np.ndarray, out: ClosedLoopResult,
           cfg: PlanConfig, planner: Callable[..., PlanResult] | None,
           kinematics: KinematicFeasibility | None, avoid: frozenset = frozenset(), until_goal: bool = False
           ) -> PlanResult:
    """One round's plan from the observed X: the rest of the last plan if it is kept, else a new one; both
    without the actions of `avoid` from here (`revisits`). `until_goal`: the loop that does not know k, which
    keeps a plan on course while it still predicts success (`keep_rest`)."""
    extra: dict = {} if kinematics is None else {"kinematics": kinematics}
    if avoid:
        extra["avoid"] = avoid
    keep = cfg.loop.keep_plan and METHODS[method].keeps_plans and bool(out.rounds)
    kept = keep_rest(models, X, X_goal, out.rounds[-1], cfg, kinematics, avoid,
                     cfg.verify.eps if until_goal else None) if keep else None
    kept_error = kept.predicted_error if kept is not None and kept.solved else None
    marginal = until_goal and kept_error is not None and kept_error >= cfg.verify.confident
    if kept is not None and kept.solved and not marginal:
        return kept
    if marginal:  # a search for a plan aimed closer than one that already predicts success: no longer than a widening
        cfg = replace(cfg, search=replace(cfg.search, max_expansions=min(cfg.search.max_expansions,
                                                                         WIDEN_EXPANSIONS)))
    result = (planner or plan)(method, models, X, X_goal, cfg, **extra)
    if kept is not None and kept_error is not None and marginal:  # a plan aimed within confident (closer) replaces it
        new_error = result.predicted_error if result.solved and result.plan else None
        aim = min(kept_error, cfg.verify.confident) if cfg.loop.commit else kept_error
        if new_error is not None and new_error < aim:
            within = f"within {cfg.verify.confident * 100:g} cm" if cfg.loop.commit else "closer"
            kept = replace(kept, reasons=[f"keep: the rest of the last plan ends {kept_error * 100:.1f} cm from the "
                                          f"goal (over {cfg.verify.confident * 100:g} cm); a new plan aims {within}"])
        else:  # the round's search: its expansions count against the loop's budget
            return replace(_absorbed(kept, result, "planned"), search=result.search)
    return result if kept is None else _absorbed(result, kept)


def widened_search(method: str, models: Models, X: np.ndarray, X_goal: np.ndarray, cfg: PlanConfig,
                   kinematics: KinematicFeasibility | None, failed: PlanResult,
                   avoid: frozenset = frozenset()) -> PlanResult:
    """The continuous search over all 9 n^2 actions (cfg.search.max_expansions nodes), after a round
    whose planner found no plan (`failed`, or only the empty plan while a block is off its goal): the
    goal-oriented actions only move misplaced blocks toward their goal, and cannot move a block out of
    the way, unstack one, or move a block already at its goal. The failed round's time, reasons and
    rejections are counted in the result (`PlanResult.widened`)."""
    searched = plan_cfs(models, X, X_goal, cfg, kinematics=kinematics, avoid=avoid, every_action=True)
    result = _absorbed(replace(searched, method=method, widened=True), failed, "planned")
    empty = ["the planner returned an empty plan with a block off its goal"] if failed.solved and not failed.plan \
        else []
    if result.solved:
        return replace(result, reasons=[*empty, *result.reasons,
                                        "searched again over every action (the goal-oriented ones gave no plan)"])
    result = replace(result, reasons=[*empty, *result.reasons, "no plan over every action either"])
    return toward_closest(X, X_goal, cfg, result, [failed.search, result.search])


def toward_closest(X: np.ndarray, X_goal: np.ndarray, cfg: PlanConfig, result: PlanResult,
                   searches: Sequence[SearchResult | None]) -> PlanResult:
    """`result` (a round without a plan) given the path to the closest state any of `searches` expanded (least
    summed distance to the goal), when that state is `PROGRESS_M` closer than the observed X: the
    loop executes its first action and plans again from what the world did. Unchanged otherwise."""
    found = [(float(goal_errors(s.closest_trajectory[-1], X_goal).sum()), i, s) for i, s in enumerate(searches)
             if s is not None and s.closest_trajectory is not None and s.closest_plan]
    if not found:
        return result
    _, _, search = min(found)
    closest = search.closest_trajectory
    assert closest is not None and search.closest_plan is not None  # filtered above
    if not _progress(X, closest[-1], X_goal, PROGRESS_M):
        return result
    toward = (f"toward the closest state found (predicted {goal_error(closest[-1], X_goal) * 100:.1f} cm from the "
              f"goal, from {goal_error(X, X_goal) * 100:.1f} cm)")
    return take_plan(replace(result, reasons=[*result.reasons, toward], toward=True), search.closest_plan, 2, closest,
                     X_goal)


def _progress(X: np.ndarray, X_then: np.ndarray, X_goal: np.ndarray, margin: float) -> bool:
    """Whether X_then is `margin` metres closer to the goal than X, in the search's h (summed distances)."""
    return float(goal_errors(X_then, X_goal).sum()) <= float(goal_errors(X, X_goal).sum()) - margin


def _absorbed(result: PlanResult, attempt: PlanResult, stage: str = "keep") -> PlanResult:
    """`result` with an earlier attempt of the round counted in it (a failed `keep_rest`, or the planning call
    before a widened search): its time (`timings[stage]`, and in the total), reasons, full refinements and
    kinematic rejections."""
    timings = dict(result.timings)
    for key in ("total", "feasibility", "refine"):
        if key in attempt.timings:
            timings[key] = timings.get(key, 0.0) + attempt.timings[key]
    timings[stage] = timings.get(stage, 0.0) + attempt.timings["total"]
    rejected = result.rejected
    if attempt.rejected is not None:
        rejected = {level: Counter(counts) for level, counts in (rejected or {1: Counter(), 2: Counter()}).items()}
        for level, counts in attempt.rejected.items():
            rejected.setdefault(level, Counter()).update(counts)
    return replace(result, timings=timings, reasons=[*attempt.reasons, *result.reasons],
                   refinements=[*attempt.refinements, *result.refinements], rejected=rejected)


def off_course(X: np.ndarray, last: PlanResult) -> float:
    """Metres: the largest 3-D distance of a block of the observed state X from where `last` predicted
    it after its first action (inf when `last` has no prediction)."""
    if last.predicted is None or len(last.predicted) < 2:
        return float("inf")
    return float(np.linalg.norm(np.asarray(X)[:, :3] - last.predicted[1][:, :3], axis=1).max(initial=0.0))


def keep_rest(models: Models, X: np.ndarray, X_goal: np.ndarray, last: PlanResult, cfg: PlanConfig,
              kinematics: KinematicFeasibility | None = None, avoid: frozenset = frozenset(),
              on_course_within: float | None = None) -> PlanResult:
    """The rest of `last` (its first action executed) as this round's plan, if it ends within
    cfg.verify.confident of X_goal as `last` predicted it, when the observed state X is within
    `ON_COURSE_M` of that prediction (or within `on_course_within`, if given: the loop that does not
    know k keeps a plan on course while it still predicts success, cfg.verify.eps), or rolled out from X
    otherwise; and, with `kinematics` (and cfg.kinematics.feasibility), it passes the check and refines.
    Else a result without a plan (its reasons say why, its timings what the check cost). The plan keeps
    the last plan's level."""
    rest = list(last.plan or [])[1:]
    level = last.level or 2
    started, clock = time.perf_counter(), Clock()
    reasons: list[str] = []

    def without_plan(why: str, feas: Feasibility | None = None) -> PlanResult:
        return assemble(last.method, X_goal, clock, started, reasons=[*reasons, why],
                        rejected=None if feas is None else feas.rejected,
                        refinements=() if feas is None else feas.refinements)

    if not rest:
        return without_plan("keep: the last plan has no actions left")
    v: Verification | None = None
    deviation = off_course(X, last)
    on_course = deviation <= ON_COURSE_M
    if on_course:  # the plan's own prediction of the rest, unless the loop has since seen one of its steps missed
        assert last.predicted is not None  # a finite deviation needs the prediction
        trajectory = np.concatenate([np.asarray(X, dtype=float)[None], last.predicted[2:]])
        on_course = not remembers(models.dynamics, trajectory[:-1], rest)
    if on_course:
        planned = Verification(tuple(tuple(int(a) for a in action) for action in rest), trajectory,
                               goal_errors(trajectory[-1], X_goal), cfg.verify.tau_verify)
        if planned.error < (cfg.verify.confident if on_course_within is None else on_course_within):
            v, kept_by = planned, "on course"
            why = f"on course (every block within {deviation * 100:.1f} cm of its predicted place), " \
                  f"predicted {v.error * 100:.1f} cm from the goal"
    if v is None:  # off course: a new rollout from the observed state
        v = verify(models.require_dynamics(), X, X_goal, rest, cfg.verify.tau_verify)
        if v.error >= cfg.verify.confident:
            return without_plan(f"keep: the rest of the last plan is predicted {v.error * 100:.1f} cm from the goal "
                                f"from the observed state (over {cfg.verify.confident * 100:g} cm)")
        kept_by, why = "rollout", f"predicted {v.error * 100:.1f} cm from the goal from the observed state"
    feas = Feasibility.of(kinematics, cfg.kinematics, clock, cfg.search.resolution, avoid)
    if feas is not None and (feas.plan(v.trajectory, v.actions) is not None
                             or not feas.refine(level, v.trajectory, v.actions).success):
        return without_plan("keep: the rest of the last plan is not kinematically feasible from here", feas)
    reasons.append(f"kept the rest of the last plan: {why}")
    result = assemble(last.method, X_goal, clock, started, reasons=reasons, plan=(v.actions, level, v.trajectory),
                      rejected=None if feas is None else feas.rejected,
                      refinements=() if feas is None else feas.refinements)
    states = last.plan_states
    if states is not None:  # the same symbolic path from the next state on (the per-step view)
        result = replace(result, candidates=[Candidate(v.actions, 0, 0.0, v.error, True, states=states[1:],
                                                       objects=last.plan_scene)])
    return replace(result, kept_by=kept_by)


def replan_rounds(k: int | None, default: int = 4) -> int:
    """k - 1 replanning rounds for a problem generated with k actions (the paper's loop)."""
    return default if k is None else max(k - 1, 0)


__all__: Sequence[str] = ["ClosedLoopResult", "keep_rest", "loop_outcome", "loop_until_goal", "off_course",
                          "paper_loop", "plan_closed_loop",
                          "replan_rounds", "toward_closest", "widened_search"]
