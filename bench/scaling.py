"""What one more block costs the reproduction: a collected sample and a training epoch per object count.

    .venv/bin/python bench/scaling.py                      # n = 2..6, 3 scenes of 10 actions each
    .venv/bin/python bench/scaling.py --objects 4,6 --scenes 5

Collection: `tamp collect`'s unit of work (`run_scene`: a random scene of n blocks, then 10 chained
random pick-place actions, IK, OMPL motions and physics in the fast world) on one core, seconds per
transition; the first scene of each n, which builds its Drake plants, is not timed. Training: the
Dynamics Model's training loop (forward, backward, Adam; `TrainConfig.fast()`, one torch thread) on
transitions of n blocks padded to n, samples per second (median of --reps one-epoch runs). Ratios are
against the smallest n, measured in the same run. The projection multiplies by the paper-scale
reproduction's 160,000 transitions (2 collection workers) and 144,000 training samples per epoch.
Planning time per n is in the evaluation report's scaling section (`tamp evaluate`, section 13).
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from learned import ModelConfig, train_model  # noqa: E402
from learned.synthetic import generate  # noqa: E402
from learned.train_config import TrainConfig  # noqa: E402
from tamp.app.collect import SceneTask, run_scene  # noqa: E402
from tamp.sim import World, WorldConfig  # noqa: E402

PAPER_SAMPLES, PAPER_EPOCH_SAMPLES, WORKERS = 160_000, 144_000, 2


def collection_s_per_sample(n: int, scenes: int, actions: int) -> float:
    world = World(WorldConfig(), seed=0)
    run_scene(world, SceneTask(1000 + n, 0, (n,), actions))  # builds this layout's plants: not timed
    t = time.perf_counter()
    done = sum(len(run_scene(world, SceneTask(n, k, (n,), actions))) for k in range(1, scenes + 1))
    return (time.perf_counter() - t) / done


def training_samples_per_s(n: int, samples: int, reps: int) -> float:
    data = generate(samples, seed=n, n_choices=(n,), n_max=n)
    settings = replace(TrainConfig.fast(), epochs=1, seed=0)
    rates = [train_model(data, ModelConfig(n_max=n), settings, progress=False).samples_per_s for _ in range(reps)]
    return statistics.median(rates)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--objects", default="2,3,4,5,6", help="object counts (default 2,3,4,5,6)")
    parser.add_argument("--scenes", type=int, default=3, help="timed scenes per count (default 3)")
    parser.add_argument("--actions", type=int, default=10, help="actions per scene (default 10, as collected)")
    parser.add_argument("--train-samples", type=int, default=20_000, help="training samples per epoch (default 20000)")
    parser.add_argument("--reps", type=int, default=3, help="one-epoch training runs per count (default 3)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    ns = [int(x) for x in args.objects.split(",")]
    rows = []
    for n in ns:
        s = collection_s_per_sample(n, args.scenes, args.actions)
        rate = training_samples_per_s(n, args.train_samples, args.reps)
        rows.append((n, s, rate))
        print(f"n={n}: {s * 1000:.0f} ms per collected transition, training {rate:,.0f} samples/s", flush=True)
    n0, s0, r0 = rows[0]
    print(f"\n| n | collection (ms / transition) | x n={n0} | training (samples / s) | epoch x n={n0} | "
          f"paper-scale collection ({PAPER_SAMPLES:,}, {WORKERS} workers, h) | paper-scale epoch (s) |")
    print("|---|---|---|---|---|---|---|")
    for n, s, rate in rows:
        print(f"| {n} | {s * 1000:.0f} | {s / s0:.2f} | {rate:,.0f} | {r0 / rate:.2f} | "
              f"{PAPER_SAMPLES * s / WORKERS / 3600:.1f} | {PAPER_EPOCH_SAMPLES / rate:.1f} |")
    mix = np.mean([s for _, s, _ in rows])
    print(f"\nA collection over n = {args.objects} in equal shares: {mix * 1000:.0f} ms per transition, "
          f"{PAPER_SAMPLES * mix / WORKERS / 3600:.1f} h for {PAPER_SAMPLES:,} transitions on {WORKERS} workers.")


if __name__ == "__main__":
    main()
