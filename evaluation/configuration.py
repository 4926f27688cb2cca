"""How `tamp evaluate` runs: `EvalConfig`, the planner's configuration and how plans are executed."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from tamp.app.faults import Faults
from tamp.app.parallel import BACKENDS
from tamp.app.settings import EvaluationSettings, Settings, settings_record
from tamp.errors import UserError
from tamp.planning.config import PlanConfig
from tamp.sim.perception_config import PerceptionConfig
from tamp.sim.world_types import fidelity_of


@dataclass(frozen=True)
class EvalConfig:
    """How to evaluate: the planner's configuration (`tamp plan` and `tamp demo` use the same one; its
    seed is each problem's, its feasibility each method's) and how plans are executed."""

    planner: PlanConfig = PlanConfig()
    fidelity: str = "fast"  # execution: "fast" (refinement's world) or "full" (arm under physics)
    oracle_max_plans: int = EvaluationSettings.oracle_max_plans  # the configuration's evaluation.oracle_max_plans
    workers: int = 1  # worker processes or Ray actors
    backend: str = "local"  # "local" process pool or "ray"
    address: str | None = None  # with backend "ray": the cluster to join (None: start a local one)
    progress: bool = True  # progress bar on stderr
    faults: Faults = Faults()  # closed loops: observation noise and a push (`tamp.app.faults`); none by default
    perception: PerceptionConfig = PerceptionConfig()  # what the closed loops observe: the truth or the cameras

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
        """What rows depend on (a results directory holds rows of one configuration only): the resolved
        configuration (`tamp config show`), the execution's fidelity and the faults."""
        settings = Settings(self.planner, EvaluationSettings(self.oracle_max_plans), self.perception)
        return {**settings_record(settings), "fidelity": self.fidelity,
                "faults": {"noise_m": self.faults.noise_m, "push_m": self.faults.push_m}}

    def plan_config(self, seed: int, feasibility: bool = True) -> PlanConfig:
        """The planner's configuration for one problem and method: the problem's seed, kinematics in the loop
        where the method has them (`Method.feasibility`) and the configuration does not turn them off."""
        p = self.planner.with_seed(seed)
        on = feasibility and p.kinematics.feasibility
        return dataclasses.replace(p, kinematics=dataclasses.replace(p.kinematics, feasibility=on))


__all__ = ["EvalConfig"]
