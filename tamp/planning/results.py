"""What the planner's stages return and what a planning call assembles from them.

`Level1Result` (Level 1), `Level2Result` (the continuous search), the kinematic check's record
(`tamp.planning.kinematic_check.Feasibility`) and the `Clock` every stage times itself with; `PlanResult`
is built from them at the end of a planning call (`assemble`), with Level 1's `Candidate` plans.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from tamp.planning.search import SearchResult
from tamp.planning.verify import Verification, goal_error
from tamp.planning.vocabulary import Infeasible, PickPlace

LEVEL1_STAGES = ("symbols", "symbolic", "verify")  # the `PlanResult.timings` keys that make up Level 1's time


class Clock:
    """Seconds per stage of one planning call. A stage opened inside another pauses it, so each stage's
    time is its own (the search's without the refinements it waits for, Level 1's verification without
    the kinematic check): no stage subtracts another's time."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._open: list[list] = []  # [stage, perf_counter() since when it runs], innermost last

    def stage(self, name: str) -> _Stage:
        """`with clock.stage(name):` times the block as `name`, pausing the stage it runs in."""
        return _Stage(self, name)

    def _enter(self, name: str) -> None:
        now = time.perf_counter()
        if self._open:
            self._charge(self._open[-1], now)
        self._open.append([name, now])

    def _exit(self) -> None:
        end = time.perf_counter()
        self._charge(self._open.pop(), end)
        if self._open:
            self._open[-1][1] = end

    def _charge(self, running: list, now: float) -> None:
        self.seconds[running[0]] = self.seconds.get(running[0], 0.0) + now - running[1]
        running[1] = now


class _Stage:
    """The context of one `Clock.stage` (a plain class: the kinematic check opens one per action it checks)."""

    __slots__ = ("clock", "name")

    def __init__(self, clock: Clock, name: str) -> None:
        self.clock, self.name = clock, name

    def __enter__(self) -> None:
        self.clock._enter(self.name)

    def __exit__(self, *exc: object) -> None:
        self.clock._exit()


@dataclass
class Candidate:
    """A symbolic plan of Level 1 with its verification outcome (None: not verified, Alg. 1 stopped before)."""

    actions: tuple[tuple[int, int, int, int], ...]
    count: int  # sampled domains that produced it
    probability: float
    error: float | None = None  # metres: max per-object distance of the predicted final state to the goal
    verified: bool | None = None
    states: tuple[int, ...] | None = field(default=None, repr=False)  # packed symbolic states (python backend)
    objects: tuple[int, ...] | None = None  # the sub-scene's objects the states describe, in the scene's
    #   indices (`level1_scene`); None: all objects
    stages: tuple[int, ...] | None = None  # a plan joined one block at a time (`level1_serial`): the blocks
    #   its stages placed, in order (count 0: no sampled domain gave it whole)
    # recorded only inside `search_trace.recording` (the search record): the Dynamics Model rollout it was verified
    #   by ((len(actions) + 1, n, 5)) and the kinematic verdict of each action ("ok", a reason, "unchecked")
    predicted: np.ndarray | None = field(default=None, repr=False)
    kinematics: tuple[str, ...] | None = None


@dataclass
class Level1Result:
    """What Level 1 gives a planning call: its chosen plan (verified, and feasible when kinematics is on), the
    candidates it ranked and verified, the symbolic planner's figures, and why it gave no plan."""

    chosen: Verification | None = None
    # chosen passed the kinematic check but is not refined yet: it waits for Level 2 (`Level1Config.wait_beyond`),
    #   which refines it only if Level 2 finds no plan (`bilevel.plan_bilevel`)
    refine_later: bool = False
    candidates: list[Candidate] = field(default_factory=list)
    symbolic_stats: dict = field(default_factory=dict)  # domains, unique plans, planner outcomes
    reasons: list[str] = field(default_factory=list)


@dataclass
class Level2Result:
    """What the continuous search gives a planning call: the search's record (its counters summed over searches
    again after failed refinements; its plan, if solved, is Level 2's) and why it gave no plan."""

    search: SearchResult | None = None
    reasons: list[str] = field(default_factory=list)

    @property
    def plan(self) -> tuple[list[tuple[int, int, int, int]], int, np.ndarray] | None:
        """The plan found as `assemble` takes it: (actions, level 2, predicted states); None: none."""
        if self.search is None or not self.search.solved:
            return None
        assert self.search.plan is not None and self.search.trajectory is not None  # solved: both set
        return self.search.plan, 2, self.search.trajectory


@dataclass(frozen=True)
class PlanResult:
    """What one planning call gives (`assemble` builds it from the stages' results); a closed loop's round that
    combines attempts builds a new one (`tamp.planning.closed_loop`)."""

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
        known = [(c.states, c.actions, c.objects, bool(c.verified)) for c in self.candidates if c.states is not None]
        for states, plan, objects, _ in sorted(known, key=lambda k: not k[3]):  # the symbolic planners take
            if plan == actions:  # their top plan unverified
                return states, objects
        for states, plan, objects, verified in known:  # the first actions of a verified plan
            if verified and plan[:len(actions)] == actions:
                return states[:len(actions) + 1], objects
        return None

    @property
    def plan_states(self) -> tuple[int, ...] | None:
        """The packed symbolic states a Level-1 plan passes through (None: Level 2, one block at a time
        (`level1_serial`), or a backend that does not give them); of the sub-scene `plan_scene`."""
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
        return {f"level {lvl}": reasons_json(counts) for lvl, counts in sorted(self.rejected.items())}

    def to_dict(self) -> dict:
        return {"method": self.method, "solved": self.solved, "level": self.level,
                "plan": None if self.plan is None else [list(a) for a in self.plan],
                "predicted_error_m": self.predicted_error,
                "candidates": [{"actions": [list(a) for a in c.actions], "count": c.count,
                                "probability": round(c.probability, 4), "error_m": c.error,
                                "verified": c.verified}
                               for c in self.candidates],
                "search": None if self.search is None else {
                    k: getattr(self.search, k) for k in ("status", "reason", "expanded", "generated",
                                                         "duplicates", "predict_calls", "time", "goals_rejected")},
                "timings": {k: round(v, 6) for k, v in self.timings.items()},
                "reasons": list(self.reasons), "symbolic": self.symbolic_stats,
                "rejected": self.rejected_dict(), "refinements": list(self.refinements), "kept": self.kept,
                "kept_by": self.kept_by, "widened": self.widened, "toward": self.toward}


def reasons_json(counts: Counter) -> dict[str, int]:
    """Rejections counted by reason, with string keys in a fixed order (JSON, messages)."""
    return {r.value if isinstance(r, Infeasible) else str(r): int(c)
            for r, c in sorted(counts.items(), key=lambda rc: str(rc[0]))}


def take_plan(result: PlanResult, actions, level: int, predicted: np.ndarray, X_goal) -> PlanResult:
    """`result` with `actions` as its plan, from `level`, with its predicted states (their last one's goal error)."""
    return replace(result, plan=[PickPlace(*a) for a in actions], level=level, predicted=predicted,
                   predicted_error=goal_error(predicted[-1], X_goal))


def assemble(method: str, X_goal, clock: Clock, started: float, *, level1: Level1Result | None = None,
             level2: Level2Result | None = None, reasons: Sequence[str] = (),
             plan: tuple[Sequence, int, np.ndarray] | None = None, rejected: dict[int, Counter] | None = None,
             refinements: Sequence[dict] = ()) -> PlanResult:
    """The PlanResult of a planning call begun at `started` (time.perf_counter()), from its stages' results:
    Level 1's candidates, figures and reasons, then `reasons` (the planner's own), then Level 2's; `plan` as
    (actions, level, predicted states), None: no plan; the kinematic check's `rejected` and `refinements`."""
    result = PlanResult(method, None, candidates=[] if level1 is None else level1.candidates,
                        search=None if level2 is None else level2.search, timings=dict(clock.seconds),
                        reasons=[*([] if level1 is None else level1.reasons), *reasons,
                                 *([] if level2 is None else level2.reasons)],
                        symbolic_stats={} if level1 is None else level1.symbolic_stats, rejected=rejected,
                        refinements=list(refinements))
    if plan is not None:
        result = take_plan(result, *plan, X_goal)
    result.timings["total"] = time.perf_counter() - started
    return result


__all__: Sequence[str] = ["Candidate", "Clock", "LEVEL1_STAGES", "Level1Result", "Level2Result", "PlanResult",
                          "assemble", "reasons_json", "take_plan"]
