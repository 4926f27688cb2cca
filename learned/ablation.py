"""Table I of the paper: effect-prediction error per bottleneck activation over several runs.

One held-out test split (fixed by the training seed) is shared by every run; each run r trains a
fresh model per activation (seed + r, which also draws the validation split from the remaining
data), keeps its best-by-validation weights, and reports the mean effect error (cm) on the test
split. `ablation_run` is one (activation, run), so that a caller can run the cells in parallel and
resume them one by one (`tamp reproduce`); `ablation_cell` reads a cell as it stands, without training
(a finished run, or the best model so far of a run still training); `summarize_ablation` makes the table;
`finish_ablation` completes a table whose finished runs are known only from its JSON (their models gone).
"""
from __future__ import annotations

import json
import math
import platform
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import torch

from guarded import Schema, read_json

from .checkpoint import load_model, read_checkpoint
from .dataset import Transitions, atomic_write_bytes, load_transitions
from .model import ACTIVATIONS, ModelConfig
from .train import evaluate, last_path, prepare, split_indices, train_model
from .train_config import TrainConfig, train_options

LABELS = {"gumbel_sigmoid": "Gumbel-Sigmoid", "tanh": "Tanh", "none": "No activation",
          "sigmoid": "Sigmoid"}
PAPER_ORDER = ("gumbel_sigmoid", "tanh", "none", "sigmoid")


def _splits(data: Transitions, run: int, train: TrainConfig, test_fraction: float
            ) -> tuple[Transitions, Transitions, Transitions]:
    """(train, validation, test) of run `run`: the test split is fixed by `train.seed`, the validation
    split drawn from the rest at seed `train.seed + run`."""
    rest_idx, test_idx = split_indices(len(data), (test_fraction,), train.seed)
    rest, test = data.subset(rest_idx), data.subset(test_idx)
    tr_idx, va_idx = split_indices(len(rest), (train.val_fraction,), train.seed + run)
    return rest.subset(tr_idx), rest.subset(va_idx), test


def cell_path(out_dir: str | Path, activation: str, run: int) -> Path:
    """Where the best model of Table I's cell (activation, run) is kept under `out_dir`."""
    return Path(out_dir) / "models" / f"{activation}-run{run}.pt"


def ablation_run(data: "str | Path | Transitions", activation: str, run: int, train: TrainConfig | None = None, *,
                 config: ModelConfig | None = None, test_fraction: float = 0.2, out_dir: str | Path | None = None,
                 resume: bool = False, progress: bool = False) -> dict[str, Any]:
    """One cell of Table I: a model of `activation` trained at seed `train.seed + run` (which also
    draws its validation split), tested on the test split fixed by `train.seed`. With `out_dir` the
    model goes to `cell_path(out_dir, activation, run)`, and `resume` continues (or, when it
    finished, just re-reads) that run. Returns its test and validation errors (cm) and epochs."""
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation {activation!r} not in {ACTIVATIONS}")
    train = train or TrainConfig()
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    tr, va, test = _splits(data, run, train, test_fraction)
    out = cell_path(out_dir, activation, run) if out_dir else None
    if out:
        out.parent.mkdir(parents=True, exist_ok=True)
    base = config or ModelConfig(n_max=data.n_max)
    res = train_model(tr, replace(base, activation=activation), replace(train, seed=train.seed + run), out,
                      val_data=va, resume=resume and out is not None and last_path(out).is_file(), progress=progress)
    ev = evaluate(res.model, test)
    return {"activation": activation, "run": run, "test_cm": ev["err_cm"], "val_cm": res.best_val_cm,
            "zero_cm": ev["zero_cm"], "finished": res.finished, "epochs": res.epochs_reached,
            "best_epoch": res.best_epoch, "num_train_val": len(tr) + len(va), "num_test": len(test)}


def ablation_cell(data: "str | Path | Transitions", activation: str, run: int, train: TrainConfig, out_dir: str | Path,
                  *, config: ModelConfig | None = None, test_fraction: float = 0.2) -> dict[str, Any] | None:
    """Cell (activation, run) of Table I as it stands in `out_dir`, without training: None if it has not
    begun; else `ablation_run`'s result, where a run still training (interrupted, or stopped by a time
    limit) gives the test error of its best model so far and `"finished": False`. ValueError if the
    cell was trained with other settings than `train` and `config`."""
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    best = cell_path(out_dir, activation, run)
    if not (best.is_file() and last_path(best).is_file()):
        return None
    tr, va, test = _splits(data, run, train, test_fraction)
    state = read_checkpoint(last_path(best)).get("train", {})
    want = train_options(replace(train, seed=train.seed + run), len(tr), len(va))
    config = replace(config or ModelConfig(n_max=data.n_max), activation=activation)
    model = load_model(best)
    if state.get("options") != want or model.config != config:
        raise ValueError(f"{best}: trained with other settings than these (options {state.get('options')} "
                         f"against {want}); give the settings it was trained with")
    ev = evaluate(model, test)
    return {"activation": activation, "run": run, "test_cm": ev["err_cm"], "val_cm": float(state["best_val_cm"]),
            "zero_cm": ev["zero_cm"], "finished": bool(state.get("finished", False)),
            "epochs": int(state.get("epochs_reached", len(state.get("history", [])))),
            "best_epoch": int(state["best_epoch"]), "num_train_val": len(tr) + len(va), "num_test": len(test)}


def summarize_ablation(runs: Sequence[dict[str, Any]], source: str, train: TrainConfig,
                       config: ModelConfig) -> dict[str, Any]:
    """Table I from the `ablation_run` / `ablation_cell` results of every (activation, run): mean +-
    sample std over the finished runs; runs still training are listed apart, under `in_progress`."""
    order = [a for a in PAPER_ORDER if any(r["activation"] == a for r in runs)] + \
            sorted({r["activation"] for r in runs} - set(PAPER_ORDER))
    per_act: dict[str, dict[str, Any]] = {}
    for act in order:
        mine = sorted((r for r in runs if r["activation"] == act), key=lambda r: r["run"])
        done = [r for r in mine if r.get("finished", True)]
        errs = [r["test_cm"] for r in done]
        per_act[act] = {"label": LABELS.get(act, act), "runs": len(done),
                        "mean_cm": float(np.mean(errs)) if errs else None,
                        "std_cm": float(np.std(errs, ddof=1)) if len(errs) > 1 else 0.0,
                        "runs_cm": errs, "val_cm": [r["val_cm"] for r in done],
                        "epochs": [r.get("epochs") for r in done], "run_ids": [r["run"] for r in done],
                        "in_progress": [{"run": r["run"], "epochs": r.get("epochs"), "test_cm": r["test_cm"],
                                         "val_cm": r["val_cm"]} for r in mine if not r.get("finished", True)]}
    first = runs[0]
    summary = {"source": source, "runs": max(a["runs"] for a in per_act.values()),
               "complete": all(not a["in_progress"] for a in per_act.values()),
               "epochs": train.epochs, "max_steps": train.max_steps,
               "seed": train.seed, "num_train_val": first["num_train_val"], "num_test": first["num_test"],
               "zero_effect_cm": first["zero_cm"], "config": config.to_dict(),
               "training": {"batch_size": train.batch_size, "lr": train.lr, "val_fraction": train.val_fraction,
                            **({"precision": train.precision} if train.precision != "float32" else {}),
                            **({"patience_epochs": train.patience_epochs} if train.patience_epochs else {})},
               "machine": {"python": platform.python_version(), "torch": torch.__version__,
                           "threads": torch.get_num_threads()},
               "activations": per_act}
    return {**summary, "trained": training_phrase(summary)}


def _inputs(data: "str | Path | Transitions", activations: Sequence[str], config: ModelConfig | None
            ) -> tuple[Transitions, str, ModelConfig]:
    """The transitions, how the table names their source, and the model config (default: sized to the
    data), once the activations are checked."""
    for a in activations:
        if a not in ACTIVATIONS:
            raise ValueError(f"activation {a!r} not in {ACTIVATIONS}")
    source = str(data) if not isinstance(data, Transitions) else "<in-memory>"
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    return data, source, config or ModelConfig(n_max=data.n_max)


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
    data, source, base = _inputs(data, activations, config)
    results = [ablation_run(data, act, r, train, config=base, test_fraction=test_fraction, out_dir=out_dir,
                            resume=resume, progress=progress) for act in activations for r in range(runs)]
    summary = summarize_ablation(results, source, train, base)
    if out_dir:
        write_ablation_report(summary, out_dir)
    return summary


def summarize_ablation_dir(data: "str | Path | Transitions", out_dir: str | Path, runs: int, *,
                           activations: Sequence[str] = PAPER_ORDER, train: TrainConfig | None = None,
                           config: ModelConfig | None = None, test_fraction: float = 0.2) -> dict[str, Any]:
    """Table I from the runs already in `out_dir` (`ablation_cell`), without training, written by
    `write_ablation_report`: what an interrupted `ablate_activations` has so far. `train` and `config`
    must be those the runs were trained with. ValueError when no run has begun there."""
    train = train or TrainConfig()
    data, source, base = _inputs(data, activations, config)
    cells = [c for a in activations for r in range(runs)
             if (c := ablation_cell(data, a, r, train, out_dir, config=base, test_fraction=test_fraction))]
    if not cells:
        raise ValueError(f"{out_dir}: no Table I run has begun there (no models/<activation>-run<k>.pt)")
    summary = summarize_ablation(cells, source, train, base)
    write_ablation_report(summary, out_dir)
    return summary


_NUMBERS = {"type": "array", "items": {"type": "number"}}
TABLE_SCHEMA = Schema({
    "type": "object",
    "required": ["epochs", "seed", "num_train_val", "num_test", "zero_effect_cm", "config", "training", "activations"],
    "properties": {
        "epochs": {"type": "integer", "minimum": 0}, "seed": {"type": "integer"},
        "num_train_val": {"type": "integer", "minimum": 0}, "num_test": {"type": "integer", "minimum": 0},
        "zero_effect_cm": {"type": "number"}, "config": {"type": "object"}, "training": {"type": "object"},
        "activations": {"type": "object", "additionalProperties": {
            "type": "object", "required": ["runs_cm", "val_cm", "epochs"],
            "properties": {"runs_cm": _NUMBERS, "val_cm": _NUMBERS, "epochs": {"type": "array"},
                           "run_ids": {"type": "array", "items": {"type": "integer", "minimum": 0}},
                           "in_progress": {"type": "array", "items": {
                               "type": "object", "required": ["run"],
                               "properties": {"run": {"type": "integer", "minimum": 0}}}}}}}}})


def read_table(path: str | Path) -> dict[str, Any]:
    """A Table I JSON (`write_ablation_report`'s ablation.json), through the guarded reader and
    `TABLE_SCHEMA`; ValueError naming the file and the field when it is not one."""
    table = read_json(path, "Table I JSON")
    TABLE_SCHEMA.check(table, f"{path} (a Table I of `tamp ablate-activations`)")
    return table


def finished_runs(table: dict[str, Any]) -> list[dict[str, Any]]:
    """The finished runs of a Table I JSON (`summarize_ablation`'s output), as `ablation_run` results.
    A table written before runs were numbered in it (no `run_ids`) numbered them 0, 1, ... leaving out
    the runs it lists as still training."""
    out = []
    for act, row in table["activations"].items():
        busy = {p["run"] for p in row.get("in_progress", [])}
        ids = row.get("run_ids") or [r for r in range(len(row["runs_cm"]) + len(busy)) if r not in busy]
        out += [{"activation": act, "run": run, "test_cm": cm, "val_cm": val, "finished": True, "epochs": ep,
                 "zero_cm": table["zero_effect_cm"], "num_train_val": table["num_train_val"],
                 "num_test": table["num_test"]}
                for run, cm, val, ep in zip(ids, row["runs_cm"], row["val_cm"], row["epochs"])]
    return out


def _same_settings(table: dict[str, Any], fresh: dict[str, Any]) -> list[str]:
    """The fields in which a Table I JSON differs from one made now (`fresh`, of one trained cell's
    settings): the training, the model, the epochs and seed, and the split (sizes and zero-effect
    error, which fingerprint the data)."""
    diffs = [f"{k}: {table.get(k)!r} in the table, {fresh[k]!r} here"
             for k in ("epochs", "max_steps", "seed", "num_train_val", "num_test", "config", "training")
             if table.get(k) != fresh[k]]
    if not math.isclose(table.get("zero_effect_cm", -1.0), fresh["zero_effect_cm"], rel_tol=1e-6):
        diffs.append(f"zero-effect error: {table.get('zero_effect_cm')} cm in the table, "
                     f"{fresh['zero_effect_cm']} cm on these data (not the data it was made from)")
    return diffs


def _zero_effect_cm(data: Transitions) -> float:
    """Mean distance (cm) the real objects of `data` move: the error of predicting no motion, as
    `evaluate` reports it (zero_cm), without a model."""
    t = prepare(data)
    return 100 * float(t["absolute"].norm(dim=-1)[t["mask"]].sum()) / int(t["mask"].sum())


def _finish_cell(data: str, activation: str, run: int, train: TrainConfig, config: ModelConfig,
                 test_fraction: float, out_dir: str) -> dict[str, Any]:
    """One cell for `finish_ablation`'s process pool (one torch thread), resumed if it began before."""
    torch.set_num_threads(1)
    return ablation_run(data, activation, run, train, config=config, test_fraction=test_fraction,
                        out_dir=out_dir, resume=True)


def finish_ablation(data: str | Path, table: dict[str, Any], out_dir: str | Path, runs: int, *,
                    train: TrainConfig, config: ModelConfig | None = None, test_fraction: float = 0.2,
                    workers: int = 1, progress: bool = True, summarize: bool = False) -> dict[str, Any]:
    """Complete Table I `table` (an ablation.json) to `runs` runs per activation: its finished runs are
    kept as it lists them, every other run (still training when it was written, or never begun) is
    trained in `out_dir` (`ablation_run`, resumed if it began there; `workers` at a time, one torch
    thread each), and the whole table is written there. For a table whose models are gone: the same
    seeds give the same runs. With `summarize` nothing is trained: those runs are read as they stand
    in `out_dir` (`ablation_cell`; a run not begun there keeps the table's entry), e.g. while another
    process trains them. ValueError if the table was made with other settings or other data."""
    data = str(data)
    transitions, _, base = _inputs(data, PAPER_ORDER, config)
    kept = finished_runs(table)
    todo = [(a, r) for a in table["activations"] for r in range(runs)
            if not any(k["activation"] == a and k["run"] == r for k in kept)]
    probe = _splits(transitions, 0, train, test_fraction)
    fresh = summarize_ablation([{"activation": "none", "run": 0, "test_cm": 0.0, "val_cm": 0.0,
                                 "zero_cm": _zero_effect_cm(probe[2]),
                                 "num_train_val": len(probe[0]) + len(probe[1]), "num_test": len(probe[2])}],
                               data, train, base)
    diffs = _same_settings(table, fresh)
    if diffs:
        raise ValueError("the table was made with other settings or data than these: " + "; ".join(diffs))
    if summarize:
        return _finish_summary(transitions, data, table, kept, todo, out_dir, train, base, test_fraction)
    del transitions, probe
    if progress:
        print(f"Table I: {len(kept)} finished run(s) kept; training {len(todo)}: "
              + ", ".join(f"{a} run {r}" for a, r in todo), flush=True)
    trained = []
    if todo:
        with ProcessPoolExecutor(max_workers=max(1, min(workers, len(todo))),
                                 mp_context=get_context("spawn")) as pool:
            jobs = [pool.submit(_finish_cell, data, a, r, train, base, test_fraction, str(out_dir)) for a, r in todo]
            for job in jobs:
                trained.append(job.result())
                if progress:
                    t = trained[-1]
                    print(f"  {t['activation']} run {t['run']}: {t['test_cm']:.3f} cm after {t['epochs']} epochs"
                          + ("" if t["finished"] else " (unfinished: run again to resume)"), flush=True)
    summary = summarize_ablation(kept + trained, data, train, base)
    write_ablation_report(summary, out_dir)
    return summary


def _finish_summary(transitions: Transitions, source: str, table: dict[str, Any], kept: list[dict[str, Any]],
                    todo: list[tuple[str, int]], out_dir: str | Path, train: TrainConfig, config: ModelConfig,
                    test_fraction: float) -> dict[str, Any]:
    """`finish_ablation(summarize=True)`: the table with the runs it lacks as they stand in `out_dir`."""
    cells = []
    for act, run in todo:
        cell = ablation_cell(transitions, act, run, train, out_dir, config=config, test_fraction=test_fraction)
        if cell is None:  # not begun here: the table's own entry of a run still training, if any
            cell = next(({"activation": act, "run": run, "test_cm": p["test_cm"], "val_cm": p["val_cm"],
                          "epochs": p.get("epochs"), "finished": False, "zero_cm": table["zero_effect_cm"],
                          "num_train_val": table["num_train_val"], "num_test": table["num_test"]}
                         for p in table["activations"].get(act, {}).get("in_progress", []) if p["run"] == run), None)
        if cell is not None:
            cells.append(cell)
    summary = summarize_ablation(kept + cells, source, train, config)
    write_ablation_report(summary, out_dir)
    return summary


def training_phrase(results: dict[str, Any]) -> str:
    """How Table I's models were trained, in words: a fixed number of epochs, or to convergence with
    the range of epochs the runs reached."""
    patience = results.get("training", {}).get("patience_epochs")
    if not patience:
        return f"{results['epochs']} epochs" + (f", at most {results['max_steps']} steps"
                                                 if results.get("max_steps") else "")
    reached = sorted(e for a in results["activations"].values() for e in a.get("epochs", []) if e is not None)
    span = "" if not reached else f"; {reached[0]}" + (f"-{reached[-1]}" if reached[-1] != reached[0] else "") + \
        " epochs reached"
    return f"trained to convergence (validation patience {patience} epochs, at most {results['epochs']}{span})"


def format_ablation_markdown(results: dict[str, Any]) -> str:
    """Markdown version of Table I: mean ± std over the finished runs, then each run's test error
    and epochs, and the runs still training (not in the means)."""
    acts = [a for a in PAPER_ORDER if a in results["activations"]] + \
           [a for a in results["activations"] if a not in PAPER_ORDER]
    rows = results["activations"]
    scored = [a for a in acts if rows[a]["mean_cm"] is not None]
    best = min(scored, key=lambda a: rows[a]["mean_cm"]) if scored else None
    cells = []
    for a in acts:
        row, n = rows[a], rows[a].get("runs", len(rows[a]["runs_cm"]))
        cell = "—" if row["mean_cm"] is None else f"{row['mean_cm']:.2f}" + (f" ± {row['std_cm']:.2f}" if n > 1 else "")
        cell = f"**{cell}**" if a == best else cell
        cells.append(cell + (f" ({n} run{'s' * (n != 1)})" if n != results["runs"] else ""))
    lines = [
        f"## Mean effect prediction error (cm) across bottleneck activations over {results['runs']} "
        f"run{'s' * (results['runs'] != 1)}",
        "",
        "| " + " | ".join(rows[a]["label"] for a in acts) + " |",
        "|" + "---|" * len(acts),
        "| " + " | ".join(cells) + " |",
        "",
        f"Test split: {results['num_test']} transitions held out from {results['source']} "
        f"(zero-effect baseline {results['zero_effect_cm']:.2f} cm); "
        f"{results['num_train_val']} for training/validation; {results.get('trained') or training_phrase(results)}; "
        f"seed {results['seed']}.",
    ]
    if all("epochs" in rows[a] for a in acts):
        lines += ["", "Each run's test error in cm (epochs trained):", ""]
        for a in acts:
            runs = [f"{cm:.3f} ({ep})" for cm, ep in zip(rows[a]["runs_cm"], rows[a]["epochs"])]
            runs += [f"{p['test_cm']:.3f} (run {p['run']}: still training, best model after {p['epochs']} epochs)"
                     for p in rows[a].get("in_progress", [])]
            lines.append(f"- {rows[a]['label']}: " + ", ".join(runs))
    if not results.get("complete", True):
        lines += ["", "Runs still training are not in the means: resume them to complete the table."]
    return "\n".join(lines) + "\n"


def write_ablation_report(results: dict[str, Any], out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``ablation.md`` and ``ablation.json`` into ``out_dir`` (each atomically); returns both paths."""
    out = Path(out_dir)
    md, js = out / "ablation.md", out / "ablation.json"
    for path, text in ((md, format_ablation_markdown(results)), (js, json.dumps(results, indent=2) + "\n")):
        atomic_write_bytes(path, lambda f, text=text: f.write(text.encode()))
    return md, js
