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
    return model.eval()


def load_model(path: str | Path) -> EffectModel:
    """The trained EffectModel stored at ``path``, in eval mode (CPU)."""
    return model_from_payload(read_checkpoint(path), path)
