"""Training of the effect model: masked MSE of the paper's Eq. 1, Adam, best-by-validation.

Loss per sample = sum over real objects of ||e_hat_i - e_i||^2 (Eq. 1), in units of the
model's ``effect_scale`` (a single scalar, so the geometry of Eq. 1 is kept), averaged over the
batch. With ``effect_loss="distance"`` (our extension) the sum is of ||e_hat_i - e_i|| itself: the
squared loss predicts the mean of a step's outcomes, which lies between them when a block comes to
rest in one of two places (on a cube or beside it); the distance predicts a median, near the more
frequent one. Reported "effect error" is the mean over real objects of ||e_hat_i - e_i||_2 in cm; it
is the same for the arm-subtracted target and for absolute displacements (the arm term is
known exactly). The zero-effect baseline (predict X' = X) is reported next to it.

Files: ``out_path`` holds the best model by validation error; ``<out>.last.pt`` holds the
latest epoch with optimizer and RNG state, which ``resume=True`` continues from exactly.

Speed. The paper's settings (batch 128, lr 1e-4, float32) spend nearly all their time
in matrix products that already run near one core's float32 peak, so the levers are fewer
cheaper flops and fewer steps: ``precision="bfloat16"`` runs the forward and backward passes under
bfloat16 autocast (weights, Adam state, loss and validation stay float32), about 3x the samples/s
on a CPU with AVX512-BF16 or AMX (slower elsewhere: `bf16_fast`); larger batches
(`TrainConfig.fast()`, batch 1024) feed bigger matrix products, with the learning rate scaled
linearly from the paper's 1e-4 at batch 128 (`scaled_lr`: 8e-4 at 1024). On the quick-scale data
the linear scaling kept the error per epoch of batch 128 (so the time to an error falls with the
samples/s), while square-root scaling (2.8e-4) needed ~2.5x the epochs and the unscaled 1e-4 more
still; figures in learned/README.md (training). The epoch's permutation is applied once
(contiguous slices per step), and running statistics stay tensors until the epoch ends.

Stopping. ``epochs`` is a maximum; with ``patience_epochs`` training stops once the validation
error has not improved by ``min_delta_cm`` for that many epochs ("converged"). Why a run stopped
is a `StopReason`, kept in the result, in both checkpoints and on the last history record. Only
``time_limit_s`` depends on the machine: such a run is ``finished == False`` and resuming it gives
what one uninterrupted run would have; resuming a finished run returns its result without training.
"""
from __future__ import annotations

import copy
import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from .checkpoint import model_from_payload, read_checkpoint, save_checkpoint, update_train_state
from .dataset import Transitions, load_transitions
from .effects import arm_displacement, effect_targets, moved_picks
from .losses import bit_usage_penalty, offset_loss, position_loss, transition_loss
from .model import EffectModel, ModelConfig, with_whole_action
from .train_config import (
    StopReason,
    TrainConfig,
    TrainResult,
    train_options,
)

DISTANCE_SMOOTHING_M = 0.001  # metres: the distance loss is sqrt(d^2 + s^2) - s, smooth within about s of 0


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
            "absolute": (Xn[..., :3] - X[..., :3]) * M[..., None], "X_next": Xn}


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


class _Plateau:
    """Early-stopping bookkeeping: the epoch of the last improvement by more than ``min_delta_cm``
    over the error at the previous such improvement (rebuilt from the history on resume)."""

    def __init__(self, min_delta_cm: float, history: list[dict[str, Any]]) -> None:
        self.min_delta_cm, self.ref_cm, self.epoch = min_delta_cm, math.inf, -1
        for h in history:
            self.update(h["epoch"], h["val_err_cm"])

    def update(self, epoch: int, val_cm: float) -> None:
        if val_cm < self.ref_cm - self.min_delta_cm:
            self.ref_cm, self.epoch = val_cm, epoch


def train_model(data: "str | Path | Sequence[str | Path] | Transitions", config: ModelConfig | None = None,
                train: TrainConfig | None = None, out_path: str | Path | None = None, *,
                val_data: Transitions | None = None, resume: bool = False, progress: bool = True,
                init: str | Path | None = None) -> TrainResult:
    """Train an EffectModel on a dataset directory (or several: `load_transitions`) or in-memory Transitions.

    Validation data is ``val_data`` if given, else a seeded ``val_fraction`` split of ``data``.
    Validates after every epoch (and when ``max_steps`` stops training early), keeps the best
    model by validation effect error (written to ``out_path`` if given) and the latest state
    (``last_path(out_path)``). ``resume=True`` continues from the latest state up to ``epochs``.
    Training stops (`StopReason`) after at most ``epochs`` epochs / ``max_steps`` steps, once the
    validation error has not improved by ``min_delta_cm`` for ``patience_epochs`` epochs, once it
    reaches ``target_val_cm``, or (unfinished) before an epoch that would start after
    ``time_limit_s`` of this call's wall time (each call trains at least one epoch); history
    records carry ``elapsed_s``.
    ``only_moved`` keeps the transitions that moved their picked block (`effects.moved_picks`),
    in training and validation alike: what the Symbolic Model learns its symbols from.
    `train` (default `TrainConfig()`, the paper's settings) says how; the names above are its fields.
    ``init`` (a checkpoint) fine-tunes: training starts from its weights and input normalisation instead
    of random ones, with its network settings (``config``, if given, must agree) and the data's object
    limit, e.g. the bundled 2-4 block models on data that adds 5 and 6 blocks.
    """
    train = train or TrainConfig()
    if train.threads:
        torch.set_num_threads(train.threads)
    data, val_data = _datasets(data, val_data, train)
    config, initial = _network(config, data, init)
    _check_heads(train, config)
    options = train_options(train, len(data), len(val_data), init)
    tr, va = prepare(data), prepare(val_data)
    torch.manual_seed(train.seed)
    run = _Run(_new_model(config, tr, initial, init), train, options, out_path)
    if resume:
        run.resume()
    run.model.train()
    reason = run.epochs(tr, va, progress)
    return run.finish(reason)


def moving_steps(data: Transitions) -> Transitions:
    """The transitions that moved their picked block (`effects.moved_picks`): what `only_moved` trains on."""
    return data.subset(np.flatnonzero(moved_picks(data.X, data.X_next, data.action)))


def _datasets(data: "str | Path | Sequence[str | Path] | Transitions", val_data: Transitions | None,
              train: TrainConfig) -> tuple[Transitions, Transitions]:
    """The training and validation transitions (`only_moved` applied; a seeded split when no `val_data`)."""
    if not isinstance(data, Transitions):
        data = load_transitions(data)
    if train.only_moved:
        data = moving_steps(data)
        if val_data is not None:
            val_data = moving_steps(val_data)
        if len(data) == 0:
            raise ValueError("no transition moved its picked block: nothing to train on with only_moved")
    if val_data is None:
        train_idx, val_idx = split_indices(len(data), (train.val_fraction,), train.seed)
        data, val_data = data.subset(train_idx), data.subset(val_idx)
    if len(val_data) == 0:
        raise ValueError("empty validation split")
    return data, val_data


def _network(config: ModelConfig | None, data: Transitions, init: str | Path | None
             ) -> tuple[ModelConfig, EffectModel | None]:
    """The network's settings and, when fine-tuning, the network it starts from (`init`): its own settings, the
    data's object limit, and a spread head or the whole action added if `config` asks for them."""
    initial = None if init is None else model_from_payload(read_checkpoint(init), init)
    if initial is not None:
        own = {**initial.config.to_dict(), "n_max": data.n_max}
        if config is not None and config.spread:  # a spread head may be added to a network without one
            own["spread"] = True
        if config is not None and config.whole_action:  # and the whole action to the paper's encoding
            own["whole_action"] = True
        given = own if config is None else {**config.to_dict(), "n_max": data.n_max}
        if given != own:
            differ = ", ".join(f"{k} {given[k]!r} (its {own[k]!r})" for k in own if given[k] != own[k])
            raise ValueError(f"{init}: the network to fine-tune has other settings than asked for: {differ}")
        config = ModelConfig.from_dict(own)
    config = config or ModelConfig(n_max=data.n_max)
    if data.n_max > config.n_max:
        raise ValueError(f"dataset n_max {data.n_max} exceeds model n_max {config.n_max}")
    return config, initial


def _check_heads(train: TrainConfig, config: ModelConfig) -> None:
    """ValueError when a loss weight asks for a head the network lacks."""
    for weight, head in (("offset_weight", "offset_decoder"),
                         ("position_weight", "position_decoder"),
                         ("transition_weight", "transition_decoder")):
        if getattr(train, weight) and not getattr(config, head):
            raise ValueError(f"{weight} needs a model with {head}=True (the head it trains)")


def _new_model(config: ModelConfig, tr: dict[str, torch.Tensor], initial: EffectModel | None,
               init: str | Path | None) -> EffectModel:
    """A network of `config` normalised on the training tensors, with the weights of `initial` if given (a
    spread head it lacks starts anew, the whole action's new inputs at zero)."""
    model = EffectModel(config)
    model.set_normalisation(**normalisation(tr))
    if initial is not None:  # its weights and normalisation buffers
        state = initial.state_dict()
        if config.whole_action and not initial.config.whole_action:
            state = with_whole_action(state, config)
        missing, unexpected = model.load_state_dict(state, strict=False)
        if unexpected or any(not k.startswith("spread_head.") for k in missing):
            raise ValueError(f"{init}: its weights do not fit the network ({missing + unexpected})")
    return model


class _Run:
    """One training call: the network, its optimizer, the step and epoch counters, the history and the best
    state by validation error, the checkpoints it writes."""

    def __init__(self, model: EffectModel, train: TrainConfig, options: dict[str, Any],
                 out_path: str | Path | None) -> None:
        self.model, self.train, self.options, self.out_path = model, train, options, out_path
        self.opt = torch.optim.Adam(model.parameters(), lr=train.lr)
        self.epoch0, self.step = 0, 0
        self.history: list[dict[str, Any]] = []
        self.best: dict[str, Any] = {"val_cm": float("inf"), "epoch": -1, "state": None}
        self.train_time, self.trained = 0.0, 0

    def resume(self) -> None:
        """Continue from the latest state of `out_path`, if it has one (the same settings, options and data)."""
        if self.out_path is None:
            raise ValueError("resume=True needs out_path")
        lp = last_path(self.out_path)
        if not lp.exists():
            return
        payload = read_checkpoint(lp)
        st = payload.get("train")
        if not st:
            raise ValueError(f"{lp}: no training state to resume from")
        # configs compared as dataclasses: a field added since the run began takes its default
        if ModelConfig.from_dict(payload["config"]) != self.model.config or st["options"] != self.options:
            raise ValueError(f"{lp}: was trained with a different config/options/data; "
                             f"refusing to resume ({payload['config']}, {st['options']})")
        self.model = model_from_payload(payload, lp).train()
        self.opt = torch.optim.Adam(self.model.parameters(), lr=self.train.lr)
        self.opt.load_state_dict(st["optimizer"])
        self.epoch0, self.step = int(st["epoch"]) + 1, int(st["step"])
        self.history = [{k: v for k, v in h.items() if k != "stop_reason"} for h in st["history"]]
        torch.set_rng_state(st["rng"])
        best_payload = read_checkpoint(self.out_path)
        self.best = {"val_cm": float(st["best_val_cm"]), "epoch": int(st["best_epoch"]),
                     "state": best_payload["state_dict"]}

    def epochs(self, tr: dict[str, torch.Tensor], va: dict[str, torch.Tensor], progress: bool) -> StopReason:
        """Train epoch after epoch until a `StopReason`, validating after each; returns it."""
        train, N = self.train, len(tr["X"])
        total = train.epochs * ((N + train.batch_size - 1) // train.batch_size)
        if train.max_steps is not None:
            total = min(train.max_steps, total)
        bar = tqdm(total=total, initial=min(self.step, total), disable=not progress, unit="step", dynamic_ncols=True)
        plateau = _Plateau(train.min_delta_cm, self.history)
        start = time.perf_counter()
        elapsed0 = self.history[-1]["elapsed_s"] if self.history else 0.0
        epoch = self.epoch0
        while (reason := self.stop_reason(epoch, plateau, start)) is None:
            run_loss, run_err, run_b, run_n = self.epoch(tr, epoch, bar)
            val = evaluate(self.model, va)
            self.history.append({"epoch": epoch, "step": self.step, "train_err_cm": 100 * run_err / max(run_n, 1),
                                 "val_err_cm": val["err_cm"], "val_zero_cm": val["zero_cm"], "val_loss": val["loss"],
                                 "elapsed_s": elapsed0 + time.perf_counter() - start})
            plateau.update(epoch, val["err_cm"])
            self.checkpoint(epoch, val["err_cm"])
            bar.set_postfix(epoch=epoch, loss=f"{run_loss / max(run_b, 1):.4f}", val_cm=f"{val['err_cm']:.2f}",
                            best_val_cm=f"{self.best['val_cm']:.2f}", zero_cm=f"{val['zero_cm']:.2f}")
            epoch += 1
        bar.close()
        return reason

    def stop_reason(self, epoch: int, plateau: _Plateau, start: float) -> StopReason | None:
        """Why not to train epoch ``epoch``. The wall-clock cap comes last, so that it never hides another
        reason, and lets every call train an epoch, so that resuming time-limited calls always progresses."""
        train = self.train
        patience = train.patience_epochs
        if patience is not None and plateau.epoch >= 0 and epoch - 1 - plateau.epoch >= patience:
            return StopReason.CONVERGED
        if train.target_val_cm is not None and self.best["val_cm"] <= train.target_val_cm:
            return StopReason.TARGET_REACHED
        if train.max_steps is not None and self.step >= train.max_steps:
            return StopReason.MAX_STEPS
        if epoch >= train.epochs:
            return StopReason.MAX_EPOCHS
        if train.time_limit_s is not None and epoch > self.epoch0 and \
                time.perf_counter() - start > train.time_limit_s:
            return StopReason.TIME_LIMIT
        return None

    def epoch(self, tr: dict[str, torch.Tensor], epoch: int, bar) -> tuple[float, float, int, int]:
        """One epoch of steps over a seeded permutation; (summed loss, summed error in metres, samples, real
        objects) of the samples it trained on."""
        train, model, N = self.train, self.model, len(tr["X"])
        perm = torch.randperm(N, generator=torch.Generator().manual_seed(train.seed * 100003 + epoch))
        # One gather per epoch; the steps then slice contiguous views.
        Xe, Ae, Me, Te = (tr[k][perm] for k in ("X", "action", "mask", "target"))
        Ne = tr["X_next"][perm] if train.transition_weight else None
        run_loss, run_err = torch.zeros((), dtype=torch.float64), torch.zeros((), dtype=torch.float64)
        run_b = 0
        scale = float(model.effect_scale)
        t0 = time.perf_counter()
        for s in range(0, N, train.batch_size):
            batch = slice(s, s + train.batch_size)
            X, A, M, T = Xe[batch], Ae[batch], Me[batch], Te[batch]
            loss, d = self.loss(X, A, M, T, None if Ne is None else Ne[batch], scale)
            self.opt.zero_grad(set_to_none=True)
            loss.backward()
            self.opt.step()
            self.step += 1
            n = X.shape[0]
            self.trained += n
            with torch.no_grad():  # running sums stay tensors: read once per epoch
                run_loss += loss.detach() * n
                run_err += d.detach().norm(dim=-1).mul(M).sum()
            run_b += n
            bar.update(1)
            if train.max_steps is not None and self.step >= train.max_steps:
                break
        self.train_time += time.perf_counter() - t0
        return float(run_loss), float(run_err), run_b, int(Me[:run_b].sum())

    def loss(self, X: torch.Tensor, A: torch.Tensor, M: torch.Tensor, T: torch.Tensor, X_next: torch.Tensor | None,
             scale: float) -> tuple[torch.Tensor, torch.Tensor]:
        """The batch's loss (Eq. 1 in units of the effect scale, plus the weighted auxiliary losses) and the
        effect residuals (metres)."""
        train, model = self.train, self.model
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=train.precision == "bfloat16"):
            u, r, unary, relation = model.encode_logits(X, M)
            pred = model.decode(X, A, M, u, r)
            usage = bit_usage_penalty(unary, relation, M) if train.bit_usage else None
            offsets = offset_loss(model, X, M, u, r, train.offset_radius_m) if train.offset_weight else None
            places = position_loss(model, X, M, u) if train.position_weight else None
            steps = None if X_next is None else transition_loss(model, X, X_next, A, M, u, r)
        d = pred.float() - T
        squared = (d / scale).pow(2).sum(dim=2)  # (B, n) per object, in units of the effect scale
        if train.effect_loss == "distance":  # smoothed at DISTANCE_SMOOTHING_M so its gradient stays finite at 0
            eps = DISTANCE_SMOOTHING_M / scale
            loss = ((squared + eps * eps).sqrt() - eps).sum(dim=1).mean()
        else:
            loss = squared.sum(dim=1).mean()
        if usage is not None:
            loss = loss + train.bit_usage * usage
        if offsets is not None:
            loss = loss + train.offset_weight * offsets
        if places is not None:
            loss = loss + train.position_weight * places
        if steps is not None:
            loss = loss + train.transition_weight * steps
        return loss, d

    def checkpoint(self, epoch: int, val_cm: float) -> None:
        """Keep the state if it is the best so far (written to out_path) and write the latest state."""
        if val_cm < self.best["val_cm"]:
            self.best = {"val_cm": val_cm, "epoch": epoch, "state": copy.deepcopy(self.model.state_dict())}
            if self.out_path is not None:
                save_checkpoint(self.out_path, self.model, {"kind": "best", "epoch": epoch, "step": self.step,
                                                            "val_err_cm": val_cm, "options": self.options})
        if self.out_path is not None:
            save_checkpoint(last_path(self.out_path), self.model, {
                "kind": "last", "epoch": epoch, "step": self.step, "options": self.options,
                "optimizer": self.opt.state_dict(), "rng": torch.get_rng_state(),
                "best_val_cm": self.best["val_cm"], "best_epoch": self.best["epoch"], "history": self.history})

    def finish(self, reason: StopReason) -> TrainResult:
        """Record why training stopped (history, both checkpoints) and return the best network."""
        if self.best["state"] is None:
            raise ValueError("no training epoch ran (epochs already reached?)")
        history, out_path = self.history, self.out_path
        epochs_reached = len(history)
        stop = {"stop_reason": reason.value, "finished": reason is not StopReason.TIME_LIMIT,
                "epochs_reached": epochs_reached}
        if history:
            history[-1]["stop_reason"] = reason.value
        if out_path is not None:
            update_train_state(out_path, stop)
            if last_path(out_path).exists():
                update_train_state(last_path(out_path), {**stop, "history": history})
        final = EffectModel(self.model.config)
        final.load_state_dict(self.best["state"])
        return TrainResult(model=final.eval(), best_val_cm=self.best["val_cm"], best_epoch=self.best["epoch"],
                           steps=self.step, samples_per_s=self.trained / self.train_time if self.train_time else 0.0,
                           history=history, out_path=Path(out_path) if out_path else None,
                           stop_reason=reason, epochs_reached=epochs_reached)
