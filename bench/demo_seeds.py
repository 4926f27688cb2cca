"""`tamp demo` over a range of seeds, as a new user runs it: how many reach the goal, and why the others did not.

    .venv/bin/python bench/demo_seeds.py --seeds 0-49                 # the defaults: 3 blocks, k = 3, full
    .venv/bin/python bench/demo_seeds.py --seeds 0-19 --objects 5 --actions 4
    .venv/bin/python bench/demo_seeds.py --seeds 0-49 --open-loop     # the baseline: one plan, no loop
    .venv/bin/python bench/demo_seeds.py --seeds 0-49 --models M      # another models directory
    .venv/bin/python bench/demo_seeds.py --seeds 0-99 --preset cameras  # observing through the camera rig

Each seed runs `tamp demo` in its own process (no replay written: --replay goes to a temporary
directory) and is judged by its exit status; the printed cause is the demo's own `cause:` line.
Prints one line per seed, then the count, and the median and mean wall time per demo.
"""
from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def seed_range(text: str) -> list[int]:
    """"0-49" or "1,2,6" as a list of seeds."""
    if "-" in text:
        low, high = text.split("-")
        return list(range(int(low), int(high) + 1))
    return [int(s) for s in text.split(",")]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=seed_range, default=seed_range("0-49"))
    p.add_argument("--objects", type=int, default=3)
    p.add_argument("--actions", type=int, default=3)
    p.add_argument("--fidelity", choices=("full", "fast"), default="full")
    p.add_argument("--open-loop", action="store_true")
    p.add_argument("--models", type=Path, default=None, help="models directory (default: the bundled models)")
    p.add_argument("--preset", default=None, help="a shipped configuration, e.g. cameras (default: the defaults)")
    args = p.parse_args()
    tamp = str(Path(sys.executable).with_name("tamp"))
    reached, times = 0, []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            command = [tamp, "demo", "--seed", str(seed), "--objects", str(args.objects), "--actions",
                       str(args.actions), "--fidelity", args.fidelity, "--replay", f"{tmp}/replay.html"]
            command += ["--open-loop"] if args.open_loop else []
            command += ["--models", str(args.models)] if args.models is not None else []
            command += ["--preset", args.preset] if args.preset is not None else []
            t = time.perf_counter()
            run = subprocess.run(command, capture_output=True, text=True)
            times.append(time.perf_counter() - t)
            if run.returncode not in (0, 1):
                print(f"seed {seed}: exit {run.returncode}: {run.stderr.strip().splitlines()[-1:]}", flush=True)
                continue
            reached += run.returncode == 0
            error = re.search(r"final error ([0-9.]+) cm \(max over blocks", run.stdout)
            cause = re.search(r"cause: (.*)", run.stdout)
            actions = re.search(r"(\d+) action\(s\) executed", run.stdout)
            print(f"seed {seed}: {'reached' if run.returncode == 0 else 'missed'}; final error "
                  f"{error.group(1) if error else '?'} cm; {actions.group(1) if actions else '?'} actions; "
                  f"{times[-1]:.1f} s" + (f"; {cause.group(1)}" if cause else ""), flush=True)
    print(f"{reached} of {len(args.seeds)} seeds reached the goal ({args.objects} blocks, k = {args.actions}, "
          f"{args.fidelity}, {'open' if args.open_loop else 'closed'} loop); wall time per demo median "
          f"{statistics.median(times):.1f} s, mean {statistics.mean(times):.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
