"""The slow tail of planning: today's continuous search against the one that checks less and stops on evidence.

    .venv/bin/python bench/planning_tail.py --seed 5302                          # n = 2-4, 150 strict problems
    .venv/bin/python bench/planning_tail.py --objects 5,6 --per-cell 6 --seed 5303
    .venv/bin/python bench/planning_tail.py --problems P.jsonl --no-execute      # a set of your own, planning only

Plans every problem with `bilevel` twice in one process, one after the other, with the bundled models
and kinematics in the planning loop, default limits otherwise:
- baseline: the search runs to its node budget (`SearchConfig(stall=None, greedy_stall=None)`) and the
  kinematic check starts every action from scratch on the world's collision checker
  (`FeasibilityChecker(shortcuts=False)`);
- new: the defaults (the stall cut from 5 blocks on; the pick half of a check remembered for the other places of the
  same grasp, the carried boxes posed as stand-ins in a collision checker of their own, a place into a
  standing block rejected before IK, grasps that cannot hold a block left out before prediction).
Prints, per number of blocks and in all: planning time per problem (median, mean, p95, max), plans
found, success (the plan refined and executed in the fast world, within the 5 cm tolerance; a plan equal
to the baseline's is not executed again), kinematic checks and expansions per problem, the ratios new /
baseline, and every problem whose plan differs. The problem set is generated (`tamp problems`) unless
--problems is given.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROOT = Path(__file__).resolve().parents[1]


def percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def summary(rows: list[dict]) -> str:
    t = [r["time_s"] for r in rows]
    success = [r["success"] for r in rows if r["success"] is not None]
    text = (f"median {1e3 * statistics.median(t):6.0f} ms, mean {statistics.mean(t):5.2f} s, "
            f"p95 {percentile(t, 95):5.2f} s, max {max(t):5.2f} s; "
            f"plans {sum(r['solved'] for r in rows):3d}/{len(rows)}")
    if success:
        text += f", success {100 * statistics.mean(success):5.1f} %"
    return text + (f"; checks per problem median {statistics.median(r['checks'] for r in rows):5.0f}, "
                   f"mean {statistics.mean(r['checks'] for r in rows):6.0f}; expansions mean "
                   f"{statistics.mean(r['expanded'] for r in rows):5.0f}")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=Path, default=None, help="problem set (default: generated from the flags below)")
    p.add_argument("--objects", default="2,3,4")
    p.add_argument("--per-cell", type=int, default=10)
    p.add_argument("--seed", type=int, default=5302, help="a seed the search was not tuned on")
    p.add_argument("--models", default=str(ROOT / "tamp" / "pretrained"))
    p.add_argument("--no-execute", dest="execute", action="store_false", help="planning only (no success figures)")
    args = p.parse_args()

    import torch

    from tamp.app.problem import read_problem_set
    from tamp.app.runner import execute_plan, executing_world
    from tamp.planning.config import PlanConfig
    from tamp.planning.models import load_models
    from tamp.planning.planners import plan
    from tamp.planning.search import all_actions
    from tamp.planning.verify import EPS_SUCCESS
    from tamp.sim.kinematic_checker import FeasibilityChecker
    from tamp.sim.kinematics import forget_ik_answers

    torch.set_num_threads(1)
    path = args.problems
    if path is None:
        path = Path(tempfile.mkdtemp(prefix="planning-tail-")) / "problems.jsonl"
        subprocess.run([sys.executable, "-m", "tamp.app.cli", "problems", "--out", str(path), "--objects", args.objects,
                        "--per-cell", str(args.per_cell), "--seed", str(args.seed), "--quiet"], check=True, cwd=ROOT)
    problems = read_problem_set(path)
    models = load_models(args.models)
    new_checker = FeasibilityChecker()
    setups = {"baseline": (replace(PlanConfig(), search=replace(PlanConfig().search, stall=None, greedy_stall=None)),
                           FeasibilityChecker(world=new_checker.world, shortcuts=False)),
              "new": (PlanConfig(), new_checker)}
    world = executing_world("fast") if args.execute else None
    rows: dict[str, list[dict]] = {name: [] for name in setups}
    warm: set[tuple] = set()
    for number, problem in enumerate(problems, start=1):
        plans: dict[str, object] = {}
        for name, (cfg, checker) in setups.items():
            scene = checker.reset(problem.X_init)
            layout = (name, tuple(int(t) for t in scene.types), problem.n)
            if layout not in warm:  # one-off costs (collision models, symbolic grounding) before any timing
                checker.check(problem.X_init, all_actions(problem.n))
                models.symbolic_planner().task(problem.n)
                warm.add(layout)
            checks = checker.num_checks
            forget_ik_answers()  # each call starts with the IK memory a fresh process has
            t = time.perf_counter()
            result = plan("bilevel", models, problem.X_init, problem.X_goal, cfg.with_seed(problem.seed),
                          kinematics=checker)
            elapsed = time.perf_counter() - t
            actions = None if result.plan is None else [tuple(int(v) for v in a) for a in result.plan]
            success = None
            if world is not None:
                if actions is None:
                    success = False
                elif actions == plans.get("baseline") and rows["baseline"][-1]["success"] is not None:
                    success = rows["baseline"][-1]["success"]
                else:
                    world.rng = np.random.default_rng(0)
                    ex = execute_plan(actions, problem.X_init, problem.X_goal, "fast", world=world)
                    success = bool(ex.refined.success and ex.error < EPS_SUCCESS)
            plans[name] = actions
            rows[name].append({"name": problem.name, "n": problem.n, "time_s": elapsed, "solved": result.solved,
                               "success": success, "checks": checker.num_checks - checks, "plan": actions,
                               "expanded": 0 if result.search is None else result.search.expanded,
                               "status": None if result.search is None else str(result.search.status)})
        print(f"\r{number}/{len(problems)} problems", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)

    print(f"bilevel, {len(problems)} problems of {path}, models {args.models}")
    for n in [*sorted({p.n for p in problems}), None]:
        label = "all" if n is None else f"n = {n}"
        print(label)
        for name in setups:
            print(f"  {name:8s} {summary([r for r in rows[name] if n is None or r['n'] == n])}")
    base, new = rows["baseline"], rows["new"]
    ratio = {q: percentile([r["time_s"] for r in new], q) / percentile([r["time_s"] for r in base], q)
             for q in (50, 95, 100)}
    print(f"new / baseline: median x{ratio[50]:.2f}, p95 x{ratio[95]:.2f}, max x{ratio[100]:.2f}, checks x"
          f"{sum(r['checks'] for r in new) / max(1, sum(r['checks'] for r in base)):.2f}, total time x"
          f"{sum(r['time_s'] for r in new) / sum(r['time_s'] for r in base):.2f}")
    differ = [(b, a) for b, a in zip(base, new) if b["plan"] != a["plan"]]
    print(f"plans that differ: {len(differ)}")
    for b, a in differ:
        print(f"  {b['name']}: baseline {b['status']} after {b['expanded']} expansions, success {b['success']}; "
              f"new {a['status']} after {a['expanded']}, success {a['success']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
