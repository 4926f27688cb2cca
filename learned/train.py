"""Training of the effect model: masked MSE of the paper's Eq. 1, Adam, best-by-validation.

Loss per sample = sum over real objects of ||e_hat_i - e_i||^2 (Eq. 1), in units of the
model's ``effect_scale`` (a single scalar, so the geometry of Eq. 1 is kept), averaged over the
batch. Reported "effect error" is the mean over real objects of ||e_hat_i - e_i||_2 in cm; it
is the same for the arm-subtracted target and for absolute displacements (the arm term is
known exactly). The zero-effect baseline (predict X' = X) is reported next to it.

Files: ``out_path`` holds the best model by validation error; ``<out>.last.pt`` holds the
latest epoch with optimizer and RNG state, which ``resume=True`` continues from exactly.
"""
from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from .checkpoint import model_from_payload, read_checkpoint, save_checkpoint
from .dataset import Transitions, load_transitions
from .effects import arm_displacement, effect_targets, moved_picks
from .model import EffectModel, ModelConfig


@dataclass
class TrainResult:
    model: EffectModel            # best model by validation error, eval mode
    best_val_cm: float            # its mean effect error on the validation split, cm
    best_epoch: int
    steps: int                    # optimizer steps taken in total (including resumed ones)
    samples_per_s: float          # training throughput of this call (forward + backward)
    history: list[dict[str, float]] = field(default_factory=list)
    out_path: Path | None = None


def last_path(out_path: str | Path) -> Path:
    """Where the resumable latest-epoch checkpoint of ``out_path`` lives."""
    p = Path(out_path)
    return p.with_name(p.stem + ".last" + (p.suffix or ".pt"))


def split_indices(num: int, fractions: tuple[float, ...], seed: int) -> list[np.ndarray]:
    """Random disjoint index sets of the given fractions; the remainder is returned first."""
    perm = np.random.default_rng(seed).permutation(num)
    sizes = [int(round(f * num)) for f in fractions]
    if sum(sizes) >= num:
        raise ValueError(f"split {fractions} leaves no training data out of {num} samples")
    parts, start = [], num - sum(sizes)
    for s in sizes:
        parts.append(np.sort(perm[start:start + s]))
        start += s
    return [np.sort(perm[:num - sum(sizes)]), *parts]


def prepare(data: Transitions) -> dict[str, torch.Tensor]:
    """Tensors for training: inputs, padding mask and arm-subtracted effect targets (metres)."""
    t = data.tensors()
    X, Xn, M, A = t["X"].float(), t["X_next"].float(), t["mask"], t["action"].long()
    return {"X": X, "mask": M, "action": A, "target": effect_targets(X, Xn, A, M),
            "absolute": (Xn[..., :3] - X[..., :3]) * M[..., None]}


def normalisation(t: dict[str, torch.Tensor]) -> dict[str, Any]:
    """Position mean/std, effect scale and arm-motion scale (metres) from training tensors."""
    M = t["mask"]
    pos = t["X"][..., :3][M]
    target = t["target"][M]
    arm = arm_displacement(t["X"], t["action"])
    return {"pos_mean": pos.mean(0), "pos_std": pos.std(0).clamp_min(0.01),
            "effect_scale": float(target.pow(2).mean().sqrt().clamp_min(0.001)),
            "arm_scale": float(arm.pow(2).sum(-1).mean().sqrt().clamp_min(0.01))}


@torch.no_grad()
def evaluate(model: EffectModel, data: "Transitions | dict[str, torch.Tensor]",
             batch_size: int = 4096) -> dict[str, float]:
    """Mean effect error (cm) over real objects, with two baselines, and the Eq. 1 loss.

    Baselines: ``zero_cm`` predicts no motion (X' = X); ``arm_cm`` predicts a zero target, i.e.
    the pick object follows the gripper exactly and nothing else moves.
    """
    t = prepare(data) if isinstance(data, Transitions) else data
    was_training = model.training
    model.eval()
    err = zero = arm = sq = 0.0
    count = 0
    N = t["X"].shape[0]
    for s in range(0, N, batch_size):
        sl = slice(s, s + batch_size)
        M = t["mask"][sl]
        d = model(t["X"][sl], t["action"][sl], M) - t["target"][sl]
        err += d.norm(dim=-1)[M].sum().item()
        zero += t["absolute"][sl].norm(dim=-1)[M].sum().item()
        arm += t["target"][sl].norm(dim=-1)[M].sum().item()
        sq += d.pow(2).sum().item()
        count += int(M.sum())
    model.train(was_training)
    return {"err_cm": 100 * err / count, "zero_cm": 100 * zero / count,
            "arm_cm": 100 * arm / count,
            "loss": sq / N / float(model.effect_scale) ** 2}


def train_model(data: "str | Path | Transitions", config: ModelConfig | None = None,
                epochs: int = 100, out_path: str | Path | None = None, *,
                val_data: Transitions | None = None, batch_size: int = 128, lr: float = 1e-4,
                val_fraction: float = 0.1, seed: int = 0, max_steps: int | None = None,
                resume: bool = False, threads: int | None = None, progress: bool = True,
                target_val_cm: float | None = None, time_limit_s: float | None = None,
                only_moved: bool = False) -> TrainResult:
    """Train an EffectModel on a dataset directory or in-memory Transitions.

    Validation data is ``val_data`` if given, else a seeded ``val_fraction`` split of ``data``.
    Validates after every epoch (and when ``max_steps`` stops training early), keeps the best
    model by validation effect error (written to ``out_path`` if given) and the latest state
    (``last_path(out_path)``). ``resume=True`` continues from the latest state up to ``epochs``.
    Training also stops after the epoch in which the validation error reaches ``target_val_cm``
    or the wall time of this call exceeds ``time_limit_s``; history records carry ``elapsed_s``.
    ``only_moved`` keeps the transitions that moved their picked block (`effects.moved_picks`),
    in training and validation alike: what the Symbolic Model learns its symbols from.
    """
    if threads:
        torch.set_num_threads(threads)
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    if only_moved:
        data = data.subset(np.flatnonzero(moved_picks(data.X, data.X_next, data.action)))
        if val_data is not None:
            val_data = val_data.subset(np.flatnonzero(moved_picks(val_data.X, val_data.X_next, val_data.action)))
        if len(data) == 0:
            raise ValueError("no transition moved its picked block: nothing to train on with only_moved")
    if val_data is None:
        train_idx, val_idx = split_indices(len(data), (val_fraction,), seed)
        data, val_data = data.subset(train_idx), data.subset(val_idx)
    if len(val_data) == 0:
        raise ValueError("empty validation split")
    config = config or ModelConfig(n_max=data.n_max)
    if data.n_max > config.n_max:
        raise ValueError(f"dataset n_max {data.n_max} exceeds model n_max {config.n_max}")
    options = {"batch_size": batch_size, "lr": lr, "val_fraction": val_fraction, "seed": seed,
               "num_train": len(data), "num_val": len(val_data), **({"only_moved": True} if only_moved else {})}
    tr, va = prepare(data), prepare(val_data)

    torch.manual_seed(seed)
    model = EffectModel(config)
    stats = normalisation(tr)
    model.set_normalisation(**stats)
    opt = torch.optim.Adam(model.parameters(), lr=lr)
    epoch0, step, history = 0, 0, []
    best: dict[str, Any] = {"val_cm": float("inf"), "epoch": -1, "state": None}

    if resume:
        if out_path is None:
            raise ValueError("resume=True needs out_path")
        lp = last_path(out_path)
        if lp.exists():
            payload = read_checkpoint(lp)
            st = payload.get("train")
            if not st:
                raise ValueError(f"{lp}: no training state to resume from")
            if payload["config"] != config.to_dict() or st["options"] != options:
                raise ValueError(f"{lp}: was trained with a different config/options/data; "
                                 f"refusing to resume ({payload['config']}, {st['options']})")
            model = model_from_payload(payload, lp).train()
            opt = torch.optim.Adam(model.parameters(), lr=lr)
            opt.load_state_dict(st["optimizer"])
            epoch0, step, history = int(st["epoch"]) + 1, int(st["step"]), list(st["history"])
            torch.set_rng_state(st["rng"])
            best_payload = read_checkpoint(out_path)
            best = {"val_cm": float(st["best_val_cm"]), "epoch": int(st["best_epoch"]),
                    "state": best_payload["state_dict"]}
    model.train()

    N = len(data)
    steps_per_epoch = (N + batch_size - 1) // batch_size
    total = epochs * steps_per_epoch if max_steps is None else min(max_steps, epochs * steps_per_epoch)
    bar = tqdm(total=total, initial=min(step, total), disable=not progress, unit="step",
               dynamic_ncols=True)
    scale = float(model.effect_scale)
    train_time, trained = 0.0, 0
    start = time.perf_counter()
    elapsed0 = history[-1]["elapsed_s"] if history else 0.0
    for epoch in range(epoch0, epochs):
        if max_steps is not None and step >= max_steps:
            break
        if target_val_cm is not None and best["val_cm"] <= target_val_cm:
            break
        if time_limit_s is not None and time.perf_counter() - start > time_limit_s:
            break
        perm = torch.randperm(N, generator=torch.Generator().manual_seed(seed * 100003 + epoch))
        run_loss = run_err = run_n = run_b = 0.0
        t0 = time.perf_counter()
        for s in range(0, N, batch_size):
            idx = perm[s:s + batch_size]
            M = tr["mask"][idx]
            pred = model(tr["X"][idx], tr["action"][idx], M)
            d = pred - tr["target"][idx]
            loss = (d / scale).pow(2).sum(dim=(1, 2)).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            step += 1
            trained += len(idx)
            with torch.no_grad():
                run_loss += loss.item() * len(idx)
                run_b += len(idx)
                run_err += d.norm(dim=-1)[M].sum().item() * 100
                run_n += int(M.sum())
            bar.update(1)
            if step % 20 == 0:
                bar.set_postfix(epoch=epoch, loss=f"{run_loss / run_b:.4f}",
                                err_cm=f"{run_err / run_n:.2f}", best_val_cm=f"{best['val_cm']:.2f}")
            if max_steps is not None and step >= max_steps:
                break
        train_time += time.perf_counter() - t0
        val = evaluate(model, va)
        rec = {"epoch": epoch, "step": step, "train_err_cm": run_err / max(run_n, 1),
               "val_err_cm": val["err_cm"], "val_zero_cm": val["zero_cm"], "val_loss": val["loss"],
               "elapsed_s": elapsed0 + time.perf_counter() - start}
        history.append(rec)
        if val["err_cm"] < best["val_cm"]:
            best = {"val_cm": val["err_cm"], "epoch": epoch,
                    "state": copy.deepcopy(model.state_dict())}
            if out_path is not None:
                save_checkpoint(out_path, model, {"kind": "best", "epoch": epoch, "step": step,
                                                  "val_err_cm": val["err_cm"], "options": options})
        if out_path is not None:
            save_checkpoint(last_path(out_path), model, {
                "kind": "last", "epoch": epoch, "step": step, "options": options,
                "optimizer": opt.state_dict(), "rng": torch.get_rng_state(),
                "best_val_cm": best["val_cm"], "best_epoch": best["epoch"], "history": history})
        bar.set_postfix(epoch=epoch, val_cm=f"{val['err_cm']:.2f}", best_val_cm=f"{best['val_cm']:.2f}",
                        zero_cm=f"{val['zero_cm']:.2f}")
    bar.close()

    final = EffectModel(config)
    if best["state"] is None:
        raise ValueError("no training epoch ran (epochs already reached?)")
    final.load_state_dict(best["state"])
    return TrainResult(model=final.eval(), best_val_cm=best["val_cm"], best_epoch=best["epoch"],
                       steps=step, samples_per_s=trained / train_time if train_time else 0.0,
                       history=history, out_path=Path(out_path) if out_path else None)
