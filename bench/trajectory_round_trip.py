"""Round trip of exported trajectories: `tamp demo --trajectory`, then the file executed again.

    .venv/bin/python bench/trajectory_round_trip.py [--seeds 0-19] [--out results/trajectories]

For each seed, `tamp demo` runs as by default (3 blocks, goal from 3 random actions, closed loop,
every action executed with the full arm under physics) and writes its trajectory file; the file is
then read back (checked) and executed again in the full world from its recorded initial scene,
back to back as one arm would run it. The figure is the largest distance (mm) of any block between
that re-execution's final scene and the demo's own observed final scene. Also: file size, the time
to sample, check and write it (as `tamp demo` reports it), to read and check it, and to execute it.
Writes round_trip.json and prints a markdown table.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
# the repository first: bench/symbolic.py would shadow the `symbolic` package
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from tamp.app.demo import DemoConfig, run_demo
from tamp.sim.trajectory_file import ROUND_TRIP_TOLERANCE, execute_trajectory, read_trajectory


def seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def one(seed: int, folder: Path) -> dict:
    path = folder / f"seed{seed}.json"
    out = io.StringIO()
    t = time.perf_counter()
    with contextlib.redirect_stdout(out):
        demo = run_demo(DemoConfig(seed=seed, replay=None, trajectory=path))
    demo_seconds = time.perf_counter() - t
    written = re.search(r"trajectory written to .* in ([\d.]+) s\)", out.getvalue())
    row: dict = {"seed": seed, "outcome": demo.outcome.value, "demo_s": round(demo_seconds, 1)}
    if written is None:
        row["note"] = out.getvalue().strip().splitlines()[-1]
        return row
    t = time.perf_counter()
    plan = read_trajectory(path)
    read_s = time.perf_counter() - t
    t = time.perf_counter()
    result = execute_trajectory(plan)
    execute_s = time.perf_counter() - t
    assert demo.loop is not None  # the demo's default: closed loop
    X_demo = demo.loop.X_final
    assert np.allclose(plan.X_final[:, :3], X_demo[:, :3], atol=1e-6)  # the file records the demo's final scene
    deviation = np.linalg.norm(result.X_final[:, :3] - X_demo[:, :3], axis=1)
    row.update(actions=len(plan.actions), skipped=len(plan.skipped), samples=plan.samples,
               arm_motion_s=round(sum(a.duration for a in plan.actions), 2), size_kB=round(path.stat().st_size / 1e3),
               write_s=float(written.group(1)), read_s=round(read_s, 3), execute_s=round(execute_s, 2),
               sim_s=round(result.sim_time, 2), grasped=all(e.grasped for e in result.log),
               max_deviation_mm=round(float(deviation.max()) * 1e3, 4),
               per_action_mm=[round(e.prediction_error * 1e3, 4) for e in result.log])
    return row


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=seeds, default=seeds("0-19"), help="e.g. 0-19 (default)")
    parser.add_argument("--out", type=Path, default=Path("results/trajectories"))
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for seed in args.seeds:
            rows.append(one(seed, Path(folder)))
            print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "round_trip.json").write_text(json.dumps(rows, indent=1) + "\n")
    print("| seed | demo outcome | actions (skipped) | samples | size kB | write s | read s | re-execute s "
          "| max block deviation mm |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "max_deviation_mm" not in r:
            print(f"| {r['seed']} | {r['outcome']} | - | - | - | - | - | - | no trajectory: {r['note']} |")
            continue
        print(f"| {r['seed']} | {r['outcome']} | {r['actions']} ({r['skipped']}) | {r['samples']} | {r['size_kB']} "
              f"| {r['write_s']:.2f} | {r['read_s']:.3f} | {r['execute_s']:.1f} | {r['max_deviation_mm']:.3f} |")
    done = [r for r in rows if "max_deviation_mm" in r]
    within = sum(r["max_deviation_mm"] <= ROUND_TRIP_TOLERANCE * 1e3 for r in done)
    print(f"\n{within} of {len(done)} files end within {ROUND_TRIP_TOLERANCE * 1e3:g} mm of the demo's final scene")
    return 0


if __name__ == "__main__":
    sys.exit(main())
