"""Table I of the paper: effect-prediction error per bottleneck activation over several runs.

One held-out test split (fixed by ``seed``) is shared by every run; each run r trains a fresh
model per activation (seed + r, which also draws the validation split from the remaining data),
keeps its best-by-validation weights, and reports the mean effect error (cm) on the test split.
"""
from __future__ import annotations

import json
import platform
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .dataset import Transitions, load_transitions
from .model import ACTIVATIONS, ModelConfig
from .train import TrainConfig, evaluate, split_indices, train_model

LABELS = {"gumbel_sigmoid": "Gumbel-Sigmoid", "tanh": "Tanh", "none": "No activation",
          "sigmoid": "Sigmoid"}
PAPER_ORDER = ("gumbel_sigmoid", "tanh", "none", "sigmoid")


def ablate_activations(data: "str | Path | Transitions", runs: int = 10, *,
                       activations: Sequence[str] = PAPER_ORDER, train: TrainConfig | None = None,
                       config: ModelConfig | None = None, test_fraction: float = 0.2,
                       out_dir: str | Path | None = None, progress: bool = True) -> dict[str, Any]:
    """Train ``runs`` models per activation; mean +- std (sample std) test effect error in cm.

    Run r trains with `train` (default `TrainConfig()`, the paper's settings) at seed `train.seed + r`,
    validating on its own `train.val_fraction` split of what the test split leaves. With
    ``out_dir``, the per-run best checkpoints go to ``out_dir/models/`` and the report is written by
    ``write_ablation_report``.
    """
    train = train or TrainConfig()
    seed = train.seed
    if train.threads:
        torch.set_num_threads(train.threads)
    for a in activations:
        if a not in ACTIVATIONS:
            raise ValueError(f"activation {a!r} not in {ACTIVATIONS}")
    source = str(data) if not isinstance(data, Transitions) else "<in-memory>"
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    rest_idx, test_idx = split_indices(len(data), (test_fraction,), seed)
    rest, test = data.subset(rest_idx), data.subset(test_idx)
    base = config or ModelConfig(n_max=data.n_max)
    per_act: dict[str, dict[str, Any]] = {}
    zero_cm = None
    for act in activations:
        errs, val_errs = [], []
        for r in range(runs):
            tr_idx, va_idx = split_indices(len(rest), (train.val_fraction,), seed + r)
            out = (Path(out_dir) / "models" / f"{act}-run{r}.pt") if out_dir else None
            if out:
                out.parent.mkdir(parents=True, exist_ok=True)
            res = train_model(rest.subset(tr_idx), replace(base, activation=act), replace(train, seed=seed + r),
                              out, val_data=rest.subset(va_idx), progress=progress)
            ev = evaluate(res.model, test)
            errs.append(ev["err_cm"])
            val_errs.append(res.best_val_cm)
            zero_cm = ev["zero_cm"]
        per_act[act] = {"label": LABELS[act], "mean_cm": float(np.mean(errs)),
                        "std_cm": float(np.std(errs, ddof=1)) if runs > 1 else 0.0,
                        "runs_cm": errs, "val_cm": val_errs}
    results = {"source": source, "runs": runs, "epochs": train.epochs, "max_steps": train.max_steps,
               "seed": seed, "num_train_val": len(rest), "num_test": len(test),
               "zero_effect_cm": zero_cm, "config": base.to_dict(),
               "training": {"batch_size": train.batch_size, "lr": train.lr, "val_fraction": train.val_fraction,
                            **({"precision": train.precision} if train.precision != "float32" else {}),
                            **({"patience_epochs": train.patience_epochs} if train.patience_epochs else {})},
               "machine": {"python": platform.python_version(), "torch": torch.__version__,
                           "threads": torch.get_num_threads()},
               "activations": per_act}
    if out_dir:
        write_ablation_report(results, out_dir)
    return results


def format_ablation_markdown(results: dict[str, Any]) -> str:
    """Markdown version of Table I for the given results."""
    acts = [a for a in PAPER_ORDER if a in results["activations"]] + \
           [a for a in results["activations"] if a not in PAPER_ORDER]
    rows = results["activations"]
    best = min(acts, key=lambda a: rows[a]["mean_cm"])
    cells = [f"{rows[a]['mean_cm']:.2f} ± {rows[a]['std_cm']:.2f}" for a in acts]
    cells = [f"**{c}**" if a == best else c for a, c in zip(acts, cells)]
    lines = [
        f"## Mean effect prediction error (cm) across bottleneck activations over "
        f"{results['runs']} runs",
        "",
        "| " + " | ".join(rows[a]["label"] for a in acts) + " |",
        "|" + "---|" * len(acts),
        "| " + " | ".join(cells) + " |",
        "",
        f"Test split: {results['num_test']} transitions held out from {results['source']} "
        f"(zero-effect baseline {results['zero_effect_cm']:.2f} cm); "
        f"{results['num_train_val']} for training/validation; {results['epochs']} epochs"
        + (f", at most {results['max_steps']} steps" if results.get("max_steps") else "")
        + f"; seed {results['seed']}.",
    ]
    return "\n".join(lines) + "\n"


def write_ablation_report(results: dict[str, Any], out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``ablation.md`` and ``ablation.json`` into ``out_dir``; returns both paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md, js = out / "ablation.md", out / "ablation.json"
    md.write_text(format_ablation_markdown(results))
    js.write_text(json.dumps(results, indent=2) + "\n")
    return md, js
