"""Table I of the paper: effect-prediction error per bottleneck activation over several runs.

One held-out test split (fixed by the training seed) is shared by every run; each run r trains a
fresh model per activation (seed + r, which also draws the validation split from the remaining
data), keeps its best-by-validation weights, and reports the mean effect error (cm) on the test
split. `ablation_run` is one (activation, run), so that a caller can run the cells in parallel and
resume them one by one (`tamp reproduce`); `summarize_ablation` makes the table of their results.
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
from .train import TrainConfig, evaluate, last_path, split_indices, train_model

LABELS = {"gumbel_sigmoid": "Gumbel-Sigmoid", "tanh": "Tanh", "none": "No activation",
          "sigmoid": "Sigmoid"}
PAPER_ORDER = ("gumbel_sigmoid", "tanh", "none", "sigmoid")


def ablation_run(data: "str | Path | Transitions", activation: str, run: int, train: TrainConfig | None = None, *,
                 config: ModelConfig | None = None, test_fraction: float = 0.2, out_dir: str | Path | None = None,
                 resume: bool = False, progress: bool = False) -> dict[str, Any]:
    """One cell of Table I: a model of `activation` trained at seed `train.seed + run` (which also
    draws its validation split), tested on the test split fixed by `train.seed`. With `out_dir` the
    model goes to `out_dir/models/{activation}-run{run}.pt`, and `resume` continues (or, when it
    finished, just re-reads) that run. Returns its test and validation errors (cm)."""
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation {activation!r} not in {ACTIVATIONS}")
    train = train or TrainConfig()
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    rest_idx, test_idx = split_indices(len(data), (test_fraction,), train.seed)
    rest, test = data.subset(rest_idx), data.subset(test_idx)
    tr_idx, va_idx = split_indices(len(rest), (train.val_fraction,), train.seed + run)
    out = (Path(out_dir) / "models" / f"{activation}-run{run}.pt") if out_dir else None
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
    base = config or ModelConfig(n_max=data.n_max)
    res = train_model(rest.subset(tr_idx), replace(base, activation=activation), replace(train, seed=train.seed + run),
                      out, val_data=rest.subset(va_idx), resume=resume and out is not None and last_path(out).is_file(),
                      progress=progress)
    ev = evaluate(res.model, test)
    return {"activation": activation, "run": run, "test_cm": ev["err_cm"], "val_cm": res.best_val_cm,
            "zero_cm": ev["zero_cm"], "finished": res.finished, "epochs": res.epochs_reached,
            "num_train_val": len(rest), "num_test": len(test)}


def summarize_ablation(runs: Sequence[dict[str, Any]], source: str, train: TrainConfig,
                       config: ModelConfig) -> dict[str, Any]:
    """Table I from the `ablation_run` results of every (activation, run): mean +- sample std."""
    order = [a for a in PAPER_ORDER if any(r["activation"] == a for r in runs)] + \
            sorted({r["activation"] for r in runs} - set(PAPER_ORDER))
    per_act: dict[str, dict[str, Any]] = {}
    for act in order:
        mine = sorted((r for r in runs if r["activation"] == act), key=lambda r: r["run"])
        errs = [r["test_cm"] for r in mine]
        per_act[act] = {"label": LABELS.get(act, act), "mean_cm": float(np.mean(errs)),
                        "std_cm": float(np.std(errs, ddof=1)) if len(errs) > 1 else 0.0,
                        "runs_cm": errs, "val_cm": [r["val_cm"] for r in mine]}
    first = runs[0]
    return {"source": source, "runs": len(runs) // len(order), "epochs": train.epochs, "max_steps": train.max_steps,
            "seed": train.seed, "num_train_val": first["num_train_val"], "num_test": first["num_test"],
            "zero_effect_cm": first["zero_cm"], "config": config.to_dict(),
            "training": {"batch_size": train.batch_size, "lr": train.lr, "val_fraction": train.val_fraction,
                         **({"precision": train.precision} if train.precision != "float32" else {}),
                         **({"patience_epochs": train.patience_epochs} if train.patience_epochs else {})},
            "machine": {"python": platform.python_version(), "torch": torch.__version__,
                        "threads": torch.get_num_threads()},
            "activations": per_act}


def ablate_activations(data: "str | Path | Transitions", runs: int = 10, *,
                       activations: Sequence[str] = PAPER_ORDER, train: TrainConfig | None = None,
                       config: ModelConfig | None = None, test_fraction: float = 0.2,
                       out_dir: str | Path | None = None, resume: bool = False,
                       progress: bool = True) -> dict[str, Any]:
    """Train ``runs`` models per activation (`ablation_run`, one after another); mean +- std (sample
    std) test effect error in cm. With ``out_dir``, the per-run best checkpoints go to
    ``out_dir/models/`` and the report is written by ``write_ablation_report``; ``resume`` continues
    the runs found there."""
    train = train or TrainConfig()
    if train.threads:
        torch.set_num_threads(train.threads)
    for a in activations:
        if a not in ACTIVATIONS:
            raise ValueError(f"activation {a!r} not in {ACTIVATIONS}")
    source = str(data) if not isinstance(data, Transitions) else "<in-memory>"
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    base = config or ModelConfig(n_max=data.n_max)
    results = [ablation_run(data, act, r, train, config=base, test_fraction=test_fraction, out_dir=out_dir,
                            resume=resume, progress=progress) for act in activations for r in range(runs)]
    summary = summarize_ablation(results, source, train, base)
    if out_dir:
        write_ablation_report(summary, out_dir)
    return summary


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
