"""Checkpoint files: plain tensors and JSON-able dicts, loadable with ``weights_only=True``.

Payload: {"format": CKPT_FORMAT, "config": ModelConfig dict, "state_dict": model weights and
normalisation buffers, "train": optional training state (epoch, optimizer, RNG, history)}.
Nothing in it executes code on load. Anything else (another network, a corrupt or truncated
file, a config that does not match the weights) raises ValueError naming the path.
"""
from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import torch

from .dataset import atomic_write_bytes
from .model import EffectModel, ModelConfig

CKPT_FORMAT = "learned-effect-model/1"


def save_checkpoint(path: str | Path, model: EffectModel, train_state: dict[str, Any] | None = None
                    ) -> None:
    """Atomically write model config + weights (+ training state for resuming)."""
    payload: dict[str, Any] = {"format": CKPT_FORMAT, "config": model.config.to_dict(),
                               "state_dict": {k: v.detach().clone() for k, v in
                                              model.state_dict().items()}}
    if train_state is not None:
        payload["train"] = train_state
    _write(path, payload)


def update_train_state(path: str | Path, info: dict[str, Any]) -> None:
    """Atomically merge ``info`` into the training state of the checkpoint at ``path``."""
    payload = read_checkpoint(path)
    payload["train"] = {**payload.get("train", {}), **info}
    _write(path, payload)


def set_object_limit(path: str | Path, n_max: int) -> None:
    """Rewrite the checkpoint at ``path`` to take scenes of up to ``n_max`` objects. The weights do not
    depend on it (attention over any number of objects): raise it only with evidence that the model
    predicts that many objects well (tamp/pretrained/PROVENANCE.md: bench/generalization.py and a
    planning evaluation at those counts)."""
    if not isinstance(n_max, int) or n_max < 1:
        raise ValueError(f"n_max must be a positive integer, got {n_max!r}")
    payload = read_checkpoint(path)
    payload["config"] = {**payload["config"], "n_max": n_max}
    model_from_payload(payload, path)  # still a valid model
    _write(path, payload)


def _write(path: str | Path, payload: dict[str, Any]) -> None:
    """Atomically write a checkpoint payload (serialized in memory first: no partial file on error)."""
    buf = io.BytesIO()
    torch.save(payload, buf)
    atomic_write_bytes(Path(path), lambda f: f.write(buf.getbuffer()))


def read_checkpoint(path: str | Path, formats: tuple[str, ...] = (CKPT_FORMAT,)) -> dict[str, Any]:
    """Load a checkpoint payload safely; ValueError (with the path) if it is not one of `formats`."""
    path = Path(path)
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise
    except Exception as e:  # torch raises many types for corrupt / foreign files
        first = (str(e).strip().splitlines() or [""])[0]  # torch's messages run over many lines
        raise ValueError(f"{path}: not a readable checkpoint ({type(e).__name__}: {first})") from e
    if not isinstance(payload, dict) or payload.get("format") not in formats:
        fmt = payload.get("format") if isinstance(payload, dict) else type(payload).__name__
        raise ValueError(f"{path}: not an effect-model checkpoint (format {fmt!r}, "
                         f"expected {' or '.join(map(repr, formats))})")
    return payload


def model_from_payload(payload: dict[str, Any], path: str | Path = "<checkpoint>") -> EffectModel:
    try:
        config = ModelConfig.from_dict(dict(payload["config"]))
        model = EffectModel(config)
        model.load_state_dict(payload["state_dict"], strict=True)
    except (KeyError, TypeError, ValueError, RuntimeError) as e:
        raise ValueError(f"{path}: checkpoint does not match the EffectModel architecture "
                         f"({type(e).__name__}: {e})") from e
    check_finite(model, path)
    return model.eval()


# the probe scene a loaded model must predict finite numbers on: a cube and a bar on the table, side by side
PROBE_SCENE = np.array([[0.70, -0.10, 0.025, 1.0, 0.0], [0.70, 0.10, 0.025, 0.0, 1.0]])


def check_finite(model: EffectModel, path: str | Path) -> None:
    """Refuse (ValueError naming `path`) a model whose weights hold NaN or infinity, or whose symbols or effects
    on `PROBE_SCENE` do (weights finite but overflowing): such a model would plan nothing and write NaN."""
    for name, tensor in model.state_dict().items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise ValueError(f"{path}: the model's weights are not finite ({name} holds NaN or infinity); the file "
                             "is damaged or its training diverged: train it again")
    X = PROBE_SCENE[:min(len(PROBE_SCENE), model.config.n_max)]
    n = len(X)
    actions = np.array([(i, di, j, dj) for i in range(n) for j in range(n) for di in (-1, 0, 1) for dj in (-1, 0, 1)],
                       np.int64)
    with torch.inference_mode():
        Xt = torch.as_tensor(X, dtype=torch.float32)[None]
        logits = [model.unary_logits(Xt), model.relation_logits(Xt)]
    mean, variance = model.predict_gaussian(np.repeat(X[None], len(actions), axis=0), actions)
    if not all(bool(torch.isfinite(t).all()) for t in logits) or not (np.isfinite(mean).all()
                                                                       and np.isfinite(variance).all()):
        raise ValueError(f"{path}: the model predicts non-finite symbols or effects (NaN or infinity) on a probe "
                         "scene of two blocks; its weights overflow: train it again")


def load_model(path: str | Path) -> EffectModel:
    """The trained EffectModel stored at ``path``, in eval mode (CPU)."""
    return model_from_payload(read_checkpoint(path), path)
