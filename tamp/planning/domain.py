"""From a trained Symbolic Model and interaction data to a learned symbolic domain.

The model's bottleneck gives unary and relation bits for the states before and after every
transition; `symbolic.build_domain` turns those into lifted operators (deterministic and
probabilistic) and writes domain.pddl, domain.ppddl, operators.json and stats.json.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tamp.errors import UserError


def learn_domain(model_path: str | Path, data_dir: str | Path, out_dir: str | Path, holdout: float = 0.1,
                 seed: int = 0, sampled_domains: int = 0, skip_corrupt: bool = True,
                 involved_only: bool = False, min_count: int = 0, min_prob: float = 0.0,
                 only_moved: bool = False, any_bottleneck: bool = False) -> dict:
    """Write the learned domain of `model_path` on the transitions in `data_dir`; returns stats.
    `only_moved`: learn from the transitions that moved their picked block alone (as the paper's
    authors do), so that failed grasps and blocked motions are not among the operators' outcomes.
    `any_bottleneck`: accept a model that is not a Symbolic Model (the Fig. 4 Sigmoid variant)."""
    import learned
    import symbolic

    if not 0.0 <= holdout < 1.0:
        raise UserError(f"holdout must be in [0, 1), got {holdout}")
    from tamp.planning.models import require_kind

    model = learned.load_model(model_path)
    if not any_bottleneck:
        require_kind(model, "symbolic", model_path)
    data = learned.load_transitions(data_dir, skip_corrupt=skip_corrupt)
    if only_moved:
        data = data.subset(np.flatnonzero(learned.moved_picks(data.X, data.X_next, data.action)))
    if len(data) == 0:
        raise UserError(f"{data_dir}: the dataset holds no transitions" + (" that moved their picked block"
                                                                          if only_moved else ""))
    if data.X.shape[1] > model.config.n_max:
        raise UserError(f"{data_dir}: scenes of up to {data.X.shape[1]} objects, but the model takes "
                         f"at most {model.config.n_max}")
    u_pre, r_pre = model.symbols_batch(data.X, data.mask)
    u_post, r_post = model.symbols_batch(data.X_next, data.mask)
    report = symbolic.build_domain(u_pre, r_pre, np.asarray(data.action), u_post, r_post, np.asarray(data.n),
                                   out_dir, holdout=holdout, seed=seed, sampled_domains=sampled_domains,
                                   involved_only=involved_only, min_count=min_count, min_prob=min_prob)
    report["model"] = str(model_path)
    report["data"] = str(data_dir)
    report["transitions"] = int(len(data))
    report["only_moved"] = only_moved
    return report
