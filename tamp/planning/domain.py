"""From a trained Symbolic Model and interaction data to a learned symbolic domain.

The model's bottleneck gives unary and relation bits for the states before and after every
transition; `symbolic.build_domain` turns those into lifted operators (deterministic and
probabilistic) and writes domain.pddl, domain.ppddl, operators.json and stats.json.
"""
from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from guarded import atomic_write_text
from tamp.errors import UserError


def learn_domain(model_path: str | Path, data_dir: "str | Path | Sequence[str | Path]", out_dir: str | Path,
                 holdout: float = 0.1, seed: int = 0, sampled_domains: int = 0, skip_corrupt: bool = True,
                 involved_only: bool = False, min_count: int = 0, min_prob: float = 0.0,
                 only_moved: bool = False, any_bottleneck: bool = False, max_arity: int | None = None,
                 core_from_all: bool = False, general_bystanders: bool = False) -> dict:
    """Write the learned domain of `model_path` on the transitions in `data_dir` (a dataset directory, or
    several learned from together: `learned.load_transitions`); returns stats.
    `only_moved`: learn from the transitions that moved their picked block alone (as the paper's
    authors do), so that failed grasps and blocked motions are not among the operators' outcomes.
    `any_bottleneck`: accept a model that is not a Symbolic Model (the Fig. 4 Sigmoid variant).
    `max_arity`: learn no operator from transitions that involve more objects (default: the most the
    lifted search takes, `symbolic.build_domain`). `general_bystanders`: operators that do not test
    their bystanders' own bits when a transition left them alone (`symbolic.operators`)."""
    import learned
    import symbolic

    if not 0.0 <= holdout < 1.0:
        raise UserError(f"holdout must be in [0, 1), got {holdout}")
    from tamp.planning.models import require_kind

    model = learned.load_model(model_path)
    if not any_bottleneck:
        require_kind(model, "symbolic", model_path)
    data = learned.load_transitions(data_dir, skip_corrupt=skip_corrupt)
    source = str(data_dir) if isinstance(data_dir, (str, Path)) else ", ".join(map(str, data_dir))  # for messages
    if only_moved:
        data = data.subset(np.flatnonzero(learned.moved_picks(data.X, data.X_next, data.action)))
    if len(data) == 0:
        raise UserError(f"{source}: the dataset holds no transitions" + (" that moved their picked block"
                                                                          if only_moved else ""))
    if data.X.shape[1] > model.config.n_max:
        raise UserError(f"{source}: scenes of up to {data.X.shape[1]} objects, but the model takes "
                         f"at most {model.config.n_max}")
    u_pre, r_pre = model.symbols_batch(data.X, data.mask)
    u_post, r_post = model.symbols_batch(data.X_next, data.mask)
    report = symbolic.build_domain(u_pre, r_pre, np.asarray(data.action), u_post, r_post, np.asarray(data.n),
                                   out_dir, holdout=holdout, seed=seed, sampled_domains=sampled_domains,
                                   involved_only=involved_only, min_count=min_count, min_prob=min_prob,
                                   max_arity=max_arity, core_from_all=core_from_all,
                                   general_bystanders=general_bystanders)
    report["model"] = str(model_path)
    report["data"] = source
    report["transitions"] = int(len(data))
    report["only_moved"] = only_moved
    return report


def export_pddl(models_dir: str | Path, out_dir: str | Path, X_init: np.ndarray | None = None,
                X_goal: np.ndarray | None = None, problem_name: str = "symbolic-task", sampled: int = 0,
                seed: int = 0) -> dict[str, Path]:
    """Write a models directory's learned domain as PDDL files other planners read: domain.pddl (most
    frequent effects), domain.ppddl (the effect distributions), with a scene pair (X_init, X_goal) its
    problem.pddl (Sigma_init and Sigma_goal from the Symbolic Model), and with `sampled` = N the
    distinct domains of N samples (seed `seed`, as the planner draws them) in sampled/."""
    import symbolic
    from tamp.planning.models import DOMAIN_DIR, load_models

    models_dir, out = Path(models_dir), Path(out_dir)
    if not symbolic.operators_file(models_dir / DOMAIN_DIR).is_file():
        raise UserError(f"no learned domain at {symbolic.operators_file(models_dir / DOMAIN_DIR)}")
    ops = symbolic.load_domain(models_dir / DOMAIN_DIR)
    paths = symbolic.write_domains(ops, out)
    if X_init is not None and X_goal is not None:
        models = load_models(models_dir)
        assert models.symbolic is not None  # load_models with need_symbolic
        models.require_objects(len(X_init), "the problem")
        problem = symbolic.make_problem(*models.symbolic.symbols(X_init), *models.symbolic.symbols(X_goal))
        paths["problem"] = out / "problem.pddl"
        atomic_write_text(paths["problem"], symbolic.problem_pddl(ops, problem, name=problem_name))
    if sampled > 0:
        written = symbolic.write_sampled_domains(ops, out / "sampled", sampled, seed)
        paths["sampled"] = written[0][0].parent
    return paths
