"""The learned models a planner needs, and the models directory layout.

    DIR/symbolic.pt   Symbolic Model (EffectModel, gumbel_sigmoid bottleneck): symbols of X
    DIR/dynamics.pt   Dynamics Model (EffectModel, sigmoid bottleneck): predicted effects
    DIR/domain/       learned symbolic domain (symbolic.build_domain output; operators.json is read)

Only the parts a method uses must exist: continuous search needs dynamics.pt alone; the symbolic
methods need all three. Anything with `symbols(X)` / `predict_effect(X, actions)` works in place of
the trained networks (tests use stubs).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from tamp.errors import UserError
from tamp.planning.verify import DynamicsModel

if TYPE_CHECKING:
    from symbolic import OperatorSet

SYMBOLIC_FILE, DYNAMICS_FILE, DOMAIN_DIR = "symbolic.pt", "dynamics.pt", "domain"
SYMBOLS_FILE = "symbols.json"  # what the Symbolic Model's bits mean (`tamp symbols --json`), optional


def pretrained_dir() -> Path:
    """The paper-scale models shipped inside the package (tamp/pretrained/; PROVENANCE.md says how
    they were made), the default of `tamp demo --models`."""
    return Path(__file__).resolve().parents[1] / "pretrained"


class SymbolModel(Protocol):
    def symbols(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Unary bits (n, d_z) and relation bits (K, n, n) of scene X."""


# seconds per symbolic planner call, by backend: the in-process search's safety net behind its state budget;
#   Fast Downward has no such budget, and translating a large learned domain takes longer from 4 blocks on
SYMBOLIC_TIME_LIMIT_S = {"python": 10.0, "fd": 120.0, "fd-naive": 120.0}


@dataclass
class Models:
    dynamics: DynamicsModel | None
    symbolic: SymbolModel | None = None
    domain: OperatorSet | None = None
    planners: dict = field(default_factory=dict)  # SymbolicPlanner per backend, reused

    def symbolic_planner(self, backend: str = "python"):
        """A SymbolicPlanner over `domain`, built once (it caches ground tasks per object count), with the
        backend's time limit per call (`SYMBOLIC_TIME_LIMIT_S`)."""
        from symbolic import SymbolicPlanner

        if self.symbolic is None or self.domain is None:
            raise UserError("the symbolic level needs a Symbolic Model and a learned domain "
                             f"({SYMBOLIC_FILE} and {DOMAIN_DIR}/ in the models directory)")
        if backend not in self.planners:
            self.planners[backend] = SymbolicPlanner(self.domain, backend=backend,
                                                     time_limit=SYMBOLIC_TIME_LIMIT_S[backend])
        return self.planners[backend]

    @property
    def n_max(self) -> int | None:
        """The most objects the loaded networks take (None for models without a config, e.g. stubs)."""
        limits = [getattr(getattr(m, "config", None), "n_max", None) for m in (self.dynamics, self.symbolic)]
        known: list[int] = [n for n in limits if n is not None]
        return min(known) if known else None

    def require_objects(self, n: int, what: str) -> None:
        """UserError if `what` (a problem, a scene) has more objects than the networks take."""
        if self.n_max is not None and n > self.n_max:
            raise UserError(f"{what} has {n} objects, but the models were trained for at most {self.n_max}")

    def require_dynamics(self) -> DynamicsModel:
        if self.dynamics is None:
            raise UserError(f"this method needs the Dynamics Model ({DYNAMICS_FILE} in the models directory)")
        return self.dynamics


def require_kind(model, kind: str, path: str | Path) -> None:
    """Refuse a network of the other kind: a Symbolic Model has the binary gumbel_sigmoid bottleneck
    (`tamp train --bottleneck gumbel_sigmoid`), a Dynamics Model any other (the default sigmoid). The
    Fig. 4 variants, which swap them on purpose, are loaded without this check (evaluation.methods)."""
    activation = getattr(getattr(model, "config", None), "activation", None)
    if activation is None:  # not a trained network (a stub): nothing to check
        return
    if kind == "symbolic" and activation != "gumbel_sigmoid":
        raise UserError(f"{path}: a Dynamics Model ({activation} bottleneck), but a Symbolic Model is needed "
                         "(tamp train --bottleneck gumbel_sigmoid)")
    if kind == "dynamics" and activation == "gumbel_sigmoid":
        raise UserError(f"{path}: a Symbolic Model (gumbel_sigmoid bottleneck), but a Dynamics Model is needed "
                         "(tamp train --bottleneck sigmoid)")


def load_bit_names(directory: str | Path):
    """The names of the Symbolic Model's bits from DIR/symbols.json (`tamp symbols --json`; bits
    without a strong meaning keep their raw names); raw names only when the file is absent. A file
    that cannot be read is a UserError naming it."""
    from learned.interpret import BitNames, read_symbols

    path = Path(directory) / SYMBOLS_FILE
    return BitNames.from_report(read_symbols(path)) if path.is_file() else BitNames.none()


def load_models(directory: str | Path, need_symbolic: bool | None = True) -> Models:
    """Load DIR/dynamics.pt, and unless `need_symbolic` is False DIR/symbolic.pt and DIR/domain/
    (None: when both are there; the continuous search needs neither, the per-step view reads symbols).

    Checks that the Symbolic Model's symbol sizes (d_z, K) match the domain's, and that the symbolic search
    takes the domain's operators (`symbolic.lifted.max_arity`); errors name the file.
    """
    import learned
    import symbolic

    directory = Path(directory)
    if not directory.is_dir():
        raise UserError(f"no models directory at {directory} (expected {SYMBOLIC_FILE}, "
                                f"{DYNAMICS_FILE} and {DOMAIN_DIR}/ in it)")
    paths = {"dynamics": directory / DYNAMICS_FILE, "symbolic": directory / SYMBOLIC_FILE,
             "domain": symbolic.operators_file(directory / DOMAIN_DIR)}
    if need_symbolic is None:
        need_symbolic = paths["symbolic"].is_file() and paths["domain"].is_file()
    wanted = ("dynamics", "symbolic", "domain") if need_symbolic else ("dynamics",)
    missing = [str(paths[w]) for w in wanted if not paths[w].is_file()]
    if missing:
        raise UserError(f"missing model file(s): {', '.join(missing)}")
    from learned.ensemble import load_dynamics

    models = Models(load_dynamics(paths["dynamics"]))
    require_kind(models.dynamics, "dynamics", paths["dynamics"])
    if need_symbolic:
        models.symbolic = learned.load_model(paths["symbolic"])
        require_kind(models.symbolic, "symbolic", paths["symbolic"])
        models.domain = symbolic.load_domain(directory / DOMAIN_DIR)
        cfg = models.symbolic.config
        if (cfg.n_unary, cfg.heads) != (models.domain.n_unary, models.domain.n_relations):
            raise UserError(f"{paths['symbolic']} has {cfg.n_unary} unary symbol(s), K={cfg.heads} but the domain in "
                             f"{paths['domain'].parent} was learned with d_z={models.domain.n_unary}, "
                             f"K={models.domain.n_relations}")
        from symbolic.lifted import max_arity

        largest = max((op.arity for op in models.domain.operators), default=0)
        limit = max_arity(cfg.n_unary, cfg.heads, given_diagonal=cfg.relations == "pairwise")
        if largest > limit:  # the lifted search (Level 1, the per-step records) would refuse every problem
            raise UserError(f"{paths['domain']} has operators of arity {largest}, but the symbolic search takes at "
                            f"most {limit} with {cfg.n_unary} unary symbol(s), K={cfg.heads}: learn the domain again "
                            "with `tamp domain` (its --max-arity keeps to the limit by default)")
    return models
