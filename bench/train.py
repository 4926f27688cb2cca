"""Training benchmark: samples/s and time to a validation effect error on this machine.

    .venv/bin/python bench/train.py                      # 50k toy samples (no Drake), 2 threads
    .venv/bin/python bench/train.py --data data/transitions --target-cm 2.5 --time-limit-min 30

Prints (1) training throughput (forward + backward + Adam, samples/s) at the default batch
size, (2) planner-side inference throughput (predict_effect over all 9 n^2 actions of a
4-object scene), (3) the wall time until the validation effect error first reaches
``--target-cm`` (or the error reached within the time limit). Issue 5's target: the default
Dynamics Model reaches <= 2.5 cm within 30 minutes on 2 cores on a 50k-sample dataset.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from learned import EffectModel, ModelConfig, load_transitions, train_model  # noqa: E402
from learned.synthetic import generate  # noqa: E402
from learned.train import normalisation, prepare  # noqa: E402


def training_throughput(data, config: ModelConfig, batch_size: int, steps: int) -> float:
    """Samples/s of optimisation steps on random batches (after 10 warm-up steps)."""
    t = prepare(data)
    model = EffectModel(config)
    model.set_normalisation(**normalisation(t))
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    gen = torch.Generator().manual_seed(0)
    elapsed = 0.0
    for i in range(steps + 10):
        idx = torch.randint(len(data), (batch_size,), generator=gen)
        t0 = time.perf_counter()
        d = model(t["X"][idx], t["action"][idx], t["mask"][idx]) - t["target"][idx]
        loss = d.pow(2).sum(dim=(1, 2)).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        if i >= 10:
            elapsed += time.perf_counter() - t0
    return steps * batch_size / elapsed


def inference_rate(config: ModelConfig, reps: int = 200) -> float:
    """predict_effect calls/s for all 144 actions of a 4-object scene."""
    model = EffectModel(config).eval()
    X = generate(1, seed=0, n_choices=(4,)).X[0].astype(np.float64)
    acts = [(i, d, j, r) for i in range(4) for d in (-1, 0, 1) for j in range(4) for r in (-1, 0, 1)]
    model.predict_effect(X, acts)
    t0 = time.perf_counter()
    for _ in range(reps):
        model.predict_effect(X, acts)
    return reps / (time.perf_counter() - t0)


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, help="dataset directory (default: toy synthetic data)")
    p.add_argument("--synthetic-samples", type=int, default=50_000)
    p.add_argument("--activation", default="sigmoid")
    p.add_argument("--batch-size", type=int, default=128)
    p.add_argument("--lr", type=float, default=1e-4)
    p.add_argument("--threads", default="1,2",
                   help="torch thread counts to measure, comma-separated; the fastest trains")
    p.add_argument("--throughput-steps", type=int, default=200)
    p.add_argument("--target-cm", type=float, default=2.5)
    p.add_argument("--time-limit-min", type=float, default=30.0)
    p.add_argument("--skip-time-to-error", action="store_true")
    p.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    a = p.parse_args(argv)

    thread_counts = [int(t) for t in a.threads.split(",")]
    t0 = time.perf_counter()
    data = load_transitions(a.data) if a.data else generate(a.synthetic_samples, seed=0)
    source = str(a.data) if a.data else f"synthetic toy rules, {a.synthetic_samples} samples"
    print(f"data: {source}: {len(data)} samples, n_max {data.n_max} "
          f"(loaded in {time.perf_counter() - t0:.1f} s); torch {torch.__version__}")
    config = ModelConfig(n_max=data.n_max, activation=a.activation)
    n_params = sum(p.numel() for p in EffectModel(config).parameters())
    print(f"model: {config} ({n_params} parameters)")

    out: dict = {"source": source, "num_samples": len(data), "config": config.to_dict(),
                 "batch_size": a.batch_size, "train_samples_per_s": {},
                 "predict_effect_calls_per_s": {}}
    for t in thread_counts:  # median of 3: the cores may be shared with other work
        torch.set_num_threads(t)
        rate = float(np.median([training_throughput(data, config, a.batch_size, a.throughput_steps)
                                for _ in range(3)]))
        calls = inference_rate(config)
        out["train_samples_per_s"][t], out["predict_effect_calls_per_s"][t] = rate, calls
        print(f"{t} thread(s): training {rate:.0f} samples/s (batch {a.batch_size}); "
              f"predict_effect (144 actions, 4 objects) {calls:.0f} calls/s")
    best_t = max(out["train_samples_per_s"], key=out["train_samples_per_s"].get)
    torch.set_num_threads(best_t)
    out["train_threads"] = best_t

    if not a.skip_time_to_error:
        with tempfile.TemporaryDirectory() as tmp:
            res = train_model(data, config, epochs=10_000, out_path=Path(tmp) / "bench.pt",
                              batch_size=a.batch_size, lr=a.lr, seed=0,
                              target_val_cm=a.target_cm, time_limit_s=a.time_limit_min * 60)
        hit = next((h for h in res.history if h["val_err_cm"] <= a.target_cm), None)
        out["time_to_target_s"] = hit["elapsed_s"] if hit else None
        out["best_val_cm"] = res.best_val_cm
        out["epochs"] = len(res.history)
        out["zero_effect_val_cm"] = res.history[-1]["val_zero_cm"]
        print(f"time to error with {best_t} thread(s):")
        if hit:
            print(f"validation error {hit['val_err_cm']:.2f} cm <= {a.target_cm} cm after "
                  f"{hit['elapsed_s']:.0f} s (epoch {hit['epoch']}, step {hit['step']})")
        else:
            print(f"target {a.target_cm} cm not reached in {a.time_limit_min} min: best "
                  f"{res.best_val_cm:.2f} cm after {len(res.history)} epochs")
        print(f"zero-effect baseline on validation: {out['zero_effect_val_cm']:.2f} cm")
    if a.json:
        a.json.write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    main()
