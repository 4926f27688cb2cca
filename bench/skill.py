"""Time per pick-place of the `fast` world, split into IK, motion planning and physics.

    .venv/bin/python bench/skill.py [--actions 50] [--objects 3] [--seed 0]

Runs the same random actions (random scenes, uniformly random among the 9 n^2 actions) with the
default skill and with a naive baseline (RRTConnect for every motion with path simplification, and
physics for a fixed 1 s after release), on one core, and prints median / p90 per stage, the
fraction of kinematically feasible actions and the speed-up. Target: median <= 0.15 s per action.
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from tamp.sim import World, WorldConfig


def run(config: WorldConfig, n_actions: int, n_objects: int, seed: int, scene_every: int = 5) -> dict:
    world = World(config, seed=seed)
    rng = np.random.default_rng(seed)
    rows = []
    for k in range(n_actions):
        if k % scene_every == 0:
            world.reset(n_objects=n_objects)
        actions = world.actions()
        _, info = world.step(actions[rng.integers(len(actions))])
        rows.append(info)
    return summarize(rows)


def summarize(rows) -> dict:
    def stats(key, only=None):
        values = np.array([r.timings.get(key, 0.0) for r in rows if only is None or only(r)])
        if values.size == 0:
            return (float("nan"), float("nan"))
        return float(np.median(values)), float(np.percentile(values, 90))

    released = lambda r: r.status == "ok"  # noqa: E731
    return {
        "n": len(rows),
        "total": stats("total"),
        "ik": stats("ik"),
        "motion": stats("motion"),
        "physics": stats("physics", released),
        "total_released": stats("total", released),
        "kinematic_success": float(np.mean([r.status not in ("ik_failure", "motion_failure") for r in rows])),
        "statuses": {s: sum(r.status == s for r in rows) for s in sorted({r.status for r in rows})},
        "settle_time": stats_of([r.settle_time for r in rows if released(r)]),
    }


def stats_of(values):
    values = np.array(values)
    return (float(np.median(values)), float(np.percentile(values, 90))) if values.size else (float("nan"),) * 2


def print_summary(name: str, s: dict) -> None:
    ms = lambda pair: f"{pair[0] * 1e3:7.1f} / {pair[1] * 1e3:7.1f} ms"  # noqa: E731
    print(f"\n{name}: {s['n']} actions  (median / p90)")
    print(f"  total per action        {ms(s['total'])}")
    print(f"  total, released actions {ms(s['total_released'])}")
    print(f"  IK                      {ms(s['ik'])}")
    print(f"  motion planning         {ms(s['motion'])}")
    print(f"  physics (released)      {ms(s['physics'])}   "
          f"simulated {s['settle_time'][0]:.2f} / {s['settle_time'][1]:.2f} s")
    print(f"  kinematically feasible  {s['kinematic_success'] * 100:5.1f} %   outcomes {s['statuses']}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--actions", type=int, default=50)
    parser.add_argument("--objects", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core
    except (AttributeError, OSError):
        pass
    ours = WorldConfig()
    baseline = dataclasses.replace(ours, direct_motions=False, simplify_paths=True, settle_speed=0.0,
                                   settle_angular_speed=0.0, settle_max_time=1.0)
    t0 = time.perf_counter()
    s_ours = run(ours, args.actions, args.objects, args.seed)
    s_base = run(baseline, args.actions, args.objects, args.seed)
    print_summary("skill (straight segment first, no simplification, settle detection)", s_ours)
    print_summary("baseline (RRTConnect + simplify every motion, fixed 1 s physics)", s_base)
    print(f"\nspeed-up, median per action: {s_base['total'][0] / s_ours['total'][0]:.1f}x; "
          f"released actions: {s_base['total_released'][0] / s_ours['total_released'][0]:.1f}x")
    print(f"target: median <= 150 ms per action -> {'met' if s_ours['total'][0] <= 0.15 else 'NOT met'}"
          f"  (wall time {time.perf_counter() - t0:.0f} s)")
    sys.stdout.flush()
    os._exit(0)  # skip OMPL's nanobind leak report at exit


if __name__ == "__main__":
    main()
