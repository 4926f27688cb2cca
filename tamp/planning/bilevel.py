"""The bilevel planner (paper, Algorithm 1), the baselines behind one interface, and closed-loop replanning.

    result = plan("bilevel", models, X_init, X_goal, PlanConfig())

Methods (`METHODS`, same signature, same `PlanResult`):
- ``bilevel``        Level 1: Sigma_init, Sigma_goal from the Symbolic Model -> probabilistic symbolic
                     planning over N sampled domains -> verify candidates in decreasing frequency, return
                     the first verified one. Level 2 (no verified candidate): continuous search. With
                     our extensions (`PlanConfig.alternatives`, `PlanConfig.nonempty`; from 5 blocks on
                     Level 1 plans in the sub-scene of the objects the goal involves, `level1_scene`,
                     and else one misplaced block at a time, `_level1_serial`).
- ``bilevel_alg1``   the paper's Algorithm 1 exactly: `bilevel` with both extensions off.
- ``probabilistic``  the most frequent plan of the probabilistic symbolic planner, not verified
                     (its verification error is reported).
- ``deterministic``  the plan in the most-frequent-effect domain (baseline), not verified.
- ``cfs``            continuous forward search alone.

The closed loops (the paper's replanning variant and the loop that does not know k) are in
`tamp.planning.closed_loop`.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import AbstractSet, Callable, Sequence

import numpy as np

from tamp.errors import UserError
from tamp.planning.config import LoopConfig
from tamp.planning.models import Models
from tamp.planning.search import (
    SearchConfig,
    SearchResult,
    SearchStatus,
    continuous_search,
    goal_oriented_actions,
    misplaced_objects,
    state_key,
)
from tamp.planning.structs import Infeasible, KinematicFeasibility, PickPlace, RefinementOutcome
from tamp.planning.validate import check_problem
from tamp.planning.verify import (
    EPS_SUCCESS,
    TAU_VERIFY,
    Verification,
    fragility,
    goal_error,
    refine_skeleton,
    states_pair,
    verify,
    verify_many,
    without_repicks,
)

SYMBOLIC_BACKENDS = ("python", "fd", "fd-naive")  # in-process search; Fast Downward, batched or one call per domain
LEVEL1_STAGES = ("symbols", "symbolic", "verify")  # the `PlanResult.timings` keys that make up Level 1's time


@dataclass(frozen=True)
class PlanConfig:
    """The planner's settings, one configuration for `tamp plan`, `tamp demo` and `tamp evaluate`."""

    n_domains: int = 100  # N sampled PDDL domains
    seed: int = 0  # seed of the sampled domains
    tau_verify: float = TAU_VERIFY  # metres
    eps: float = EPS_SUCCESS  # metres: success tolerance (goal test of the search, closed loop)
    backend: str = "python"  # symbolic planner backend, one of SYMBOLIC_BACKENDS
    symbolic_time_limit: float = 10.0  # seconds per symbolic planner call
    level1_budget: int | None = 100_000  # symbolic states the search for all N domains may generate
    #                                      (deterministic; about 3-4 microseconds each on this machine)
    level1_time_budget: float | None = None  # seconds for all N symbolic planner calls (machine-dependent)
    verify_all: bool = False  # verify every candidate (default: stop at the first verified one, Alg. 1)
    # Beyond the paper, bilevel only (0 and False give its Algorithm 1 exactly; the unverified
    # baselines never use them: without verification they would pick among look-alike plans blindly):
    alternatives: int = 64  # per symbolic plan, plans through the same symbolic states (the best of a
    #                         beam search of this width over the skeleton, `verify.refine_skeleton`), verified after it
    alternatives_total: int = 256  # per problem; later symbolic plans are verified alone
    nonempty: bool = True  # X_init not within tau of X_goal: the symbolic plan needs >= 1 action
    focus_from: int | None = 5  # from this many objects on, symbolic plans pick up only blocks off their
    #                             goal (`search.misplaced_objects`, the continuous search's pruning); None: never
    level1_focus_budget: int | None = 25_000  # from focus_from objects on, Level 1's budget (None: level1_budget):
    #   there the learned symbols rarely give a verified plan beyond a few thousand states, and a search
    #   that ends at the budget only delays Level 2 (tuned on the seed-13 problems of 5 and 6 blocks)
    level1_objects: int | None = 4  # from focus_from objects on, Level 1 plans in the sub-scene of the objects a
    #   goal-oriented plan involves (`level1_scene`: the blocks off their goal and the objects the continuous
    #   search's pruning would place them on), verifying its plans in the whole scene, when they are at most
    #   this many (the scene sizes the bundled models were trained on); with more, only `level1_serial`
    #   (in the whole scene Level 1 gave no plan there: seeds 13 and 101). None: it plans in the whole scene
    level1_serial: bool = True  # from focus_from objects on, when Level 1 gives no verified plan, it plans one
    #   misplaced block at a time (`_level1_serial`: each stage in its block's sub-scene), lowest goal first
    level1_confident: float | None = EPS_SUCCESS  # metres: a verified Level-1 plan predicted farther than this
    #   from the goal (worst object; the paper verifies up to tau_verify) is kept while Level 2 looks for a
    #   plan, and taken only if Level 2 finds none (None: take it, as the paper does)
    level1_cut: bool = True  # a verified Level-1 plan ends at its first action predicted to bring every block
    #   within search.confident of the goal, and loses each pick of a block the next action picks again when
    #   the shorter plan is predicted as close (False: the plan as verified, as the paper does)
    keep_plan: bool = True  # closed loop: keep the rest of the last plan while, rolled out from the observed
    #   state, it ends within search.confident of the goal and refines (False: plan again every round)
    on_course: float | None = 0.015  # metres: closed loop, with keep_plan: when every block of the observed state
    #   is within this distance (3-D) of where the last plan predicted it, the plan's own prediction of the
    #   rest decides (within search.confident of the goal), not a new rollout: the world did what the plan
    #   expected, and the model's prediction of the rest swings by centimetres under millimetre changes of
    #   its input (the plan passed the fragility test against 5 mm of such noise; 1.5 cm is three of its
    #   sigmas). None: the new rollout always decides
    # Kinematics in the planning loop (cfs, bilevel; needs a `kinematics` object passed to `plan`):
    feasibility: bool = True  # check actions on the predicted states, refine a plan before returning it
    max_refinements: int = 4  # full refinements per planning call (Level-1 candidates and Level-2 plans)
    search: SearchConfig = SearchConfig()
    loop: LoopConfig = LoopConfig()  # the closed loop that does not know k (`closed_loop.plan_closed_loop`)

    def __post_init__(self) -> None:
        if self.backend not in SYMBOLIC_BACKENDS:
            raise UserError(f"symbolic backend must be one of {', '.join(SYMBOLIC_BACKENDS)}, got {self.backend!r}")
        for name in ("tau_verify", "eps", "symbolic_time_limit", "level1_confident", "on_course"):
            value = getattr(self, name)
            if value is not None and not value > 0:  # level1_confident, on_course may be None
                raise UserError(f"PlanConfig.{name} must be positive, got {value}")
        if self.n_domains < 1:
            raise UserError(f"the number of sampled domains must be at least 1, got {self.n_domains}")
        if self.focus_from is not None and self.focus_from < 1:
            raise UserError(f"PlanConfig.focus_from must be a positive object count or None, got {self.focus_from}")
        for name in ("level1_budget", "level1_focus_budget"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise UserError(f"PlanConfig.{name} must be a positive number of states or None, "
                                f"got {getattr(self, name)}")
        if self.level1_objects is not None and self.level1_objects < 2:
            raise UserError(f"PlanConfig.level1_objects must be at least 2 objects (a block and where it goes) "
                            f"or None, got {self.level1_objects}")

    def focused(self, n_objects: int) -> bool:
        """Whether Level 1 focuses on the blocks off their goal in a scene of `n_objects` blocks."""
        return self.focus_from is not None and n_objects >= self.focus_from

    def level1_budget_for(self, n_objects: int) -> int | None:
        """Level 1's budget (generated symbolic states) in a scene of `n_objects` blocks."""
        if not self.focused(n_objects) or self.level1_focus_budget is None:
            return self.level1_budget
        return min(self.level1_focus_budget, self.level1_budget or self.level1_focus_budget)


@dataclass
class Candidate:
    """A symbolic plan of Level 1 with its verification outcome (None: not verified, Alg. 1 stopped before)."""

    actions: tuple[tuple[int, int, int, int], ...]
    count: int  # sampled domains that produced it
    probability: float
    error: float | None = None  # metres: max per-object distance of the predicted final state to the goal
    verified: bool | None = None
    alternative_of: int | None = None  # index of the ranked symbolic plan whose symbolic states it shares
    states: tuple[int, ...] | None = field(default=None, repr=False)  # packed symbolic states (python backend)
    objects: tuple[int, ...] | None = None  # the sub-scene's objects the states describe, in the scene's
    #   indices (`level1_scene`); None: all objects
    stages: tuple[int, ...] | None = None  # a plan joined one block at a time (`_level1_serial`): the blocks
    #   its stages placed, in order (count 0: no sampled domain gave it whole)


@dataclass
class PlanResult:
    method: str
    plan: list[PickPlace] | None  # None: no plan
    level: int | None = None  # 1 (symbolic) or 2 (continuous search) that produced the plan
    predicted: np.ndarray | None = None  # (len(plan) + 1, n, 5) Dynamics Model rollout of the plan
    candidates: list[Candidate] = field(default_factory=list)
    search: SearchResult | None = None
    timings: dict[str, float] = field(default_factory=dict)  # seconds: symbols, symbolic, verify, search, total
    reasons: list[str] = field(default_factory=list)  # why each level did not produce the plan
    symbolic_stats: dict = field(default_factory=dict)  # domains, unique plans, planner outcomes
    predicted_error: float | None = None  # metres: max per-object distance, predicted final state to goal
    # Kinematic feasibility: per level (1, 2), how many candidate plans (Level 1) or successors
    # (Level 2) the check or full refinement rejected, by reason; None when it was off
    rejected: dict[int, Counter] | None = None
    refinements: list[dict] = field(default_factory=list)  # level, plan, outcome of each full refinement
    kept_by: str | None = None  # closed loop: the plan is the rest of the last round's (`keep_rest`), not planned
    #   anew, judged by the plan's own prediction ("on course") or by a rollout from the observed state ("rollout")
    widened: bool = False  # closed loop: the plan of a search over every action, after the planner found none
    toward: bool = False  # closed loop, widened: no plan reaches the goal; the path to the closest state found

    @property
    def solved(self) -> bool:
        return self.plan is not None

    @property
    def kept(self) -> bool:
        """Closed loop: the plan is the rest of the last round's, not planned anew."""
        return self.kept_by is not None

    @property
    def origin(self) -> str:
        """How this round got its plan: "planned", "widened search", "toward the closest state", "kept on
        course" or "kept by rollout"."""
        if self.kept_by is None:
            return "toward the closest state" if self.toward else "widened search" if self.widened else "planned"
        return "kept on course" if self.kept_by == "on course" else "kept by rollout"

    def _plan_path(self) -> tuple[tuple[int, ...], tuple[int, ...] | None] | None:
        """The packed symbolic states a Level-1 plan passes through and the sub-scene they describe."""
        if self.level != 1 or self.plan is None:
            return None
        actions = tuple(tuple(int(v) for v in a) for a in self.plan)
        known = [(c.states, c.actions, c.objects) for c in self.candidates if c.verified and c.states is not None]
        for states, plan, objects in known:
            if plan == actions:
                return states, objects
        for states, plan, objects in known:  # a plan cut where it reaches the goal (level1_cut): its path's start
            if plan[:len(actions)] == actions:
                return states[:len(actions) + 1], objects
        return None

    @property
    def plan_states(self) -> tuple[int, ...] | None:
        """The packed symbolic states a Level-1 plan passes through (None: Level 2, one block at a time
        (`_level1_serial`), or a backend that does not give them); of the sub-scene `plan_scene`."""
        path = self._plan_path()
        return None if path is None else path[0]

    @property
    def plan_scene(self) -> tuple[int, ...] | None:
        """The objects whose symbols `plan_states` describe, in the scene's indices (`level1_scene`); None:
        every object."""
        path = self._plan_path()
        return None if path is None else path[1]

    def rejected_dict(self) -> dict | None:
        """`rejected` with string keys (JSON): {"level 1": {"no_grasp": 3, ...}, "level 2": {...}}."""
        if self.rejected is None:
            return None
        return {f"level {lvl}": {r.value if isinstance(r, Infeasible) else str(r): int(c) for r, c in sorted(
            counts.items(), key=lambda rc: str(rc[0]))} for lvl, counts in sorted(self.rejected.items())}

    def to_dict(self) -> dict:
        return {"method": self.method, "solved": self.solved, "level": self.level,
                "plan": None if self.plan is None else [list(a) for a in self.plan],
                "predicted_error_m": self.predicted_error,
                "candidates": [{"actions": [list(a) for a in c.actions], "count": c.count,
                                "probability": round(c.probability, 4), "error_m": c.error,
                                "verified": c.verified, "alternative_of": c.alternative_of}
                               for c in self.candidates],
                "search": None if self.search is None else {
                    k: getattr(self.search, k) for k in ("status", "reason", "expanded", "generated",
                                                         "duplicates", "predict_calls", "time")},
                "timings": {k: round(v, 6) for k, v in self.timings.items()},
                "reasons": list(self.reasons), "symbolic": self.symbolic_stats,
                "rejected": self.rejected_dict(), "refinements": list(self.refinements), "kept": self.kept,
                "kept_by": self.kept_by, "widened": self.widened, "toward": self.toward}


# --- the levels -------------------------------------------------------------------------------
def level1_scene(X_init: np.ndarray, X_goal: np.ndarray, cfg: PlanConfig) -> tuple[int, ...] | None:
    """The objects Level 1 plans over (our extension, `PlanConfig.level1_objects`); None: every object.

    From cfg.focus_from objects on: the objects of the continuous search's pruned actions in X_init
    (`search.goal_oriented_actions`), i.e. the blocks off their goal and, for each, the objects it
    would be placed on. The Symbolic Model then sees a scene of the size it was trained on, and the
    symbols of blocks that play no part cannot make Sigma_goal unreachable; the Dynamics Model
    verifies the plans in the whole scene. With more than cfg.level1_objects, Level 1 plans only one
    block at a time (`_level1_serial`)."""
    if cfg.level1_objects is None or not cfg.focused(len(X_init)):
        return None
    actions = goal_oriented_actions(np.asarray(X_init), np.asarray(X_goal), cfg.search.misplaced, cfg.eps,
                                    cfg.search.release_targets)
    return tuple(int(o) for o in np.unique(actions[:, [0, 2]]))


def _symbolic_problem(models: Models, X_init: np.ndarray, X_goal: np.ndarray, cfg: PlanConfig,
                      objects: tuple[int, ...] | None = None):
    """Sigma_init, Sigma_goal of the scene, or of the sub-scene of `objects` (`level1_scene`); with
    cfg.nonempty, the empty plan is ruled out when it cannot verify (X_init itself is not within tau
    of X_goal although the symbols may agree); from cfg.focus_from objects on, plans may pick up only
    the blocks off their goal."""
    from symbolic import make_problem

    assert models.symbolic is not None  # models.symbolic_planner() checked it
    X_init, X_goal = np.asarray(X_init), np.asarray(X_goal)
    scene = slice(None) if objects is None else list(objects)
    ui, ri = models.symbolic.symbols(X_init[scene])
    ug, rg = models.symbolic.symbols(X_goal[scene])
    movable = None
    if cfg.focused(len(X_init)):
        wrong = misplaced_objects(X_init, X_goal, cfg.search.misplaced, cfg.search.eps).tolist()
        movable = (wrong if objects is None else [objects.index(o) for o in wrong]) or None
    return make_problem(ui, ri, ug, rg, nonempty=cfg.nonempty and goal_error(X_init, X_goal) >= cfg.tau_verify,
                        movable=movable)


def _in_scene(actions, objects: tuple[int, ...] | None) -> tuple[tuple[int, int, int, int], ...]:
    """Actions on a sub-scene's objects (indices into `objects`) as actions on the whole scene."""
    if objects is None:
        return tuple((int(i), int(g), int(j), int(r)) for i, g, j, r in actions)
    return tuple((objects[i], int(g), objects[j], int(r)) for i, g, j, r in actions)


def _level1_plans(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
                  probabilistic: bool = True, objects: tuple[int, ...] | None = None) -> list[Candidate]:
    """Symbolic candidates, best first, their actions on the whole scene (planned in the sub-scene of
    `objects` if given); failures go to result.reasons (prefixed 'level 1')."""
    t = time.perf_counter()
    try:
        planner = models.symbolic_planner(cfg.backend, cfg.symbolic_time_limit)
        problem = _symbolic_problem(models, X_init, X_goal, cfg, objects)
    except ValueError as error:
        result.reasons.append(f"level 1: {error}")
        return []
    finally:
        result.timings["symbols"] = time.perf_counter() - t
    t = time.perf_counter()
    if probabilistic:
        out = planner.plan_probabilistic(problem, n_domains=cfg.n_domains, seed=cfg.seed,
                                         time_budget=cfg.level1_time_budget,
                                         budget=cfg.level1_budget_for(len(X_init)))
        result.timings["symbolic"] = time.perf_counter() - t
        result.symbolic_stats = {"n_domains": out.n_domains, "unique_plans": len(out.plans),
                                 "outcomes": dict(out.statuses), "expanded": out.expanded,
                                 "generated": out.generated, "movable": problem.movable,
                                 "objects": None if objects is None else list(objects),
                                 "timings": {k: round(v, 6) for k, v in out.timings.items()}}
        if not out.plans:
            result.reasons.append(f"level 1: no symbolic plan in any of the {out.n_domains} sampled domains "
                                  f"(outcomes: {dict(out.statuses)})")
        return [Candidate(_in_scene(p.actions, objects), p.count, p.probability, states=p.states, objects=objects)
                for p in out.plans]
    out = planner.plan_deterministic(problem)
    result.timings["symbolic"] = time.perf_counter() - t
    result.symbolic_stats = {"outcome": out.status.value}
    if not out.solved:
        result.reasons.append(f"level 1: no plan in the deterministic domain ({out.status.value}: {out.message})")
        return []
    from symbolic import steps_to_actions

    assert models.domain is not None  # models.symbolic_planner() checked it
    actions = steps_to_actions(models.domain, out.plan, len(X_init))
    return [Candidate(tuple(actions), 1, 1.0)]


def _verify(models: Models, X_init, X_goal, candidate: Candidate, cfg: PlanConfig):
    v = verify(models.require_dynamics(), X_init, X_goal, candidate.actions, cfg.tau_verify)
    candidate.error, candidate.verified = v.error, v.verified
    return v


def _take(result: PlanResult, actions, level: int, predicted: np.ndarray, X_goal) -> PlanResult:
    result.plan, result.level, result.predicted = [PickPlace(*a) for a in actions], level, predicted
    result.predicted_error = goal_error(predicted[-1], X_goal)
    return result


class _Feasibility:
    """The kinematic check and refinement of one planning call: results cached per (state, action),
    rejections counted per level and reason, time and refinement budget tracked."""

    def __init__(self, kinematics: KinematicFeasibility, cfg: PlanConfig, result: PlanResult,
                 avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> None:
        self.kinematics, self.cfg, self.result = kinematics, cfg, result
        self.resolution = cfg.search.resolution
        # (state key, action) known to fail: the closed loop's revisits (`avoid`), then failed refinements
        self.cache: dict[tuple[bytes, tuple], Infeasible | None] = {key: Infeasible.REVISIT for key in avoid}
        self.pruned: set[tuple[bytes, tuple]] = set(avoid)
        self.rejected: dict[int, Counter] = {1: Counter(), 2: Counter()}
        result.rejected = self.rejected
        result.timings.setdefault("feasibility", 0.0)
        result.timings.setdefault("refine", 0.0)

    @classmethod
    def of(cls, kinematics: KinematicFeasibility | None, cfg: PlanConfig, result: PlanResult,
           avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> "_Feasibility | None":
        """The feasibility of a planning call, or None when it is off (no kinematics, or cfg.feasibility False)."""
        return cls(kinematics, cfg, result, avoid) if kinematics is not None and cfg.feasibility else None

    def action(self, X: np.ndarray, action) -> Infeasible | None:
        """The check of one action in the predicted state X (cached)."""
        action = tuple(int(v) for v in action)
        key = (state_key(X, self.resolution), action)
        if key in self.pruned:
            return self.cache.get(key) or Infeasible.REFINE_MOTION
        if key not in self.cache:
            t = time.perf_counter()
            self.cache[key] = self.kinematics.check(X, np.asarray([action], dtype=np.int64))[0]
            self.result.timings["feasibility"] += time.perf_counter() - t
        return self.cache[key]

    def plan(self, trajectory: np.ndarray, actions) -> Infeasible | None:
        """The first reason an action of the plan fails on its predicted state, or None."""
        for X, a in zip(trajectory, actions):
            reason = self.action(X, a)
            if reason is not None:
                return reason
        return None

    @property
    def refinements_left(self) -> int:
        return self.cfg.max_refinements - len(self.result.refinements)

    def refine(self, level: int, trajectory: np.ndarray, actions) -> RefinementOutcome:
        """Full refinement; a failure prunes its (predicted state, action) for the rest of the call."""
        t = time.perf_counter()
        outcome = self.kinematics.refine([tuple(int(v) for v in a) for a in actions], trajectory)
        self.result.timings["refine"] += time.perf_counter() - t
        self.result.refinements.append({"level": level, "plan": [list(map(int, a)) for a in actions],
                                        "failed_action": outcome.action_index,
                                        "reason": None if outcome.reason is None else outcome.reason.value,
                                        "message": outcome.message})
        if not outcome.success:
            k = outcome.action_index
            key = (state_key(trajectory[k], self.resolution), tuple(int(v) for v in actions[k]))
            self.pruned.add(key)
            self.cache[key] = outcome.reason
            self.rejected[level][outcome.reason] += 1
        return outcome


def _level2(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
            feas: _Feasibility | None = None) -> PlanResult:
    """Continuous search; with `feas`, infeasible successors are pruned and a found plan is refined,
    searching again without the failing (state, action) while the refinement budget lasts."""
    t = time.perf_counter()
    refine_before = result.timings.get("refine", 0.0)
    search_cfg = replace(cfg.search, eps=cfg.eps)
    check = None if feas is None else feas.action
    while True:
        out = continuous_search(models.require_dynamics(), X_init, X_goal, search_cfg, check,
                                frozenset() if feas is None else feas.pruned)
        if feas is not None:
            feas.rejected[2].update(out.rejected)
            if result.search is not None:  # a search again after a refinement failure: count all
                for name in ("expanded", "generated", "duplicates", "predict_calls"):
                    setattr(out, name, getattr(out, name) + getattr(result.search, name))
        result.search = out
        if not out.solved or feas is None or not out.plan:
            break
        if feas.refinements_left <= 0:
            result.reasons.append(f"level 2: refinement budget ({cfg.max_refinements}) used up; the plan found "
                                  "was not refined")
            result.search.status = SearchStatus.REFINEMENT_BUDGET
            result.search.reason = "refinement budget used up"
            break
        assert out.trajectory is not None  # a solved search has its predicted trajectory
        outcome = feas.refine(2, out.trajectory, out.plan)
        if outcome.success:
            break
        result.reasons.append(f"level 2: the plan found did not refine (action {outcome.action_index}: "
                              f"{outcome.message}); searching again without that (state, action)")
    # search time: the searches with their checks, not the refinements between them
    result.timings["search"] = time.perf_counter() - t - (result.timings.get("refine", 0.0) - refine_before)
    if out.solved:
        assert out.plan is not None and out.trajectory is not None  # solved: both set
        return _take(result, out.plan, 2, out.trajectory, X_goal)
    result.reasons.append(f"level 2: {out.reason}")
    return result


def _timed(method: str, body: Callable[[PlanResult], PlanResult]) -> PlanResult:
    t = time.perf_counter()
    result = body(PlanResult(method, None))
    result.timings["total"] = time.perf_counter() - t
    return result


# --- the methods ------------------------------------------------------------------------------
def plan_bilevel(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
                 kinematics: KinematicFeasibility | None = None,
                 avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> PlanResult:
    """Algorithm 1 of the paper: a verified plan of Level 1, else Level 2's continuous search.

    With `kinematics` (and cfg.feasibility) a verified plan must also pass the kinematic check on its
    predicted states and refine, else the next one is tried; Level 2 then prunes infeasible
    successors and the (state, action) pairs that failed refinement, and those of `avoid`
    ((`search.state_key`, action) pairs a closed loop came back from)."""
    def body(result: PlanResult) -> PlanResult:
        feas = _Feasibility.of(kinematics, cfg, result, avoid)
        chosen = _level1(models, X_init, X_goal, cfg, result, feas)
        if chosen is None and cfg.level1_serial and cfg.focused(len(X_init)):
            chosen = _level1_serial(models, X_init, X_goal, cfg, result, feas)  # our extension
        confident = cfg.level1_confident
        if chosen is not None and confident is not None and chosen.error >= confident:
            # our extension: verified, but predicted to miss the goal
            result.reasons.append(f"level 1: its verified plan is predicted {chosen.error * 100:.1f} cm from the "
                                  f"goal (over {confident * 100:g} cm); kept while level 2 searches")
        elif chosen is not None and confident is not None and _fragile(models, X_init, X_goal, chosen, cfg):
            result.reasons.append(f"level 1: its verified plan misses the goal in over {cfg.search.max_fragility:.0%} "
                                  "of its perturbed rollouts; kept while level 2 searches")
        elif chosen is not None:
            return _take(result, chosen.actions, 1, chosen.trajectory, X_goal)
        result = _level2(models, X_init, X_goal, cfg, result, feas)  # line 16: continuous search fallback
        if result.solved or chosen is None:
            return result
        return _take(result, chosen.actions, 1, chosen.trajectory, X_goal)
    return _timed("bilevel", body)


def _fragile(models: Models, X_init, X_goal, chosen: Verification, cfg: PlanConfig) -> bool:
    """Whether more than cfg.search.max_fragility of the plan's perturbed rollouts miss the goal
    (`verify.fragility`; our extension, the continuous search's test of a goal state)."""
    limit = cfg.search.max_fragility
    return limit is not None and bool(chosen.actions) and fragility(
        models.require_dynamics(), X_init, X_goal, chosen.actions, cfg.eps, cfg.search.noise) > limit


def _level1(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
            feas: _Feasibility | None) -> Verification | None:
    """Level 1 of Algorithm 1 (lines 4-14): Sigma_init, Sigma_goal -> plans of N sampled domains, ranked
    by frequency -> the first plan whose Dynamics Model rollout ends within tau of X_goal.

    Our extensions: from cfg.focus_from objects on, Sigma is read on the sub-scene of the objects the
    goal involves (`level1_scene`; none when they are more than cfg.level1_objects); and in
    `_Verifier.check`, a ranked plan is verified together with the plans through the same symbolic
    states (`cfg.alternatives`), and a verified plan must pass the kinematic check and refine (`feas`)."""
    t = time.perf_counter()
    objects = level1_scene(X_init, X_goal, cfg)  # our extension; None: every object, as the paper plans
    if objects is not None and cfg.level1_objects is not None and len(objects) > cfg.level1_objects:
        result.timings["symbols"] = time.perf_counter() - t
        result.reasons.append(f"level 1: the goal involves {len(objects)} objects, more than the "
                              f"{cfg.level1_objects} of the scenes it plans in (--level1-objects)")
        return None
    ranked = _level1_plans(models, X_init, X_goal, cfg, result, objects=objects)  # lines 5-7
    verifier = _Verifier(models, X_init, X_goal, cfg, result, feas, ranked)
    for i in range(len(ranked)):  # line 9: in decreasing order of probability
        verifier.check(i)  # lines 10-11
        if verifier.chosen is not None and not cfg.verify_all:
            break  # line 12
        if verifier.refinements_used_up():
            break
    verifier.finish()
    return verifier.chosen


def _level1_serial(models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
                   feas: _Feasibility | None) -> Verification | None:
    """Level 1 one misplaced block at a time (our extension, `PlanConfig.level1_serial`).

    Stage by stage, from the state the plan so far is predicted to reach: for the misplaced blocks
    left, lowest goal first (a support before what stands on it), Level 1 plans to put that block at
    its goal and leave the others where they are (its sub-scene: the block and the objects it would
    be placed on, `level1_scene`); the first block with a plan predicted within cfg.eps of that
    sub-goal is the stage's. The plans are joined and verified against X_goal in the whole scene,
    then checked and refined as one. None (with the reason) when a stage places no block or the
    joined plan does not verify. Each stage plans in a scene of two or three objects, where the
    symbols the models learned on 2-4 blocks are reliable, however many objects the whole goal involves."""
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    left = sorted(misplaced_objects(X_init, X_goal, cfg.search.misplaced, cfg.search.eps).tolist(),
                  key=lambda i: (X_goal[i, 2], i))
    if len(left) < 2:
        return None  # one block: the sub-scene plan above was this plan
    X = X_init
    actions: list[tuple[int, int, int, int]] = []
    stages: list[int] = []  # the blocks placed, in order
    while left:
        for block in left:
            sub_goal = X.copy()
            sub_goal[block, :3] = X_goal[block, :3]
            stage = PlanResult(result.method, None)
            v = _level1(models, X, sub_goal, cfg, stage, None)
            for key in LEVEL1_STAGES:  # Level 1's time, every stage counted
                result.timings[key] = result.timings.get(key, 0.0) + stage.timings.get(key, 0.0)
            if v is not None and v.error < cfg.eps:
                break
        else:
            result.reasons.append(f"level 1, one block at a time: no plan places any of blocks {left} after "
                                  f"{len(stages)} placed ({stages})")
            result.symbolic_stats["serial"] = {"placed": stages, "left": left}
            return None
        stages.append(block)
        left.remove(block)
        actions += v.actions
        X = v.trajectory[-1]
    t = time.perf_counter()
    whole = verify(models.require_dynamics(), X_init, X_goal, actions, cfg.tau_verify)
    result.timings["verify"] += time.perf_counter() - t
    result.symbolic_stats["serial"] = {"placed": stages, "left": [], "error_m": round(whole.error, 6)}
    result.candidates.append(Candidate(whole.actions, 0, 0.0, whole.error, whole.verified, stages=tuple(stages)))
    if not whole.verified:
        result.reasons.append(f"level 1, one block at a time: the joined plan is predicted {whole.error * 100:.1f} "
                              f"cm from the goal (tau {cfg.tau_verify * 100:g} cm)")
        return None
    chosen = _feasible_choice([whole], feas)
    if chosen is None:
        result.reasons.append("level 1, one block at a time: the joined plan is not kinematically feasible")
    return chosen


class _Verifier:
    """Verification of Level 1's ranked plans (Alg. 1, lines 9-14) with our extensions, and its record.

    - The ranked plans' own rollouts are computed in growing chunks (1, 2, 4, ... plans), all prefixes
      of one length in one forward pass (`verify_many`): the same numbers as one plan at a time.
    - Alternatives (cfg.alternatives > 0, states known): the best plans of a beam search over the
      plan's skeleton (`refine_skeleton`), whose rollouts verify them; the group's verified plans are
      tried smallest predicted error first.
    - Kinematics (`feas`): a verified plan is taken only if it passes the check and refines.
    """

    def __init__(self, models: Models, X_init, X_goal, cfg: PlanConfig, result: PlanResult,
                 feas: _Feasibility | None, ranked: list[Candidate]):
        self.models, self.X_init, self.X_goal, self.cfg, self.result, self.feas, self.ranked = \
            models, X_init, X_goal, cfg, result, feas, ranked
        self.model = models.require_dynamics()
        self.checked: list[Candidate] = []  # verified so far: ranked plans and their alternatives
        self.chosen: Verification | None = None
        self.any_verified = False
        self.alternatives_left = cfg.alternatives_total
        self._rollouts: dict[int, Verification] = {}
        self._done = 0  # ranked plans checked
        self._start = time.perf_counter()

    def refinements_used_up(self) -> bool:
        """True (and the reason recorded) when no plan is chosen and no full refinement is left."""
        if self.feas is None or self.feas.refinements_left > 0 or self.chosen is not None:
            return False
        self.result.reasons.append(f"level 1: refinement budget ({self.cfg.max_refinements}) used up")
        return True

    def _rollout(self, i: int) -> Verification:
        if i not in self._rollouts:
            chunk = self.ranked[i: i + max(1, len(self._rollouts))]
            for j, v in enumerate(verify_many(self.model, self.X_init, self.X_goal, [c.actions for c in chunk],
                                              self.cfg.tau_verify)):
                self._rollouts[i + j] = v
        return self._rollouts[i]

    def check(self, i: int) -> None:
        """Verify ranked plan i (and its alternatives); take the first acceptable verified plan."""
        candidate = self.ranked[i]
        self._done += 1
        group: list[Candidate] = [candidate]
        checks: list[Verification] = []
        limit = min(self.cfg.alternatives, self.alternatives_left)
        if limit > 0 and candidate.states is not None and candidate.actions:
            planner = self.models.symbolic_planner(self.cfg.backend, self.cfg.symbolic_time_limit)
            objects = candidate.objects
            options = [list(_in_scene(step, objects)) for step in planner.skeleton_options(
                len(self.X_init) if objects is None else len(objects), candidate.states)]
            best, own = refine_skeleton(self.model, self.X_init, self.X_goal, options, limit + 1,
                                        self.cfg.tau_verify, also=candidate.actions)
            assert own is not None  # `also` given
            alternatives = [v for v in best if v.actions != candidate.actions][:limit]
            self.alternatives_left -= len(alternatives)
            group += [Candidate(v.actions, candidate.count, candidate.probability, alternative_of=i,
                                states=candidate.states, objects=objects) for v in alternatives]
            checks = [own] + alternatives
        else:
            checks = [self._rollout(i)]
        for c, v in zip(group, checks):
            c.error, c.verified = v.error, v.verified
        self.checked += group
        verified = [v for v in checks if v.verified]
        if self.cfg.level1_cut:
            verified = [self._shortened(v) for v in verified]
        verified.sort(key=lambda v: v.error)
        self.any_verified = self.any_verified or bool(verified)
        if self.chosen is None:
            self.chosen = _feasible_choice(verified, self.feas)

    def _shortened(self, v: Verification) -> Verification:
        """`v` cut where it reaches the goal, then without the picks the next action repeats if that
        plan is predicted within search.confident of the goal or no farther than `v` (cfg.level1_cut)."""
        v = v.cut(self.X_goal, self.cfg.search.confident)
        shorter = without_repicks(v.actions)
        if len(shorter) == len(v.actions):
            return v
        w = verify(self.model, self.X_init, self.X_goal, shorter, self.cfg.tau_verify)
        return w if w.verified and (w.error < self.cfg.search.confident or w.error <= v.error) else v

    def finish(self) -> None:
        """Record the candidates (checked ones, then the rest), the verification time and, without a
        chosen plan, why."""
        result, feas, ranked = self.result, self.feas, self.ranked
        result.candidates = self.checked + ranked[self._done:]
        if ranked:
            result.timings["verify"] = time.perf_counter() - self._start - (
                0.0 if feas is None else result.timings["feasibility"] + result.timings["refine"])
        if self.chosen is not None or not ranked:
            return
        if self.any_verified and feas is not None:
            rejected = result.rejected_dict()
            assert rejected is not None  # counted while feasibility is on
            result.reasons.append(f"level 1: no verified plan was kinematically feasible "
                                  f"(rejected: {rejected['level 1']})")
            return
        best = min(c.error for c in self.checked if c.error is not None)
        alts = sum(c.alternative_of is not None for c in self.checked)
        result.reasons.append(f"level 1: none of the {len(ranked)} symbolic plans verified"
                              + (f" (nor {alts} alternatives through the same symbols)" if alts else "")
                              + f" (best predicted error {best * 100:.1f} cm, tau {self.cfg.tau_verify * 100:g} cm)")


def _feasible_choice(verified: list[Verification], feas: _Feasibility | None) -> Verification | None:
    """The first verified plan (smallest error first) that passes the kinematic check on its predicted
    states and then refines; without `feas`, the first verified plan."""
    if feas is None:
        return verified[0] if verified else None
    for v in verified:
        reason = feas.plan(v.trajectory, v.actions)
        if reason is not None:
            feas.rejected[1][reason] += 1
            continue
        if not v.actions:
            return v
        if feas.refinements_left <= 0:
            return None
        if feas.refine(1, v.trajectory, v.actions).success:
            return v
    return None


def plan_bilevel_alg1(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
                      kinematics: KinematicFeasibility | None = None) -> PlanResult:
    """The paper's Algorithm 1 exactly: ranked symbolic plans verified alone (no look-alike
    alternatives, any block picked) and the empty plan allowed whenever Sigma_init = Sigma_goal; its
    Level 2 returns the continuous search's first goal state and prunes actions by the paper's rule."""
    paper = replace(cfg, alternatives=0, nonempty=False, feasibility=False, focus_from=None, level1_confident=None,
                    level1_cut=False,
                    search=replace(cfg.search, look_on=0, release_targets=False, max_fragility=None))
    result = plan_bilevel(models, X_init, X_goal, paper)
    result.method = "bilevel_alg1"
    return result


def _symbolic_only(method: str, probabilistic: bool):
    def run(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
            kinematics: KinematicFeasibility | None = None) -> PlanResult:
        def body(result: PlanResult) -> PlanResult:
            result.candidates = _level1_plans(models, X_init, X_goal, replace(cfg, nonempty=False), result,
                                          probabilistic)
            if not result.candidates:
                return result
            t = time.perf_counter()
            v = _verify(models, X_init, X_goal, result.candidates[0], cfg)  # reported, not used
            result.timings["verify"] = time.perf_counter() - t
            return _take(result, v.actions, 1, v.trajectory, X_goal)
        return _timed(method, body)
    run.__doc__ = f"The {method} symbolic planner alone (top plan, unverified; `kinematics` is ignored)."
    return run


plan_probabilistic = _symbolic_only("probabilistic", True)
plan_deterministic = _symbolic_only("deterministic", False)


def plan_cfs(models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
             kinematics: KinematicFeasibility | None = None,
             avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> PlanResult:
    """Continuous forward search alone; with `kinematics` (and cfg.feasibility) infeasible successors
    are pruned, as are the pairs of `avoid` (see `plan_bilevel`), and the plan is refined before it is
    returned."""
    def body(result: PlanResult) -> PlanResult:
        feas = _Feasibility.of(kinematics, cfg, result, avoid)
        return _level2(models, X_init, X_goal, cfg, result, feas)
    return _timed("cfs", body)


Planner = Callable[..., PlanResult]  # (models, X_init, X_goal, cfg, kinematics=None) -> PlanResult
METHODS: dict[str, Planner] = {"bilevel": plan_bilevel, "bilevel_alg1": plan_bilevel_alg1,
                               "probabilistic": plan_probabilistic, "deterministic": plan_deterministic,
                               "cfs": plan_cfs}
# the methods that put kinematics in their planning loop when given a checker (and cfg.feasibility)
KINEMATIC_METHODS = frozenset({"cfs", "bilevel"})
# the methods whose closed loop keeps a plan on course (cfg.keep_plan); the others replan every round
KEEPING_METHODS = frozenset({"cfs", "bilevel"})


def plan(method: str, models: Models, X_init, X_goal, cfg: PlanConfig = PlanConfig(),
         kinematics: KinematicFeasibility | None = None,
         avoid: AbstractSet[tuple[bytes, tuple]] = frozenset()) -> PlanResult:
    """Run one of METHODS on (X_init, X_goal), both (n, 5) arrays. `kinematics` (e.g. a
    tamp.sim.feasibility.FeasibilityChecker that observed the scene of X_init) puts kinematic feasibility
    into the planning loop of KINEMATIC_METHODS (unless cfg.feasibility is False); with it, those
    methods also leave out the (state key, action) pairs of `avoid` (a closed loop's revisits)."""
    if method not in METHODS:
        raise ValueError(f"unknown planning method {method!r}; choose one of {', '.join(METHODS)}")
    X_init, X_goal = states_pair(X_init, X_goal)
    # an observed X_init may hold tilted blocks: checked as any scene, not as one placed upright
    check_problem(X_init, X_goal, where="plan()", n_max=getattr(models, "n_max", None), init_upright=False)
    extra = {"avoid": avoid} if avoid and method in KINEMATIC_METHODS else {}
    return METHODS[method](models, X_init, X_goal, cfg, kinematics=kinematics, **extra)


__all__: Sequence[str] = ["Candidate", "LEVEL1_STAGES", "METHODS", "PlanConfig", "PlanResult", "Planner",
                          "level1_scene", "plan", "plan_bilevel", "plan_bilevel_alg1", "plan_cfs",
                          "plan_deterministic", "plan_probabilistic"]
