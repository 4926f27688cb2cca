"""Training an ensemble Dynamics Model: M members on bootstrap resamples, each with a fitted spread head.

Member m (of M) is trained by `train_model` on a resample with replacement of the training split, of the
split's size, drawn with ``default_rng([seed, m])``; with *extra* data (the robot's own executed steps, `tamp
practice`) a share ``extra_share`` of each resample is drawn from the extra data's training split and the rest
from the random data's, so that a few hundred planned steps weigh in beside 144,000 random ones. All members
are validated on the same split (both sources' validation splits). Then the member's spread head is fitted
(`learned.spread`) on the same transitions (with ``only_moved``, the moving ones). Members start from `init`'s
weights when given (an ensemble file gives member m its own member m mod M; a single model gives all members
its weights: the resamples and the seeds make them differ), and keep its object limit when it is larger than
the data's (a limit raised on evidence, as the bundled models' was: tamp/pretrained/PROVENANCE.md).

Files: member m's checkpoints are ``<out>.member-m.pt`` (and its ``.last.pt``: a stopped run resumes
where each member was), the ensemble ``<out>`` (`learned.ensemble`) once all members are done.
Members train in parallel on ``workers`` processes, one torch thread each.
"""
from __future__ import annotations

import dataclasses
import multiprocessing
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .checkpoint import read_checkpoint, save_checkpoint
from .dataset import Transitions, load_transitions
from .ensemble import EffectEnsemble, load_dynamics, member_models, save_ensemble
from .model import ModelConfig
from .spread import SpreadConfig, fit_spread
from .train import last_path, moving_steps, split_indices, train_model
from .train_config import TrainConfig

DataSource = str | Path | Sequence[str | Path] | Transitions


@dataclass(frozen=True)
class EnsembleConfig:
    """How many members and how their data is drawn (the network is `ModelConfig`'s, each member's
    training `TrainConfig`'s)."""
    members: int = 5  # PETS's ensemble size; 5 members cost 5 forward passes per prediction
    extra_share: float = 0.25  # share of each resample drawn from the extra (practised) data, when there is some
    workers: int = 1  # members trained at once, one process and one torch thread each
    spread: SpreadConfig = field(default_factory=SpreadConfig)

    def __post_init__(self) -> None:
        if isinstance(self.members, bool) or not isinstance(self.members, int) or self.members < 1:
            raise ValueError(f"members must be a positive integer, got {self.members!r}")
        if not 0.0 < self.extra_share < 1.0:
            raise ValueError(f"extra_share must be in (0, 1), got {self.extra_share}")
        if self.workers < 1:
            raise ValueError(f"workers must be >= 1, got {self.workers}")


@dataclass
class EnsembleResult:
    model: EffectEnsemble
    members: list[dict[str, Any]]  # per member: validation error (cm), best epoch, epochs, spread figures
    out_path: Path


def member_path(out_path: str | Path, m: int) -> Path:
    p = Path(out_path)
    return p.with_name(f"{p.stem}.member-{m}{p.suffix or '.pt'}")


def _load(source) -> Transitions:
    """The transitions of one dataset directory or of several, concatenated. Unlike `load_transitions`, several
    directories need not share their world settings: the robot's own steps (`tamp practice`) run in the world
    that executes plans, whose arm paths are simplified, beside data collected in the collection's world."""
    if isinstance(source, Transitions):
        return source
    if isinstance(source, (str, Path)):
        return load_transitions(source)
    parts = [load_transitions(d) for d in source]
    n_max = max(p.n_max for p in parts)
    return Transitions.concatenate([p.padded(n_max) for p in parts])


def _splits(data: Transitions, extra: Transitions | None, train: TrainConfig
            ) -> tuple[Transitions, Transitions | None, Transitions]:
    """(random training split, extra training split, the shared validation split)."""
    n_max = max(data.n_max, extra.n_max if extra is not None else 0)
    tr, va = split_indices(len(data), (train.val_fraction,), train.seed)
    data_tr, val = data.subset(tr).padded(n_max), data.subset(va).padded(n_max)
    if extra is None:
        return data_tr, None, val
    if len(extra) < 2:
        raise ValueError(f"the extra data has {len(extra)} transition(s): too few to split for validation")
    tr, va = split_indices(len(extra), (train.val_fraction,), train.seed)
    extra_tr = extra.subset(tr).padded(n_max)
    return data_tr, extra_tr, Transitions.concatenate([val, extra.subset(va).padded(n_max)], val.meta)


def resample(data_tr: Transitions, extra_tr: Transitions | None, m: int, seed: int, extra_share: float
             ) -> Transitions:
    """Member m's bootstrap resample: len(data_tr) transitions drawn with replacement (a share `extra_share`
    of them from `extra_tr` when given)."""
    rng = np.random.default_rng([seed, m])
    size = len(data_tr)
    if extra_tr is None:
        return data_tr.subset(np.sort(rng.integers(0, size, size)))
    k = int(round(extra_share * size))
    parts = [data_tr.subset(np.sort(rng.integers(0, size, size - k))),
             extra_tr.subset(np.sort(rng.integers(0, len(extra_tr), k)))]
    return Transitions.concatenate(parts, data_tr.meta)


def _member_init(init: str | Path | None, out_path: Path, m: int) -> Path | None:
    """The checkpoint member m starts from: `init` itself, or its member m mod M written beside the output."""
    if init is None:
        return None
    models = member_models(init)
    if len(models) == 1:
        return Path(init)
    path = out_path.with_name(f"{out_path.stem}.init-{m}.pt")
    if not path.exists():
        save_checkpoint(path, models[m % len(models)])
    return path


def _train_member(task: tuple) -> dict[str, Any]:
    """Train and fit member m (one process); returns its figures. Resumes a member stopped midway and
    skips one already done."""
    (data, extra, config, train, ensemble, init, out_path, m, progress) = task
    import torch

    torch.set_num_threads(train.threads or 1)
    path = member_path(out_path, m)
    if path.exists():
        state = read_checkpoint(path).get("train", {})
        if "spread" in state and state.get("finished", True):
            return {"member": m, **state["spread_figures"]}
    data_tr, extra_tr, val = _splits(_load(data), None if extra is None else _load(extra), train)
    sample = resample(data_tr, extra_tr, m, train.seed, ensemble.extra_share)
    member_train = dataclasses.replace(train, seed=train.seed + m)
    start = _member_init(init, Path(out_path), m)
    result = train_model(sample, config, member_train, path, val_data=val, resume=True, progress=progress,
                         init=start)
    if not result.finished:
        return {"member": m, "finished": False}
    if start is not None:  # the object limit of the model it started from, if larger (raised on evidence)
        limit = member_models(start)[0].config.n_max
        if limit > result.model.config.n_max:
            result.model.config = dataclasses.replace(result.model.config, n_max=limit)
    if train.only_moved:  # the spread of the steps it learned from: where blocks go when an action executes
        sample, val = moving_steps(sample), moving_steps(val)
    figures = fit_spread(result.model, sample, val, ensemble.spread)
    out = {"val_err_cm": result.best_val_cm, "best_epoch": result.best_epoch, "epochs": result.epochs_reached,
           "stop_reason": result.stop_reason.value, **figures}
    state = read_checkpoint(path)["train"]
    save_checkpoint(path, result.model, {**state, "spread": True, "spread_figures": out})
    return {"member": m, **out}


def train_ensemble(data: DataSource, out_path: str | Path, *, extra: DataSource | None = None,
                   config: ModelConfig | None = None, train: TrainConfig | None = None,
                   ensemble: EnsembleConfig = EnsembleConfig(), init: str | Path | None = None,
                   progress: bool = True) -> EnsembleResult:
    """Train `ensemble.members` members (module docstring) and write the ensemble to `out_path`; a stopped
    run resumes (members already done are kept). `config` gets a spread head whatever it says."""
    train = train or TrainConfig()
    out_path = Path(out_path)
    if init is not None and config is None:
        config = member_models(init)[0].config
    config = dataclasses.replace(config or ModelConfig(n_max=_load(data).n_max), spread=True)
    parallel = ensemble.workers > 1 and ensemble.members > 1
    if parallel and (isinstance(data, Transitions) or isinstance(extra, Transitions)):
        raise ValueError("parallel members read their data from disk: give dataset directories, not Transitions")
    if not parallel:  # one process: the data is read once for every member
        data, extra = _load(data), None if extra is None else _load(extra)
    tasks = [(data, extra, config, train, ensemble, init, out_path, m, progress and not parallel)
             for m in range(ensemble.members)]
    if parallel:
        from tqdm.auto import tqdm

        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(min(ensemble.workers, ensemble.members), mp_context=context) as pool:
            figures = list(tqdm(pool.map(_train_member, tasks), total=len(tasks), disable=not progress,
                                desc="ensemble members", unit="member"))
    else:
        figures = [_train_member(t) for t in tasks]
    unfinished = [f["member"] for f in figures if f.get("finished") is False]
    if unfinished:
        raise TimeoutError(f"members {unfinished} stopped at the time limit: run again to resume them")
    members = [load_dynamics(member_path(out_path, m)) for m in range(ensemble.members)]
    info = {"members": figures, "extra_share": ensemble.extra_share if extra is not None else None,
            "seed": train.seed, "resample": "bootstrap, default_rng([seed, m]) for member m"}
    save_ensemble(out_path, members, info)  # type: ignore[arg-type]
    return EnsembleResult(EffectEnsemble(members, info), figures, out_path)  # type: ignore[arg-type]


def cleanup_members(out_path: str | Path, members: int) -> None:
    """Remove the members' own checkpoints once the ensemble file holds them."""
    out_path = Path(out_path)
    for m in range(members):
        for p in (member_path(out_path, m), last_path(member_path(out_path, m)),
                  out_path.with_name(f"{out_path.stem}.init-{m}.pt")):
            p.unlink(missing_ok=True)
