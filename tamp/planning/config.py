"""The planner's configuration: one small frozen struct per concern, composed into `PlanConfig`.

    PlanConfig(level1=Level1Config(seed=7), kinematics=KinematicsConfig(feasibility=False))

Each stage receives its own part and `VerifyConfig`, what counts as the goal (the one owner of the
tolerances every stage tests against: tau, eps, a confident goal state, a misplaced block); only the
planners that compose the stages (`tamp.planning.bilevel`, `.methods`, `.closed_loop`) hold the whole.

Each option's comment says what it does and why its default, in a line; the measurements behind the
defaults are in docs/beyond-the-paper.md and BUILD_NOTES.md. `tamp plan`, `tamp demo` and `tamp
evaluate` take their flags from these fields (`tamp.app.planner_flags.PLANNER_FLAGS`; a test checks
that every field has a flag or is listed as not exposed, and that the defaults agree).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

from tamp.errors import UserError
from tamp.planning.search import SearchConfig
from tamp.planning.verify import EPS_SUCCESS, VerifyConfig

# the symbolic planners of Level 1, by name, and what each is (the flags' help is built from it)
SYMBOLIC_BACKENDS = {"python": "in-process search, the fastest", "fd": "Fast Downward, as in the paper",
                     "fd-naive": "one Fast Downward driver call per sampled domain"}


def _positive(owner: str, **values: float | None) -> None:
    """UserError unless each value is positive (None allowed: the option is off)."""
    for name, value in values.items():
        if value is not None and not value > 0:
            raise UserError(f"{owner}.{name} must be positive, got {value}")


@dataclass(frozen=True)
class Level1Config:
    """Level 1 (Algorithm 1, lines 4-14): symbolic planning over N sampled domains, then verification.

    The fields from `alternatives` on are our extensions (bilevel only; `bilevel_alg1` turns them off,
    the unverified baselines never use them); docs/beyond-the-paper.md measures each."""

    n_domains: int = 100  # N sampled PDDL domains (the paper's N)
    seed: int = 0  # seed of the sampled domains; callers set the problem's
    backend: str = "python"  # symbolic planner, one of SYMBOLIC_BACKENDS: in-process is fastest
    symbolic_time_limit: float = 10.0  # seconds per symbolic planner call: a safety net behind `budget`
    budget: int | None = 100_000  # symbolic states one search for all N domains may generate: deterministic
    time_budget: float | None = None  # seconds for all N symbolic calls (off: it would depend on the machine)
    verify_all: bool = False  # verify every candidate (default: stop at the first verified one, as Alg. 1)
    # verify the ranked plans whose place is final as soon as the search has them, and search on only if none
    # is taken: Alg. 1's plan, found sooner (the candidates then record the part of the ranking searched)
    settle: bool = True
    alternatives: int = 64  # per symbolic plan, verify the best plans of a beam this wide over its skeleton
    alternatives_total: int = 256  # per problem (later symbolic plans are verified alone): bounds the time
    nonempty: bool = True  # X_init not within tau of X_goal: the symbolic plan needs >= 1 action
    focus_from: int | None = 5  # from this many objects on, plans pick up only misplaced blocks (None: never)
    focus_budget: int | None = 25_000  # from focus_from objects on, `budget`'s stand-in: later plans rarely verify
    objects: int | None = 4  # from focus_from on, plan in the goal's sub-scene up to this many objects (training size)
    serial: bool = True  # from focus_from on, with no verified plan, plan one misplaced block at a time
    wait_beyond: float | None = EPS_SUCCESS  # metres: a verified plan predicted this far waits for Level 2 (None: off)
    cut: bool = True  # end a verified plan where it reaches the goal, drop repeated picks (False: paper)

    def __post_init__(self) -> None:
        if self.backend not in SYMBOLIC_BACKENDS:
            raise UserError(f"symbolic backend must be one of {', '.join(SYMBOLIC_BACKENDS)}, got {self.backend!r}")
        _positive("Level1Config", symbolic_time_limit=self.symbolic_time_limit, wait_beyond=self.wait_beyond)
        if self.n_domains < 1:
            raise UserError(f"the number of sampled domains must be at least 1, got {self.n_domains}")
        if self.focus_from is not None and self.focus_from < 1:
            raise UserError(f"Level1Config.focus_from must be a positive object count or None, got {self.focus_from}")
        for name in ("budget", "focus_budget"):
            if getattr(self, name) is not None and getattr(self, name) < 1:
                raise UserError(f"Level1Config.{name} must be a positive number of states or None, "
                                f"got {getattr(self, name)}")
        if self.objects is not None and self.objects < 2:
            raise UserError(f"Level1Config.objects must be at least 2 objects (a block and where it goes) "
                            f"or None, got {self.objects}")

    def focused(self, n_objects: int) -> bool:
        """Whether Level 1 focuses on the blocks off their goal in a scene of `n_objects` blocks."""
        return self.focus_from is not None and n_objects >= self.focus_from

    def budget_for(self, n_objects: int) -> int | None:
        """Level 1's budget (generated symbolic states) in a scene of `n_objects` blocks."""
        if not self.focused(n_objects) or self.focus_budget is None:
            return self.budget
        return min(self.focus_budget, self.budget or self.focus_budget)


@dataclass(frozen=True)
class KinematicsConfig:
    """Kinematics in the planning loop (cfs, bilevel; needs a `kinematics` object passed to `plan`)."""

    feasibility: bool = True  # check actions on the predicted states, refine a plan before returning it
    max_refinements: int = 4  # full refinements per planning call (Level-1 candidates and Level-2 plans): bounds time
    # metres: a predicted block this close to resting on the table or a block is checked resting on it: the checks are
    #   exact to the millimetre and a prediction is not (None: where the prediction puts it; docs/practice-and-doubt.md)
    rest_within: float | None = 0.01


@dataclass(frozen=True)
class LoopConfig:
    """The closed loops (`tamp.planning.closed_loop`): keeping a plan (both), and the loop that does not know k."""

    keep_plan: bool = True  # keep the rest of the last plan while it ends within verify.confident and refines
    on_course: float | None = 0.015  # metres: blocks this close to the plan's prediction: its own prediction
    #   decides, not a rollout that swings under mm changes (3 sigmas of the fragility test's noise; None: rollout)
    # a plan on course whose end is predicted over verify.confident (but within eps) gives way only to one predicted
    #   within verify.confident (False: to any plan predicted closer, which let the loop wander between such plans)
    commit: bool = True
    max_actions: int = 30  # actions sent before the loop gives up: k <= 5 needs 5, the rest is room for detours
    widen: bool = True  # a round without a plan searches again over all 9 n^2 actions (make room, unstack)
    widen_expansions: int = 400  # node budget of the widened search (about 2-4 s at 4 blocks with kinematics)
    search_budget: int = 3000  # search expansions over all rounds: a loop whose rounds keep failing ends in about
    #   the time of two failed searches
    # from search.greedy_from blocks on, the search budget in place of search_budget: there a loop that reaches the
    #   goal spends far fewer expansions (docs/closing-the-loop.md; None: search_budget)
    greedy_search_budget: int | None = 1500
    stall: int | None = 300  # the stall cut of its rounds' searches at any number of blocks (`SearchConfig.stall` and
    #   `.greedy_stall`, which it replaces there; None: the search's own): a round that fails has a widened search and
    #   the next round behind it
    progress: float = 0.02  # metres, summed over blocks: without a plan, a step toward the closest state the round's
    #   searches expanded is taken only if that state is this much closer to the goal
    revisit: float = 0.01  # metres: back this close to an observed state, leave out the actions taken from there
    # metres: an action that lands this far from its prediction, alike `remember_alike` times, is predicted for the
    #   rest of the loop as the world did it, from states whose deciding blocks lie this close (`experience`; None: off)
    remember: float | None = 0.02
    remember_alike: int = 2  # misses alike before one is trusted: one outcome may be scatter (a yaw X does not hold)
    stop_margin: float = 0.0  # metres: the loop that does not know k stops this far inside eps; short of that but
    #   within eps it steps only on a plan predicted within confident (0: exact observations; `--noise` sets sigma)
    # times the loop that does not know k observes the scene again after a round without a plan, before it stops: a
    #   noisy observation may put neighbours into each other where the next one does not (0: exact observations, where
    #   a second look sees the same; `--noise` sets 2)
    looks: int = 0

    def __post_init__(self) -> None:
        _positive("LoopConfig", on_course=self.on_course, remember=self.remember)
        if not self.revisit >= 0 or not self.progress >= 0 or not self.stop_margin >= 0:
            raise UserError(f"LoopConfig.revisit, .progress and .stop_margin must be distances of 0 m or more, got "
                            f"{self.revisit}, {self.progress} and {self.stop_margin}")
        if self.stall is not None and self.stall < 1:
            raise UserError(f"LoopConfig.stall must be a positive number of expansions or None, got {self.stall}")
        if self.greedy_search_budget is not None and self.greedy_search_budget < 1:
            raise UserError(f"LoopConfig.greedy_search_budget must be a positive number of expansions or None, got "
                            f"{self.greedy_search_budget}")
        if self.looks < 0:
            raise UserError(f"LoopConfig.looks must be 0 or more, got {self.looks}")
        if self.remember_alike < 1:
            raise UserError(f"LoopConfig.remember_alike must be 1 or more, got {self.remember_alike}")
        if self.max_actions < 1 or self.widen_expansions < 1 or self.search_budget < 1:
            raise UserError(f"the closed loop needs at least 1 action and 1 expansion of its searches, got "
                            f"{self.max_actions} actions, {self.widen_expansions} expansions widened and a search "
                            f"budget of {self.search_budget}")

    def search_budget_for(self, n_objects: int, greedy_from: int | None) -> int:
        """The loop's search budget (expansions over all rounds) in a scene of `n_objects` blocks, the search
        greedy from `greedy_from` blocks on (`SearchConfig.greedy_from`)."""
        greedy = greedy_from is not None and n_objects >= greedy_from
        return self.greedy_search_budget if greedy and self.greedy_search_budget is not None else self.search_budget


@dataclass(frozen=True)
class PlanConfig:
    """The planner's settings, one configuration for `tamp plan`, `tamp demo` and `tamp evaluate`."""

    level1: Level1Config = Level1Config()
    verify: VerifyConfig = VerifyConfig()
    search: SearchConfig = SearchConfig()  # Level 2, the continuous search (`tamp.planning.search`)
    kinematics: KinematicsConfig = KinematicsConfig()
    loop: LoopConfig = LoopConfig()

    def __post_init__(self) -> None:
        if not self.loop.stop_margin < min(self.verify.eps, self.verify.misplaced):
            raise UserError(f"the closed loop's stop margin ({self.loop.stop_margin} m) must be below the success "
                            f"tolerance eps ({self.verify.eps} m)")

    def with_seed(self, seed: int) -> PlanConfig:
        """This configuration with Level 1's domains sampled from `seed` (callers give the problem's)."""
        return replace(self, level1=replace(self.level1, seed=seed))


__all__ = ["KinematicsConfig", "Level1Config", "LoopConfig", "PlanConfig", "SYMBOLIC_BACKENDS", "VerifyConfig"]
