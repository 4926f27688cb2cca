"""The planner's configuration: one small frozen struct per concern, composed into `PlanConfig`.

    PlanConfig(level1=Level1Config(seed=7), kinematics=KinematicsConfig(feasibility=False))

Each stage receives its own part and `VerifyConfig`, what counts as the goal (the one owner of the
tolerances every stage tests against: tau, eps, a confident goal state, a misplaced block); only the
planners that compose the stages (`tamp.planning.bilevel`, `.planners`, `.closed_loop`) hold the whole.

A configuration is data: `tamp config show` prints it as TOML, each field with the one-line comment it
has here (what it does and why its default), and `--config FILE` / `--preset NAME` read it back
(`tamp.app.settings`). The shipped presets are files in tamp/presets/: `default` (these defaults) and
`paper` (the paper's Algorithm 1, what `bilevel_alg1` plans with: `paper_config`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cache
from pathlib import Path
from typing import Any

from guarded.config import build, read_toml
from tamp.errors import UserError
from tamp.inputs import MAX_DOMAINS
from tamp.planning.search import SearchConfig
from tamp.planning.verify import EPS_SUCCESS, VerifyConfig

# the symbolic planners of Level 1, by name, and what each is (the flags' help is built from it)
SYMBOLIC_BACKENDS = {"python": "in-process search, the fastest", "fd": "Fast Downward, as in the paper",
                     "fd-naive": "one Fast Downward driver call per sampled domain"}


def symbolic_backend_help(default: str) -> str:
    """The help of a --symbolic-backend flag, from the registry of symbolic planners."""
    return "symbolic planner: " + ", ".join(f"{name} ({what}{', default' if name == default else ''})"
                                            for name, what in SYMBOLIC_BACKENDS.items())


PRESETS_DIR = Path(__file__).resolve().parents[1] / "presets"  # NAME.toml: the shipped presets

SUBSCENE_OBJECTS = 4  # from focus_from on, Level 1 plans in the goal's sub-scene of at most this many objects
#   (the Symbolic Model's training size; more: one block at a time, `Level1Config.serial`)
GREEDY_SEARCH_BUDGET = 1500  # the closed loop's search budget from search.greedy_from blocks on: a plan comes soon


def _positive(owner: str, **values: float | None) -> None:
    """UserError unless each value is positive (None allowed: the option is off)."""
    for name, value in values.items():
        if value is not None and not value > 0:
            raise UserError(f"{owner}.{name} must be positive, got {value}")


@dataclass(frozen=True)
class Level1Config:
    """Level 1 (Algorithm 1, lines 4-14): symbolic planning over N sampled domains, then verification.

    The fields from `focus_from` on are our extensions (bilevel only; the `paper` preset turns them off, the
    unverified baselines never use them); docs/beyond-the-paper.md describes each."""

    n_domains: int = 100  # N sampled PDDL domains (the paper's N)
    seed: int = 0  # seed of the sampled domains; callers set the problem's
    backend: str = "python"  # symbolic planner: python (in-process, fastest), fd (Fast Downward), fd-naive
    budget: int | None = 25_000  # symbolic states one search for all N domains may generate: later plans rarely verify
    focus_from: int | None = 5  # from this many objects on, plans pick up only misplaced blocks
    serial: bool = True  # from focus_from on, with no verified plan, plan one misplaced block at a time
    wait_beyond: float | None = EPS_SUCCESS  # metres: a verified plan predicted this far waits for Level 2

    def __post_init__(self) -> None:
        if self.backend not in SYMBOLIC_BACKENDS:
            raise UserError(f"symbolic backend must be one of {', '.join(SYMBOLIC_BACKENDS)}, got {self.backend!r}")
        _positive("Level1Config", wait_beyond=self.wait_beyond)
        if not 1 <= self.n_domains <= MAX_DOMAINS:  # each draws an effect per operator: (N, operators) in memory
            raise UserError(f"level1.n_domains, the number of sampled domains, must be in 1..{MAX_DOMAINS:,}, "
                            f"got {self.n_domains}")
        if self.focus_from is not None and self.focus_from < 1:
            raise UserError(f"Level1Config.focus_from must be a positive object count or None, got {self.focus_from}")
        if self.budget is not None and self.budget < 1:
            raise UserError(f"Level1Config.budget must be a positive number of states or None, got {self.budget}")

    def focused(self, n_objects: int) -> bool:
        """Whether Level 1 focuses on the blocks off their goal in a scene of `n_objects` blocks."""
        return self.focus_from is not None and n_objects >= self.focus_from

    def scene_sizes(self, n_objects: int) -> tuple[int, ...]:
        """The object counts of the scenes Level 1 may plan in, in a scene of `n_objects` blocks: the whole scene's,
        and when focused its sub-scenes' (`level1.level1_scene`). The symbolic planner builds its task once per
        count (0.3-1 s each), a one-off cost that a benchmark pays before timing."""
        subscenes = range(1, min(n_objects, SUBSCENE_OBJECTS) + 1) if self.focused(n_objects) else ()
        return tuple(sorted({n_objects, *subscenes}))


@dataclass(frozen=True)
class KinematicsConfig:
    """Kinematics in the planning loop (cfs, bilevel; needs a `kinematics` object passed to `plan`)."""

    feasibility: bool = True  # check actions on the predicted states, refine a plan before returning it
    max_refinements: int = 4  # full refinements per planning call (Level-1 and Level-2 plans): bounds time

    def __post_init__(self) -> None:
        if self.max_refinements < 1:
            raise UserError(f"KinematicsConfig.max_refinements must be at least 1, got {self.max_refinements}")


@dataclass(frozen=True)
class LoopConfig:
    """The closed loops (`tamp.planning.closed_loop`): keeping a plan (both), and the loop that does not know k."""

    keep_plan: bool = True  # keep the rest of the last plan while it ends within verify.confident and refines
    commit: bool = True  # a kept plan short of confident gives way only to a plan predicted within confident
    max_actions: int = 30  # actions sent before the loop gives up: k <= 5 needs 5, the rest is room for detours
    widen: bool = True  # a round without a plan searches again over all 9 n^2 actions (make room, unstack)
    search_budget: int = 3000  # search expansions over all rounds: a failing loop ends in about two searches' time
    stall: int | None = 300  # the stall cut of its rounds' searches, in place of search.stall and .greedy_stall
    stop_margin: float | None = None  # metres inside eps the loop stops (false: 1 sigma of the observation noise)
    looks: int | None = None  # observations again after a round without a plan (false: 2 under noise, else 0)

    def __post_init__(self) -> None:
        if not self.margin >= 0:
            raise UserError(f"LoopConfig.stop_margin must be a distance of 0 m or more, got {self.stop_margin}")
        if self.stall is not None and self.stall < 1:
            raise UserError(f"LoopConfig.stall must be a positive number of expansions or None, got {self.stall}")
        if self.looks_again < 0:
            raise UserError(f"LoopConfig.looks must be 0 or more, got {self.looks}")
        if self.max_actions < 1 or self.search_budget < 1:
            raise UserError(f"the closed loop needs at least 1 action and 1 expansion of its searches, got "
                            f"{self.max_actions} actions and a search budget of {self.search_budget}")

    @property
    def margin(self) -> float:
        """Metres inside eps the loop stops (0 when `stop_margin` was left to the noise and none is known)."""
        return self.stop_margin or 0.0

    @property
    def looks_again(self) -> int:
        """Times the loop observes again after a round without a plan (`looks`, 0 when left to the noise)."""
        return self.looks or 0

    def search_budget_for(self, n_objects: int, greedy_from: int | None) -> int:
        """The loop's search budget (expansions over all rounds) in a scene of `n_objects` blocks, the search
        greedy from `greedy_from` blocks on (`SearchConfig.greedy_from`)."""
        greedy = greedy_from is not None and n_objects >= greedy_from
        return min(GREEDY_SEARCH_BUDGET, self.search_budget) if greedy else self.search_budget


@dataclass(frozen=True)
class PlanConfig:
    """The planner's settings, one configuration for `tamp plan`, `tamp demo` and `tamp evaluate`."""

    level1: Level1Config = Level1Config()
    verify: VerifyConfig = VerifyConfig()
    search: SearchConfig = SearchConfig()  # Level 2, the continuous search (`tamp.planning.search`)
    kinematics: KinematicsConfig = KinematicsConfig()
    loop: LoopConfig = LoopConfig()

    def __post_init__(self) -> None:
        if not self.loop.margin < min(self.verify.eps, self.verify.misplaced):
            raise UserError(f"the closed loop's stop margin ({self.loop.margin} m) must be below the success "
                            f"tolerance eps ({self.verify.eps} m)")

    def with_seed(self, seed: int) -> PlanConfig:
        """This configuration with Level 1's domains sampled from `seed` (callers give the problem's)."""
        return replace(self, level1=replace(self.level1, seed=seed))


PLAN_SECTIONS = ("level1", "verify", "search", "kinematics", "loop")  # PlanConfig's parts: the file's tables


def preset_path(name: str) -> Path:
    """The file of the shipped preset `name` (UserError naming the presets when there is none)."""
    path = PRESETS_DIR / f"{name}.toml"
    if not path.is_file():
        raise UserError(f"no preset {name!r}; the presets are {', '.join(presets())}")
    return path


def presets() -> list[str]:
    """The names of the shipped presets."""
    return sorted(p.stem for p in PRESETS_DIR.glob("*.toml"))


def overlay(cfg: PlanConfig, table: dict[str, Any], where: str, also: tuple[str, ...] = ()) -> PlanConfig:
    """`cfg` with the planner's keys of a configuration table over it (keys in `also` are someone else's)."""
    return build(PlanConfig, table, where, base=cfg, also=also)


@cache
def _preset_table(name: str) -> dict[str, Any]:
    return read_toml(preset_path(name), "preset")


def paper_config(cfg: PlanConfig) -> PlanConfig:
    """`cfg` as the paper's Algorithm 1 plans (`bilevel_alg1`): the `paper` preset's settings over it."""
    return overlay(cfg, _preset_table("paper"), str(preset_path("paper")), also=("evaluation", "perception"))


__all__ = ["KinematicsConfig", "Level1Config", "LoopConfig", "PLAN_SECTIONS", "PlanConfig", "SYMBOLIC_BACKENDS",
           "VerifyConfig", "overlay", "paper_config", "preset_path", "presets", "symbolic_backend_help"]
