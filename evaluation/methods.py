"""The methods compared by the evaluation, and the model sets they plan with.

Each method (`METHODS`, each with what it is in `Method.about`; `tamp evaluate --help` lists them) is a
`tamp.planning.planners` planner, a model variant and open or closed loop. `probabilistic_oracle` is the
paper's measure of the probabilistic planner, an EXECUTION ORACLE: the plans of the N sampled domains,
most frequent first, each executed from X_init until one reaches the goal (at most
EvalConfig.oracle_max_plans); no planner could choose this way without the simulator.

`cfs`, `bilevel`, `bilevel_replan` and `bilevel_loop` plan with kinematics in the loop (tamp.sim.kinematic_checker:
actions checked on the predicted states, plans refined before they are returned); `cfs_nofeas`,
`bilevel_nofeas` and `bilevel_replan_nofeas` are the same planners without it (before / after on the
same problems: `tamp evaluate --methods cfs,cfs_nofeas,...`). The symbolic baselines never use it.

The default model set is the models directory (symbolic.pt, dynamics.pt, domain/); the last two
methods use optional variants in DIR/variants/: symbolic_sigmoid.pt with domain_sigmoid/, and
dynamics_gumbel.pt. The symbolic_sigmoid set keeps DIR/dynamics.pt to report its plans'
predicted error.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from symbolic import operators_file
from tamp.errors import UserError
from tamp.planning.models import DOMAIN_DIR, DYNAMICS_FILE, SYMBOLIC_FILE, Models
from tamp.planning.vocabulary import Loop

VARIANTS_DIR = "variants"
SYMBOLIC_SIGMOID, DOMAIN_SIGMOID, DYNAMICS_GUMBEL = "symbolic_sigmoid.pt", "domain_sigmoid", "dynamics_gumbel.pt"


@dataclass(frozen=True)
class Method:
    name: str
    planner: str  # a tamp.planning.planners.METHODS key
    models: str  # model set: "default" | "symbolic_sigmoid" | "dynamics_gumbel"
    loop: Loop | None = None  # closed loop: the paper's k - 1 rounds or until the goal; None: open loop
    oracle: bool = False  # execute the ranked plans until one succeeds (the authors' measure)
    feasibility: bool = False  # kinematic check and refinement in the planning loop (tamp.sim.kinematic_checker)
    about: str = ""  # what it is, in a line (`tamp evaluate --help`)

    @property
    def closed_loop(self) -> bool:
        return self.loop is not None

    @property
    def symbolic(self) -> bool:
        """Whether the method needs a Symbolic Model and a domain."""
        return self.planner != "cfs"


METHODS: dict[str, Method] = {m.name: m for m in (
    Method("deterministic", "deterministic", "default",
           about="the deterministic symbolic planner's plan, unverified (the baseline)"),
    Method("probabilistic", "probabilistic", "default",
           about="the most frequent plan of N sampled domains, unverified"),
    Method("probabilistic_oracle", "probabilistic", "default", oracle=True,
           about="the paper's measure: the sampled domains' plans executed until one succeeds (an oracle)"),
    Method("cfs", "cfs", "default", feasibility=True, about="continuous forward search alone"),
    Method("bilevel", "bilevel", "default", feasibility=True, about="Algorithm 1 with our extensions"),
    Method("bilevel_alg1", "bilevel_alg1", "default", about="the paper's Algorithm 1 exactly"),
    Method("bilevel_replan", "bilevel", "default", loop=Loop.PAPER, feasibility=True,
           about="bilevel in the paper's closed loop of k - 1 replanning rounds"),
    Method("bilevel_loop", "bilevel", "default", loop=Loop.UNTIL_GOAL, feasibility=True,
           about="bilevel in the closed loop that plans again after every action until the goal"),
    Method("symbolic_sigmoid", "deterministic", "symbolic_sigmoid",
           about="the deterministic planner with the Sigmoid Symbolic Model (Fig. 4; DIR/variants/)"),
    Method("cfs_gumbel", "cfs", "dynamics_gumbel",
           about="continuous search with the Gumbel-Sigmoid Dynamics Model (Fig. 4; DIR/variants/)"),
    Method("cfs_nofeas", "cfs", "default", about="cfs without kinematics in its planning loop"),
    Method("bilevel_nofeas", "bilevel", "default", about="bilevel without kinematics in its planning loop"),
    Method("bilevel_replan_nofeas", "bilevel", "default", loop=Loop.PAPER,
           about="bilevel_replan without kinematics in its planning loop"),
)}
FEASIBILITY_PAIRS = (("cfs", "cfs_nofeas"), ("bilevel", "bilevel_nofeas"), ("bilevel_replan", "bilevel_replan_nofeas"))
DEFAULT_METHODS = ("deterministic", "probabilistic", "probabilistic_oracle", "cfs", "bilevel", "bilevel_alg1",
                   "bilevel_replan", "bilevel_loop")
VARIANT_METHODS = ("symbolic_sigmoid", "cfs_gumbel")


def methods_help() -> str:
    """Every method in a line each, the defaults marked: `tamp evaluate --help` lists them from METHODS."""
    return "; ".join(f"{m.name}{' (default)' if m.name in DEFAULT_METHODS else ''}: {m.about}"
                     for m in METHODS.values())


def required_files(models_dir: str | Path, method: str) -> list[Path]:
    """The files a method loads from the models directory (domains: their operators.json)."""
    d = Path(models_dir)
    v = d / VARIANTS_DIR
    m = METHODS[method]
    if m.models == "symbolic_sigmoid":
        return [d / DYNAMICS_FILE, v / SYMBOLIC_SIGMOID, operators_file(v / DOMAIN_SIGMOID)]
    if m.models == "dynamics_gumbel":
        return [v / DYNAMICS_GUMBEL]
    if m.symbolic:
        return [d / DYNAMICS_FILE, d / SYMBOLIC_FILE, operators_file(d / DOMAIN_DIR)]
    return [d / DYNAMICS_FILE]


def default_methods(models_dir: str | Path) -> list[str]:
    """DEFAULT_METHODS, and the variant methods whose files exist in the models directory."""
    return list(DEFAULT_METHODS) + [m for m in VARIANT_METHODS
                                    if all(p.is_file() for p in required_files(models_dir, m))]


def resolve_methods(models_dir: str | Path, methods: Sequence[str] | None = None) -> list[str]:
    """Check the requested methods (default: `default_methods`) and that their files exist.

    Returns them in the report order of METHODS. An unknown method or a missing file is an error
    naming it.
    """
    models_dir = Path(models_dir)
    if not models_dir.is_dir():
        raise UserError(f"no models directory at {models_dir}")
    if methods is None:
        methods = default_methods(models_dir)
    methods = list(methods)
    if not methods:
        raise UserError("no methods to evaluate")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise UserError(f"unknown method {unknown[0]!r}; choose from {', '.join(METHODS)}")
    for m in methods:
        missing = [p for p in required_files(models_dir, m) if not p.is_file()]
        if missing:
            raise UserError(f"method {m} needs {missing[0]}, which does not exist")
    return [m for m in METHODS if m in methods]


def load_method_models(models_dir: str | Path, methods: Sequence[str]) -> dict[str, Models]:
    """Models per method; each model set (and each network file) is loaded once and shared."""
    import learned
    import symbolic

    models_dir = Path(models_dir)
    methods = resolve_methods(models_dir, methods)
    sets: dict[str, Models] = {}
    needed = {METHODS[m].models for m in methods}
    if "default" in needed or "symbolic_sigmoid" in needed:
        from tamp.planning.models import load_models

        needs_symbols = any(METHODS[m].models == "default" and METHODS[m].symbolic for m in methods)
        sets["default"] = load_models(models_dir, need_symbolic=True if needs_symbols else None)
    if "symbolic_sigmoid" in needed:
        path, domain_dir = models_dir / VARIANTS_DIR / SYMBOLIC_SIGMOID, models_dir / VARIANTS_DIR / DOMAIN_SIGMOID
        model, domain = learned.load_model(path), symbolic.load_domain(domain_dir)
        cfg = model.config
        if (cfg.n_unary, cfg.heads) != (domain.n_unary, domain.n_relations):
            raise UserError(f"{path} has {cfg.n_unary} unary symbol(s), K={cfg.heads} but the domain in "
                             f"{domain_dir} was learned with d_z={domain.n_unary}, K={domain.n_relations}")
        sets["symbolic_sigmoid"] = Models(sets["default"].dynamics, model, domain)
    if "dynamics_gumbel" in needed:
        sets["dynamics_gumbel"] = Models(learned.load_model(models_dir / VARIANTS_DIR / DYNAMICS_GUMBEL))
    return {m: sets[METHODS[m].models] for m in methods}
