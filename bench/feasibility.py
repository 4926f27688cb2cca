"""The kinematic feasibility check against full refinement: cost per action and agreement.

    PYTHONPATH=. nice -n 10 .venv/bin/python bench/feasibility.py [--pairs 500] [--seed 0]

Random (scene, action) pairs: a random scene of 2-4 blocks, then 0-2 random actions executed in the
`fast` world (so that stacks, shifted and turned blocks occur), then one uniformly random action of
the 9 n^2. Each action is checked by `tamp.sim.kinematic_checker.FeasibilityChecker` on the scene (positions
from X, orientations from the observed scene, as in planning) and fully refined from the same scene
twice: as the planners refine (`FeasibilityChecker.refine`: IK, OMPL motions, grasp, no physics) and
as execution does (`tamp.sim.refine`: the same, with physics after release for the retreat), the
ground truth. A false accept is an action the check passes and refinement fails: the planner would
return a plan that does not refine (target <= 2 % of pairs). A false reject is an action the check
rejects and refinement carries out: a plan the planner misses. Baseline in the same run: full
refinement's cost, of which the check should be a small fraction.
"""
from __future__ import annotations

import argparse
import os
import time
from collections import Counter

os.environ.setdefault("OMP_NUM_THREADS", "1")

import dataclasses

import numpy as np

from tamp.planning.vocabulary import PickPlace
from tamp.sim import World, WorldConfig
from tamp.sim.kinematic_checker import FeasibilityChecker
from tamp.sim.kinematics import Q_HOME
from tamp.sim.refine import refine


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=500)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    scenes = World(WorldConfig(), seed=args.seed)
    checker = FeasibilityChecker()
    executor = World(dataclasses.replace(WorldConfig(), fidelity="fast", simplify_paths=True))
    verdicts, check_s, refine_s, plan_refine_s, reasons, failures = [], [], [], [], Counter(), Counter()
    for _ in range(args.pairs):
        n = int(rng.integers(2, 5))
        X = scenes.reset(n_objects=n, seed=int(rng.integers(2**31 - 1)))
        for _ in range(int(rng.integers(0, 3))):
            X, _ = scenes.step(scenes.actions()[int(rng.integers(9 * n * n))])
        action = scenes.actions()[int(rng.integers(9 * n * n))]
        checker.observe(scenes.scene, Q_HOME)
        checker.check(X, [action])  # first use of a layout builds its checkers: not timed
        t = time.perf_counter()
        reason = checker.check(X, [action])[0]
        check_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        planned = checker.refine([PickPlace(*action)])
        plan_refine_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        executed = refine([PickPlace(*action)], scene=scenes.scene, q_start=Q_HOME, world=executor)
        refine_s.append(time.perf_counter() - t)
        verdicts.append((reason is None, executed.success, planned.success))
        reasons[reason.value if reason is not None else "accepted"] += 1
        if not executed.success:
            failures[executed.failure.stage] += 1
    v = np.array(verdicts)
    accept, refined, planned_ok = v[:, 0], v[:, 1], v[:, 2]
    fa, fr = int(np.sum(accept & ~refined)), int(np.sum(~accept & refined))
    check_ms, refine_ms = np.array(check_s) * 1e3, np.array(refine_s) * 1e3
    print(f"{args.pairs} random (scene, action) pairs, n = 2..4, seed {args.seed}")
    print(f"check verdicts: {dict(reasons)}; refinement failures by stage: {dict(failures)}")
    print(f"agreement with full refinement: {100 * np.mean(accept == refined):.1f} %")
    print(f"  false accepts (check passes, refinement fails): {fa} = {100 * fa / len(v):.2f} % of pairs "
          f"(target <= 2 %), {100 * fa / max(accept.sum(), 1):.2f} % of accepted")
    print(f"  false rejects (check rejects, refinement succeeds): {fr} = {100 * fr / len(v):.2f} % of pairs")
    print(f"the planners' refinement (no physics) agrees with it on {100 * np.mean(planned_ok == refined):.1f} % "
          f"of pairs (median {np.median(plan_refine_s) * 1e3:.1f} ms per action)")
    print(f"cost per action: check median {np.median(check_ms):.2f} ms (p90 {np.percentile(check_ms, 90):.2f}, "
          f"accepted {np.median(check_ms[accept]) if accept.any() else float('nan'):.2f}); full refinement "
          f"(baseline) median {np.median(refine_ms):.1f} ms (p90 {np.percentile(refine_ms, 90):.1f}, refined "
          f"{np.median(refine_ms[refined]) if refined.any() else float('nan'):.1f})")
    print(f"ratio full refinement / check: {np.median(refine_ms) / np.median(check_ms):.0f}x (medians), "
          f"{refine_ms.mean() / check_ms.mean():.0f}x (means)")


if __name__ == "__main__":
    main()
