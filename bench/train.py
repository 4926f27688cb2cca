"""Training benchmark: the paper's settings against the fast defaults, on the same data, in one run.

    .venv/bin/python bench/train.py                                  # 50k toy samples (no Drake)
    .venv/bin/python bench/train.py --data runs/quick/data --target-cm 2.0 --time-limit-min 10

Before: the paper's settings (`TrainConfig()`: batch 128, lr 1e-4, float32, one thread).
After: `TrainConfig.fast()` (batch 1024, lr scaled linearly to 8e-4, bfloat16 autocast where the
CPU has native bfloat16, early stopping), at each of ``--threads``. Prints (1) training throughput
(samples/s of `train_model`'s loop: forward, backward, Adam; median of ``--reps`` one-epoch runs)
and the after/before ratio, (2) planner-side inference throughput (predict_effect over all 144
actions of a 4-object scene), (3) for before and after, the wall time until the validation effect
error first reaches ``--target-cm`` (or the best error within ``--time-limit-min``) and the ratio.
The machine's other load changes both figures alike; it is printed with them (load average).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from learned import EffectModel, ModelConfig, load_transitions, train_model  # noqa: E402
from learned.synthetic import generate  # noqa: E402
from learned.train_config import TrainConfig  # noqa: E402


def throughput(data, config: ModelConfig, settings: TrainConfig, reps: int, max_samples: int) -> float:
    """Median samples/s of `train_model`'s training loop over ``reps`` one-epoch runs (at most
    ``max_samples`` training samples each, so that big datasets stay quick to measure)."""
    sub = data.subset(np.arange(min(len(data), max_samples)))
    rates = [train_model(sub, config, replace(settings, epochs=1, seed=0), progress=False).samples_per_s
             for _ in range(reps)]
    return float(np.median(rates))


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


def time_to_error(data, config: ModelConfig, settings: TrainConfig, target_cm: float, limit_s: float,
                  only_moved: bool) -> dict:
    """Wall time until the validation error first reaches ``target_cm``, within ``limit_s``."""
    with tempfile.TemporaryDirectory() as tmp:
        train = replace(settings, epochs=100_000, seed=0, target_val_cm=target_cm, time_limit_s=limit_s,
                        only_moved=only_moved)
        res = train_model(data, config, train, Path(tmp) / "bench.pt", progress=False)
    hit = next((h for h in res.history if h["val_err_cm"] <= target_cm), None)
    return {"time_to_target_s": hit["elapsed_s"] if hit else None, "epoch": hit["epoch"] if hit else None,
            "best_val_cm": res.best_val_cm, "best_epoch": res.best_epoch, "epochs": res.epochs_reached,
            "elapsed_s": res.history[-1]["elapsed_s"], "stop_reason": res.stop_reason.value,
            "zero_effect_val_cm": res.history[-1]["val_zero_cm"]}


def _describe(s: TrainConfig) -> str:
    return f"batch {s.batch_size}, lr {s.lr:.3g}, {s.precision}, {s.threads} thread(s)"


def main(argv: list[str] | None = None) -> dict:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", type=Path, help="dataset directory (default: toy synthetic data)")
    p.add_argument("--synthetic-samples", type=int, default=50_000)
    p.add_argument("--model", choices=("dynamics", "symbolic"), default="dynamics",
                   help="dynamics: sigmoid, d_z 8, K 4; symbolic: gumbel_sigmoid, d_z 1, K 3, no arm input, "
                   "moving transitions only")
    p.add_argument("--threads", default="1,2", help="thread counts to measure the fast settings at; the fastest trains")
    p.add_argument("--reps", type=int, default=3, help="one-epoch throughput runs per setting (median)")
    p.add_argument("--throughput-samples", type=int, default=20_000, help="training samples per throughput run")
    p.add_argument("--target-cm", type=float, default=2.5)
    p.add_argument("--time-limit-min", type=float, default=5.0, help="per setting, for the time to error")
    p.add_argument("--skip-time-to-error", action="store_true")
    p.add_argument("--json", type=Path, help="also write the figures to this JSON file")
    a = p.parse_args(argv)

    t0 = time.perf_counter()
    data = load_transitions(a.data) if a.data else generate(a.synthetic_samples, seed=0)
    source = str(a.data) if a.data else f"synthetic toy rules, {a.synthetic_samples} samples"
    print(f"data: {source}: {len(data)} samples, n_max {data.n_max} "
          f"(loaded in {time.perf_counter() - t0:.1f} s); torch {torch.__version__}; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    symbolic = a.model == "symbolic"
    config = (ModelConfig(n_max=data.n_max, activation="gumbel_sigmoid", d_z=1, heads=3, arm_input=False) if symbolic
              else ModelConfig(n_max=data.n_max, activation="sigmoid", d_z=8, heads=4))
    n_params = sum(p.numel() for p in EffectModel(config).parameters())
    print(f"model: {a.model} {config} ({n_params} parameters)")

    before = TrainConfig(threads=1)  # the paper's settings
    afters = [TrainConfig.fast(threads=int(t)) for t in a.threads.split(",")]
    out: dict = {"source": source, "num_samples": len(data), "model": a.model, "config": config.to_dict(),
                 "before": asdict(before), "throughput": [], "load_average": os.getloadavg()[0]}
    rate0 = throughput(data, config, before, a.reps, a.throughput_samples)
    print(f"before ({_describe(before)}): {rate0:.0f} samples/s")
    best, best_rate = afters[0], 0.0
    for s in afters:
        rate = throughput(data, config, s, a.reps, a.throughput_samples)
        out["throughput"].append({**asdict(s), "samples_per_s": rate, "ratio": rate / rate0})
        print(f"after  ({_describe(s)}): {rate:.0f} samples/s, {rate / rate0:.2f}x")
        if rate > best_rate:
            best, best_rate = s, rate
    out.update(before_samples_per_s=rate0, after=asdict(best), after_samples_per_s=best_rate,
               samples_per_s_ratio=best_rate / rate0)
    torch.set_num_threads(best.threads)
    out["predict_effect_calls_per_s"] = inference_rate(config)
    print(f"predict_effect (144 actions, 4 objects, {best.threads} thread(s)): "
          f"{out['predict_effect_calls_per_s']:.0f} calls/s")

    if not a.skip_time_to_error:
        print(f"time to a validation error <= {a.target_cm} cm (at most {a.time_limit_min} min each):")
        for name, s in (("before", before), ("after", best)):
            r = out[f"{name}_time_to_error"] = time_to_error(data, config, s, a.target_cm, 60 * a.time_limit_min,
                                                              symbolic)
            reached = (f"{r['time_to_target_s']:.0f} s (epoch {r['epoch']})" if r["time_to_target_s"] is not None
                       else f"not reached: best {r['best_val_cm']:.2f} cm after {r['elapsed_s']:.0f} s")
            print(f"  {name:6} ({_describe(s)}): {reached}")
        t_before, t_after = (out[f"{n}_time_to_error"]["time_to_target_s"] for n in ("before", "after"))
        if t_before and t_after:
            out["time_to_error_ratio"] = t_before / t_after
            print(f"  after is {t_before / t_after:.1f}x faster to {a.target_cm} cm")
        print(f"zero-effect baseline on validation: {out['after_time_to_error']['zero_effect_val_cm']:.2f} cm")
    if a.json:
        a.json.write_text(json.dumps(out, indent=2) + "\n")
    return out


if __name__ == "__main__":
    main()
