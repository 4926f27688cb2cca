"""Refinement time and success on random feasible actions, and full-physics execution speed.

    .venv/bin/python bench/refine.py [--actions 100] [--execute 20] [--objects 3] [--seed 0]

An action is feasible when the `fast` world executed it. Each is then refined from the same exact
scene (IK, OMPL paths simplified for execution, time parameterization); the first `--execute` of
them are executed with the arm under physics. Baseline in the same run: refinement with every
motion planned by RRTConnect (no straight-segment shortcut). Targets: refinement median <= 0.3 s
per pick-place and >= 99 % success on feasible actions.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from tamp.sim import World, WorldConfig
from tamp.sim.execute import execute
from tamp.sim.refine import refine


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actions", type=int, default=100)
    parser.add_argument("--execute", type=int, default=20)
    parser.add_argument("--objects", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    fast = World(WorldConfig(), seed=args.seed)
    planner = World(dataclasses.replace(WorldConfig(), simplify_paths=True), seed=args.seed)
    baseline = World(dataclasses.replace(WorldConfig(), simplify_paths=True, direct_motions=False), seed=args.seed)
    rng = np.random.default_rng(args.seed)
    times, base_times, ok = [], [], 0
    exec_wall, exec_sim, failures = [], [], []
    n, attempts = 0, 0
    while n < args.actions:
        attempts += 1
        if attempts % 5 == 1:  # a new scene every 5 attempted actions
            fast.reset(n_objects=args.objects)
        scene, q = fast.scene, fast.q.copy()
        actions = fast.actions()
        action = actions[rng.integers(len(actions))]
        _, info = fast.step(action)
        if info.status != "ok":
            fast.set_scene(scene, q)
            continue
        n += 1
        refined = refine([action], scene=scene, q_start=q, world=planner)
        times.append(refined.refine_time)
        ok += refined.success
        if not refined.success:
            failures.append(str(refined.failure))
        if len(base_times) < min(20, args.actions):
            base_times.append(refine([action], scene=scene, q_start=q, world=baseline).refine_time)
        if refined.success and len(exec_wall) < args.execute:
            result = execute(refined)
            exec_wall.append(result.wall_time)
            exec_sim.append(result.sim_time)
        print(f"\r{n}/{args.actions} feasible actions refined", end="", file=sys.stderr)
    print(file=sys.stderr)
    times, base_times = np.array(times), np.array(base_times)
    print(f"refinement per pick-place: median {np.median(times) * 1e3:.0f} ms, "
          f"p90 {np.percentile(times, 90) * 1e3:.0f} ms"
          f"  (target median <= 300 ms)")
    print(f"refinement success on feasible actions: {ok}/{n} = {ok / n * 100:.1f} %  (target >= 99 %)")
    for f in failures:
        print(f"  failed: {f}")
    print(f"baseline (RRTConnect for every motion), {len(base_times)} actions: median "
          f"{np.median(base_times) * 1e3:.0f} ms -> "
          f"speed-up {np.median(base_times) / np.median(times[:len(base_times)]):.1f}x")
    if exec_wall:
        w, s = np.array(exec_wall), np.array(exec_sim)
        print(f"full-physics execution, {len(w)} actions: median {np.median(w):.2f} s wall for "
              f"{np.median(s):.2f} s simulated; real-time factor {np.sum(s) / np.sum(w):.1f}x")
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    main()
