"""Collection throughput: samples/s with 1 and 2 local workers, and the scaling ratio.

    .venv/bin/python bench/collect.py                  # 400 samples per run, objects 2,3,4
    .venv/bin/python bench/collect.py --samples 2000   # longer runs, steadier figures

Each run collects the same dataset (same seed) into a fresh temporary directory with
`tamp.app.collect.collect`; the two datasets are checked to be identical. Reported per run: wall-clock
samples/s including start-up (worker processes, Drake imports, one Drake plant per block-type
layout, built on first use: up to 28 for n in 2..4), and the steady rate over the second half of
the samples. Target: >= 20 samples/s on 2 cores. Wall-clock figures depend on what else the
machine runs, so the CPU seconds per sample (this process and its workers) are printed as well:
2 / (CPU s per sample) is what two free cores would give.
"""
from __future__ import annotations

import argparse
import os
import resource
import tempfile
from pathlib import Path

import numpy as np


def _cpu_seconds() -> float:
    """User + system CPU time of this process and its reaped children (the pool workers)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--samples", type=int, default=400, help="samples per run (default 400)")
    parser.add_argument("--objects", default="2,3,4", help="object counts (default 2,3,4)")
    parser.add_argument("--workers", default="1,2", help="worker counts to compare (default 1,2)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()

    from learned.dataset import load_transitions
    from tamp.app.collect import CollectConfig, collect

    cfg = CollectConfig(samples=args.samples, objects=tuple(int(v) for v in args.objects.split(",")),
                        seed=args.seed)
    workers = [int(w) for w in args.workers.split(",")]
    print(f"collect {cfg.samples} samples, objects {cfg.objects}, {cfg.actions_per_scene} actions per "
          f"scene, on {len(os.sched_getaffinity(0))} CPUs (load average {os.getloadavg()[0]:.2f} at start)")
    print("| workers | wall s | samples/s (wall) | samples/s (second half) | CPU ms per sample |")
    print("|---|---|---|---|---|")
    rates, datasets = {}, []
    with tempfile.TemporaryDirectory(prefix="bench-collect-") as tmp:
        for w in workers:
            cpu0 = _cpu_seconds()
            report = collect(Path(tmp) / f"w{w}", cfg, workers=w, progress=False)
            cpu = (_cpu_seconds() - cpu0) / report.new_samples
            wall = report.new_samples / report.seconds
            rates[w] = (wall, report.rate(0.5))
            print(f"| {w} | {report.seconds:.1f} | {wall:.1f} | {rates[w][1]:.1f} | {cpu * 1e3:.0f} |", flush=True)
            datasets.append(load_transitions(report.directory).arrays())
        same = all(np.array_equal(d[k], datasets[0][k]) for d in datasets[1:] for k in d)
    print(f"datasets identical across worker counts: {'yes' if same else 'NO'}")
    if len(workers) >= 2:
        a, b = workers[0], workers[-1]
        print(f"scaling {a} -> {b} workers: x{rates[b][0] / rates[a][0]:.2f} (wall), "
              f"x{rates[b][1] / rates[a][1]:.2f} (second half)")
    print(f"load average at end {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
