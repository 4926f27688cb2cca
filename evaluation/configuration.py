"""How `tamp evaluate` runs: `EvalConfig`, the planner's configuration and how plans are executed."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from tamp.app.faults import Faults
from tamp.app.parallel import BACKENDS
from tamp.errors import UserError
from tamp.planning.config import KinematicsConfig, Level1Config, LoopConfig, PlanConfig
from tamp.sim.world_types import fidelity_of

# The loop settings a results directory without a "loop" entry was made with (the defaults when such directories
# were made): any other setting is written out, so that no directory is resumed with settings it was not made with.
IMPLICIT_LOOP = {"max_actions": 12, "widen": True, "widen_expansions": 400, "search_budget": 3000,
                 "greedy_search_budget": 1500, "stall": 300, "progress": 0.02, "revisit": 0.01}


@dataclass(frozen=True)
class EvalConfig:
    """How to evaluate: the planner's configuration (`tamp plan` and `tamp demo` use the same one; its
    seed is each problem's, its feasibility each method's) and how plans are executed."""

    planner: PlanConfig = PlanConfig()
    fidelity: str = "fast"  # execution: "fast" (refinement's world) or "full" (arm under physics)
    oracle_max_plans: int = 20  # probabilistic_oracle: ranked plans executed at most, per problem
    workers: int = 1  # worker processes or Ray actors
    backend: str = "local"  # "local" process pool or "ray"
    address: str | None = None  # with backend "ray": the cluster to join (None: start a local one)
    progress: bool = True  # progress bar on stderr
    faults: Faults = Faults()  # closed loops: observation noise and a push (`tamp.app.faults`); none by default

    def __post_init__(self) -> None:
        fidelity_of(self.fidelity, "--fidelity")
        if self.backend not in BACKENDS:
            raise UserError(f"--backend must be one of {', '.join(BACKENDS)}, got {self.backend!r}")
        for name in ("oracle_max_plans", "workers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise UserError(f"--{name.replace('_', '-')} must be a positive integer, got {value!r}")

    @property
    def eps(self) -> float:
        return self.planner.verify.eps

    @property
    def tau_verify(self) -> float:
        return self.planner.verify.tau_verify

    @property
    def symbolic_backend(self) -> str:
        return self.planner.level1.backend

    def defining(self) -> dict[str, Any]:
        """The settings rows depend on (a results directory holds rows of one setting only)."""
        p = self.planner
        out = {"fidelity": self.fidelity, "eps_m": p.verify.eps, "tau_verify_m": p.verify.tau_verify,
               "n_domains": p.level1.n_domains,
               "search_time_limit_s": p.search.time_limit, "search_max_expansions": p.search.max_expansions,
               "search_stall": p.search.stall,
               "search_confident_m": p.verify.confident, "search_look_on": p.search.look_on,
               "search_release_targets": p.search.release_targets,
               "search_max_fragility": p.search.max_fragility, "search_noise_m": p.search.noise,
               "level1_budget": p.level1.budget, "level1_time_budget_s": p.level1.time_budget,
               "level1_focus_from": p.level1.focus_from, "level1_focus_budget": p.level1.focus_budget,
               "level1_confident_m": p.level1.wait_beyond, "level1_cut": p.level1.cut,
               "level1_objects": p.level1.objects, "level1_serial": p.level1.serial,
               "keep_plan": p.loop.keep_plan, "on_course_m": p.loop.on_course,
               "symbolic_backend": p.level1.backend, "oracle_max_plans": self.oracle_max_plans}
        if p.level1.symbolic_time_limit != Level1Config.symbolic_time_limit:  # older directories stay resumable
            out["symbolic_time_limit_s"] = p.level1.symbolic_time_limit
        if p.level1.settle != Level1Config.settle:
            out["level1_settle"] = p.level1.settle
        if p.kinematics.rest_within != KinematicsConfig.rest_within:
            out["kinematics_rest_within_m"] = p.kinematics.rest_within
        if p.search.max_doubt is not None:
            out["search_max_doubt_m"] = p.search.max_doubt
        if p.search.resolution != 0.01:  # the grid of every directory made before it was a setting
            out["search_resolution_m"] = p.search.resolution
        if p.search.clear_blockers:  # the search of every directory made before it offered goal-oriented actions only
            out["search_clear_blockers"] = True
        if p.search.greedy_from is not None:
            out["search_greedy_from"] = p.search.greedy_from
            out["search_greedy_h_unit_m"] = p.search.greedy_h_unit
            out["search_greedy_per_misplaced"] = p.search.greedy_per_misplaced
            out["search_greedy_stall"] = p.search.greedy_stall
            out["loop_greedy_search_budget"] = p.loop.greedy_search_budget
        if p.loop.commit != LoopConfig.commit:
            out["loop_commit"] = p.loop.commit
        # the loop that does not know k: the same, by the fields other than those recorded above
        above = ("keep_plan", "on_course", "commit")
        # fields added since, left out at the value that plans as the loop did before them (older directories stay
        #   resumable; a directory made before the loop remembered misses is not resumed with it)
        later = {"stop_margin": LoopConfig.stop_margin, "remember": None, "looks": LoopConfig.looks}
        loop = {k: v for k, v in dataclasses.asdict(p.loop).items() if k not in above}
        if p.loop.remember is None:
            del loop["remember_alike"]
        loop = {k: v for k, v in loop.items() if k not in later or v != later[k]}
        if loop != IMPLICIT_LOOP:
            out["loop"] = loop
        if self.faults.any:
            out["faults"] = {"noise_m": self.faults.noise_m, "push_m": self.faults.push_m}
        return out

    def plan_config(self, seed: int, feasibility: bool = True) -> PlanConfig:
        p = self.planner.with_seed(seed)
        return dataclasses.replace(p, kinematics=dataclasses.replace(p.kinematics, feasibility=feasibility))


__all__ = ["EvalConfig", "IMPLICIT_LOOP"]
