"""`tamp reproduce`: the paper's experiments end to end, from nothing to `report.md`.

    collect -> train (Dynamics, Symbolic and the two Fig. 4 variants; Table I ablation alongside)
            -> learned domains -> problem set -> evaluate every method -> report

Layout of the output directory:

    OUT/data/                 interaction transitions (`tamp collect`)
    OUT/models/               symbolic.pt, dynamics.pt, domain/   (`tamp plan --models OUT/models`)
    OUT/models/variants/      symbolic_sigmoid.pt, domain_sigmoid/, dynamics_gumbel.pt (Fig. 4)
    OUT/ablation/             ablation.json, ablation.md (Table I)
    OUT/problems.jsonl        the problem set (regenerable from its seeds)
    OUT/results/              rows.jsonl, meta.json, report.md, report.json, figures/
    OUT/stages.json           finished stages with their wall time; a rerun skips them

Every stage resumes: collection re-collects only missing shards, training continues from the last
checkpoint, the evaluation recomputes only missing rows. With `models=DIR` (for example the bundled
`tamp/pretrained`) the collection, training and domain stages are skipped and DIR's models are
evaluated. `protocol` and `runs` choose the problem sets (`evaluation.problems`): `runs` sets of
consecutive seeds in one file, reported as mean ± std over runs. The Symbolic Model has the paper's published
size (d_z 1, K 3; the Dynamics Model 8, 4), learns from the transitions that moved the picked
block, without the arm's pick-to-place displacement as input (so that what its decoder needs about
the scene passes through the symbols), and its operators mention only the objects a transition
involves (see symbolic/README.md). Each Fig. 4 variant changes the activation alone: the Sigmoid
Symbolic Model is trained as the Symbolic Model, the Gumbel Dynamics Model as the Dynamics Model.
"""
from __future__ import annotations

import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING, Any

from guarded import Schema, read_json
from tamp.errors import UserError
from tamp.records import atomic_write_text, output_dir

if TYPE_CHECKING:
    from learned import TrainConfig


@dataclass(frozen=True)
class ModelSpec:
    """One network to train: where it goes, its bottleneck and what it learns from."""

    path: str  # relative to OUT/models
    activation: str
    d_z: int
    heads: int
    symbolic: bool = False  # a Symbolic Model: no arm displacement input, trained on the moves alone


@dataclass(frozen=True)
class Scale:
    """Sizes of one reproduction. `quick` fits in an hour on 2 cores; `paper` is the paper's."""

    samples: int
    epochs: int  # per model (the paper: 4000)
    train_time_limit_s: float | None  # cap per model, so that a slow machine still finishes
    ablation_runs: int  # seeds per activation (the paper: 10)
    ablation_epochs: int
    per_cell: int  # problems per (n, k) (the paper: 100)
    search_time_limit_s: float  # continuous search, per problem
    objects: tuple[int, ...] = (2, 3, 4)
    actions: tuple[int, ...] = (1, 2, 3, 4, 5)
    lr: float = 1e-4  # Adam, batch 128: the paper's
    seed: int = 0
    # Training settings beyond the paper's (learned.TrainConfig); the defaults are the paper's and are
    # left out of stages.json (`Stages`), so that reproductions begun before they existed stay resumable.
    batch_size: int = 128
    precision: str = "float32"  # or "bfloat16": autocast forward/backward, ~3x faster where the CPU has bf16
    patience_epochs: int | None = None  # early stopping: `epochs` is then a maximum
    models: tuple[ModelSpec, ...] = (
        ModelSpec("dynamics.pt", "sigmoid", 8, 4),
        ModelSpec("symbolic.pt", "gumbel_sigmoid", 1, 3, symbolic=True),
        ModelSpec("variants/symbolic_sigmoid.pt", "sigmoid", 1, 3, symbolic=True),
        ModelSpec("variants/dynamics_gumbel.pt", "gumbel_sigmoid", 8, 4),
    )
    domains: dict[str, str] = field(default_factory=lambda: {
        "symbolic.pt": "domain", "variants/symbolic_sigmoid.pt": "variants/domain_sigmoid"})

    def train_config(self, **changes: Any) -> "TrainConfig":
        """The scale's training settings (one thread per job: jobs run side by side), with `changes`."""
        from learned import TrainConfig

        settings: dict[str, Any] = dict(epochs=self.epochs, batch_size=self.batch_size, lr=self.lr,
                                        precision=self.precision, patience_epochs=self.patience_epochs,
                                        seed=self.seed, threads=1, time_limit_s=self.train_time_limit_s)
        return TrainConfig(**{**settings, **changes})


SCALES: dict[str, Scale] = {
    # the paper's training settings, 250 epochs: what the bundled models were made with (tamp/pretrained), and
    # existing quick OUTs stay resumable; the fast settings would do better here (learned/README.md, training)
    "quick": Scale(samples=40_000, epochs=250, train_time_limit_s=None, ablation_runs=2, ablation_epochs=15,
                   per_cell=10, search_time_limit_s=10.0),
    # to convergence (patience 100 epochs, at most the paper's 4000) at the fast settings
    # (learned.TrainConfig.fast(): batch 1024, lr 1e-4 scaled linearly, bfloat16 autocast)
    # Table I over 3 seeds per activation (the paper: 10), trained to convergence as the models are
    "paper": Scale(samples=160_000, epochs=4000, train_time_limit_s=None, ablation_runs=3, ablation_epochs=4000,
                   per_cell=100, search_time_limit_s=60.0, batch_size=1024, lr=8e-4, precision="bfloat16",
                   patience_epochs=100),
}


# reproduce() options that define a run beside the scale, and their defaults
DEFAULT_OPTIONS: dict[str, Any] = {"protocol": "strict", "runs": 1, "models": None, "symbolic_backend": "python"}
# Scale fields added later, with the values that reproduce what a reproduction did before they existed
LEGACY_SCALE: dict[str, Any] = {"batch_size": 128, "precision": "float32", "patience_epochs": None}


class TrainingUnfinished(RuntimeError):
    """A wall-clock cap stopped a model before it finished: rerun the same command to resume it."""


def _say(message: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {message}", flush=True)


STAGES_SCHEMA = Schema({"type": "object", "required": ["setup", "finished"], "properties": {
    "setup": {"type": "object"}, "finished": {"type": "object", "additionalProperties": {"type": "object"}}}})


class Stages:
    """OUT/stages.json: which stages finished, and how long they took (seconds)."""

    def __init__(self, out: Path, scale_name: str, scale: Scale, **options: Any) -> None:
        self.path = out / "stages.json"
        config = {k: v for k, v in asdict(scale).items() if not (k in LEGACY_SCALE and v == LEGACY_SCALE[k])}
        setup = {"scale": scale_name, "config": json.loads(json.dumps(config))}
        setup.update({k: v for k, v in options.items() if v != DEFAULT_OPTIONS[k]})  # older OUTs stay resumable
        if self.path.is_file():
            self.state = read_json(self.path, "stages file")
            STAGES_SCHEMA.check(self.state, str(self.path))
            if self.state.get("setup") != setup:
                raise UserError(f"{out} holds a reproduction with other settings ({self.path}: scale "
                                 f"{self.state.get('setup', {}).get('scale')!r}); use another --out")
        else:
            self.state = {"setup": setup, "finished": {}}
            self._write()

    def done(self, name: str) -> bool:
        return name in self.state["finished"]

    def finish(self, name: str, seconds: float, **info: Any) -> None:
        self.state["finished"][name] = {"seconds": round(seconds, 1), **info}
        self._write()

    def _write(self) -> None:
        atomic_write_text(self.path, json.dumps(self.state, indent=1) + "\n")


# --- the training jobs (run in worker processes) ---------------------------------------------------
def _train_job(data: str, out: str, spec: ModelSpec, scale: Scale) -> dict:
    import torch

    from learned import ModelConfig, train_model
    from learned.train import last_path

    torch.set_num_threads(1)
    path = Path(out) / spec.path
    path.parent.mkdir(parents=True, exist_ok=True)
    config = ModelConfig(activation=spec.activation, d_z=spec.d_z, heads=spec.heads, arm_input=not spec.symbolic)
    result = train_model(data, config, scale.train_config(only_moved=spec.symbolic), path, progress=False,
                         resume=last_path(path).is_file())
    return {"model": spec.path, "val_cm": round(result.best_val_cm, 3), "best_epoch": result.best_epoch,
            "epochs": result.epochs_reached, "stop": result.stop_reason.value, "finished": result.finished}


def _ablation_job(data: str, out: str, scale: Scale, activation: str, run: int) -> dict:
    """One (activation, run) of Table I, resumed from OUT/ablation/models/ if it began before."""
    import torch

    from learned.ablation import ablation_run

    torch.set_num_threads(1)
    result = ablation_run(data, activation, run, scale.train_config(epochs=scale.ablation_epochs), out_dir=out,
                          resume=True)
    return {**result, "model": f"ablation/{activation}-run{run}"}


# --- the pipeline ----------------------------------------------------------------------------------
def reproduce(out: str | Path, scale_name: str = "quick", workers: int | None = None, backend: str = "local",
              fidelity: str = "fast", protocol: str = "strict", runs: int = 1, models: str | Path | None = None,
              symbolic_backend: str = "python", address: str | None = None) -> Path:
    """Run (or resume) every stage; returns the path of report.md. `models`: evaluate this models
    directory instead of collecting and training (stages collect, train and domains skipped)."""
    from tamp.app.parallel import available_cpus
    from tamp.app.problem import PROTOCOLS

    if scale_name not in SCALES:
        raise UserError(f"unknown scale {scale_name!r}; choose one of {', '.join(SCALES)}")
    if protocol not in PROTOCOLS:
        raise UserError(f"--protocol must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    if runs < 1:
        raise UserError(f"--runs must be a positive integer, got {runs}")
    if models is not None:
        models = Path(models).resolve()
        if not models.is_dir():
            raise UserError(f"no models directory at {models} (--models: symbolic.pt, dynamics.pt, domain/)")
    scale, out = SCALES[scale_name], Path(out)
    with output_dir(out, "--out", own=("stages.json",)):
        return _reproduce(out, scale_name, scale, workers or available_cpus(), backend, fidelity, protocol, runs,
                          models, symbolic_backend, address)


def _reproduce(out: Path, scale_name: str, scale: Scale, workers: int, backend: str, fidelity: str, protocol: str,
               runs: int, models: Path | None, symbolic_backend: str, address: str | None) -> Path:
    """`reproduce` in its claimed folder `out`."""
    stages = Stages(out, scale_name, scale, protocol=protocol, runs=runs,
                    models=None if models is None else str(models), symbolic_backend=symbolic_backend)
    data = out / "data"
    t_all = time.perf_counter()
    _say(f"reproduce --scale {scale_name} into {out} with {workers} worker(s)"
         + ("" if models is None else f", evaluating the models of {models}"))
    if models is not None:
        return _evaluate_stages(out, stages, scale, models, workers, backend, fidelity, protocol, runs,
                                symbolic_backend, t_all, address)
    models = out / "models"

    if not stages.done("collect"):
        from tamp.app.collect import CollectConfig, collect

        _say(f"collect: {scale.samples} random pick-place transitions, {','.join(map(str, scale.objects))} objects")
        t = time.perf_counter()
        collected = collect(data, CollectConfig(samples=scale.samples, objects=scale.objects, seed=scale.seed),
                            workers=workers, backend=backend, address=address, progress=True)
        stages.finish("collect", time.perf_counter() - t, samples=collected.samples)

    if not stages.done("train"):
        _train_stage(data, models, out, stages, scale, workers)

    if not stages.done("domains"):
        from tamp.planning.domain import learn_domain

        t, results = time.perf_counter(), []
        for model, domain in scale.domains.items():
            report = learn_domain(models / model, data, models / domain, seed=scale.seed, involved_only=True,
                                  any_bottleneck=True)  # the Fig. 4 Sigmoid variant learns one too
            results.append({"model": model, "operators": report["n_operators"]})
            _say(f"domain: {report['n_operators']} operators from {model} -> {models / domain}")
        stages.finish("domains", time.perf_counter() - t, results=results)

    return _evaluate_stages(out, stages, scale, models, workers, backend, fidelity, protocol, runs, symbolic_backend,
                            t_all, address)


def _train_stage(data: Path, models: Path, out: Path, stages: Stages, scale: Scale, workers: int) -> None:
    """The train stage: every model of the scale and the Table I ablation's cells, `workers` at a time."""
    limit = ("no time limit" if scale.train_time_limit_s is None
             else f"at most {scale.train_time_limit_s} s per call")
    epochs = (f"{scale.epochs} epochs" if scale.patience_epochs is None else
              f"to convergence, patience {scale.patience_epochs}, at most {scale.epochs} epochs")
    _say(f"train: {len(scale.models)} models ({epochs} each, batch {scale.batch_size}, lr {scale.lr:g}, "
         f"{scale.precision}, {limit}) and the Table I ablation, {workers} at a time")
    from learned import ModelConfig
    from learned.ablation import PAPER_ORDER, summarize_ablation, write_ablation_report

    t = time.perf_counter()
    results = []
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        jobs = [pool.submit(_train_job, str(data), str(models), spec, scale) for spec in scale.models]
        jobs += [pool.submit(_ablation_job, str(data), str(out / "ablation"), scale, activation, run)
                 for run in range(scale.ablation_runs) for activation in PAPER_ORDER]
        for job in as_completed(jobs):
            results.append(job.result())
            _say(f"  trained {json.dumps(results[-1])}")
    unfinished = [r["model"] for r in results if not r.get("finished", True)]
    if unfinished:  # a wall-clock cap must not decide a result: leave the stage open for a rerun
        raise TrainingUnfinished(f"train: {', '.join(unfinished)} stopped at the time limit "
                                 f"({scale.train_time_limit_s} s) before finishing; rerun the same command "
                                 "to resume training")
    cells = [r for r in results if r["model"].startswith("ablation/")]
    summary = [r for r in results if r not in cells]
    if cells:  # Table I from its cells, as `tamp ablate-activations` writes it
        table = summarize_ablation(cells, str(data), scale.train_config(epochs=scale.ablation_epochs),
                                   ModelConfig(n_max=max(scale.objects)))
        write_ablation_report(table, out / "ablation")
        summary.append({"model": "ablation",
                        "mean_cm": {a: round(v["mean_cm"], 3) for a, v in table["activations"].items()}})
    stages.finish("train", time.perf_counter() - t, results=summary)


def _evaluate_stages(out: Path, stages: Stages, scale: Scale, models: Path, workers: int, backend: str,
                     fidelity: str, protocol: str, runs: int, symbolic_backend: str, t_all: float,
                     address: str | None = None) -> Path:
    """The problem set, the evaluation of every method and the report."""
    problems = out / "problems.jsonl"
    if not stages.done("problems"):
        from evaluation.problems import generate_problems, write_problems

        _say(f"problems: {scale.per_cell} per (n, k), n in {scale.objects}, k in {scale.actions}, {protocol} "
             f"protocol, {runs} run(s)")
        t = time.perf_counter()
        write_problems(problems, generate_problems(scale.objects, scale.actions, scale.per_cell, seed=scale.seed,
                                                   protocol=protocol, runs=runs, workers=workers))
        stages.finish("problems", time.perf_counter() - t)

    results_dir = out / "results"
    if not stages.done("evaluate"):
        from evaluation.configuration import EvalConfig
        from evaluation.run import evaluate
        from tamp.planning.config import Level1Config, PlanConfig
        from tamp.planning.search import SearchConfig

        _say(f"evaluate every method on {problems} ({fidelity} world)")
        t = time.perf_counter()
        planner = PlanConfig(level1=Level1Config(backend=symbolic_backend),
                             search=SearchConfig(time_limit=scale.search_time_limit_s))
        evaluate(models, problems, results_dir,
                 config=EvalConfig(planner=planner, fidelity=fidelity, workers=workers, backend=backend,
                                   address=address))
        stages.finish("evaluate", time.perf_counter() - t)

    from evaluation.report import write_report

    ablation = out / "ablation" / "ablation.json"
    report_path = write_report(results_dir, ablation=ablation if ablation.is_file() else None)
    stages.finish("report", 0.0)
    _say(f"done in {(time.perf_counter() - t_all) / 60:.1f} min (this call); report: {report_path}")
    return report_path


if __name__ == "__main__":  # pragma: no cover
    sys.exit("use `tamp reproduce`")
