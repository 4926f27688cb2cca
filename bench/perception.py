"""Perception from the camera rig against the simulator's truth, over the scenes a closed loop observes.

    .venv/bin/python bench/perception.py
    .venv/bin/python bench/perception.py --problems results/problems/strict-n2-4-s781.jsonl.gz --limit 20
    .venv/bin/python bench/perception.py --no-noise --config my.toml

For every problem of the held-out sets (default: strict-n2-4-s781 and strict-n5-6-s778), the world is set to the
initial scene (settled by physics), then executes the problem's own goal-generating actions one by one in the
fast world; the rig observes the scene at the start and after every action (stacks, blocks side by side and
leaning blocks come from those actions). Identities are carried from one observation to the next as a closed loop
would: each observation is assigned to the previous estimates (the first to the problem's initial scene). The
rig and its noise are the configuration's `[perception]` (default: four cameras at 640x480, noise on).

Printed: per class of the true block (on the table, in a stack, leaning) the position error median and p95 (mm),
the orientation error median (deg; the yaw for a block resting flat) and the share of right types; over the
observations the share with the right count (every block found, nothing extra), how many failures were said,
and the time per observation, median and p95 (ms): rendering (Drake), perception, their sum, and the sensor
noise model's share (a simulator's cost that no real camera has), against the issue's targets.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tamp.app.problem import read_problem_set
from tamp.app.settings import add_config_arguments, settings_of

SETS = ("results/problems/strict-n2-4-s781.jsonl.gz", "results/problems/strict-n5-6-s778.jsonl.gz")
# the targets: position median and p95 (mm), yaw median (deg), types right, counts right (%), time (ms)
TARGETS = {"position_median_mm": 3.0, "position_p95_mm": 10.0, "yaw_median_deg": 2.0, "type_right": 99.5,
           "count_right": 99.9, "time_median_ms": 150.0, "time_p95_ms": 400.0}


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def run(problem_files: list[Path], limit: int | None, config, seed: int) -> list:
    """Every observation (tamp.sim.perception_check.Observation) of the problems' scenes, in order."""
    from tamp.sim.cameras import CameraRig
    from tamp.sim.perception_check import observe
    from tamp.sim.world import World

    rig, world = CameraRig(config), World()
    rng = np.random.default_rng(seed)
    world.reset(n_objects=2, seed=0)
    rig.render(world.scene)  # the renderer's first frame (about 0.5 s) is paid before anything is timed
    observations = []
    for path in problem_files:
        problems = read_problem_set(path)[:limit]
        t = time.perf_counter()
        for problem in problems:
            world.reset(X=problem.X_init, seed=problem.seed)
            seen = observe(rig, world.scene, rng, previous=problem.X_init)  # the problem names the blocks
            observations.append(seen)
            known = seen.seen.X if seen.count_right else problem.X_init
            for action in problem.actions:
                world.step(action)
                seen = observe(rig, world.scene, rng, previous=known)  # the last estimates with the right count
                observations.append(seen)
                known = seen.seen.X if seen.count_right else known
        print(f"{path}: {len(problems)} problems observed in {time.perf_counter() - t:.0f} s", file=sys.stderr)
    return observations


def report(observations: list) -> str:
    """The bench's tables (see the module docstring)."""
    from tamp.sim.perception_check import CLASSES

    checks = [c for o in observations for c in o.checks]
    lines = [f"{len(observations)} observations, {len(checks)} blocks", "",
             "class     blocks  found  pos median mm  pos p95 mm  yaw median deg  type right %"]
    for kind in (*CLASSES, "all"):
        mine = [c for c in checks if kind in (c.kind, "all")]
        found = [c for c in mine if c.found]
        errors = [1000 * c.position_error_m for c in found]
        angles = [float(np.degrees(c.orientation_error_rad)) for c in found]
        right = 100 * sum(c.type_right for c in found) / max(1, len(found))
        lines.append(f"{kind:8s} {len(mine):7d} {len(found):6d} {percentile(errors, 50):14.2f} "
                     f"{percentile(errors, 95):11.2f} {percentile(angles, 50):15.2f} {right:13.2f}")
    counted = sum(o.count_right for o in observations)
    unsaid = sum(not o.count_right and o.seen.ok for o in observations)
    lines += ["", f"count right: {counted}/{len(observations)} = {100 * counted / len(observations):.2f} % of "
              f"observations; failures said in {sum(not o.seen.ok for o in observations)}; a wrong count unsaid in "
              f"{unsaid}"]
    times = {"render": [1000 * o.render_s for o in observations],
             "perceive": [1000 * o.perceive_s for o in observations],
             "render + perceive": [1000 * (o.render_s + o.perceive_s) for o in observations],
             "sensor noise model": [1000 * o.noise_s for o in observations]}
    lines += ["", "time per observation    median ms   p95 ms"]
    lines += [f"{name:22s} {statistics.median(v):10.1f} {percentile(v, 95):8.1f}" for name, v in times.items()]
    found = [c for c in checks if c.found]
    figures = {"position_median_mm": percentile([1000 * c.position_error_m for c in found], 50),
               "position_p95_mm": percentile([1000 * c.position_error_m for c in found], 95),
               "yaw_median_deg": percentile([float(np.degrees(c.orientation_error_rad)) for c in found], 50),
               "type_right": 100 * sum(c.type_right for c in found) / max(1, len(found)),
               "count_right": 100 * counted / len(observations),
               "time_median_ms": statistics.median(times["render + perceive"]),
               "time_p95_ms": percentile(times["render + perceive"], 95)}
    lines += ["", "target                    measured   target  met"]
    for name, target in TARGETS.items():
        higher_is_better = name in ("type_right", "count_right")
        met = figures[name] >= target if higher_is_better else figures[name] <= target
        lines.append(f"{name:24s} {figures[name]:9.2f} {target:8.1f}  {'yes' if met else 'NO'}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=Path, action="append", default=None,
                   help="a problem set (repeatable; default: " + ", ".join(SETS) + ")")
    p.add_argument("--limit", type=int, default=None, help="the first N problems of each set (default: all)")
    p.add_argument("--seed", type=int, default=0, help="seed of the sensors' noise (default 0)")
    p.add_argument("--no-noise", action="store_true", help="the rendered depth as it is (perception.noise.on = false)")
    add_config_arguments(p)
    args = p.parse_args(argv)
    config = settings_of(args).perception
    if args.no_noise:
        config = config.without_noise()
    observations = run(args.problems or [Path(s) for s in SETS], args.limit, config, args.seed)
    print(report(observations))
    return 0


if __name__ == "__main__":
    sys.stdout.flush()
    code = main()
    sys.stdout.flush()
    import os

    os._exit(code)  # OMPL's bindings report leaked instances at interpreter exit (BUILD_NOTES.md)
