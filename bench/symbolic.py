"""Level 1 per problem on a learned domain, n = 2 to 6, stage by stage, against the plain planner of
`symbolic.reference` (one search per domain over the grounded task), measured in the same run.

    .venv/bin/python bench/symbolic.py                     # bundled models, n = 2..6, 10 problems per n
    .venv/bin/python bench/symbolic.py --quick             # 4 problems per n
    .venv/bin/python bench/symbolic.py --models runs/paper_scale/models --problems set.jsonl

Problems: --problems FILE (`tamp problems`; its object counts), else generated in the Drake world
(strict protocol, k = 1..3 random actions, seed --seed). The networks' object limit is lifted for the
measurement: the Symbolic and Dynamics Models take any number of objects, the question here is
what Level 1 costs, not how well they predict beyond the counts they were trained on.

Stages per problem (the `bilevel` planner's Level 1 with the default PlanConfig, kinematics off):
symbols (the Symbolic Model on X_init and X_goal), sampling (effects drawn for the operators the
search meets), search (the one search for all N domains, backward distances included), verification
(ranked plans rolled out with the Dynamics Model). Level 1 = their sum.

Baseline (n <= --baseline-max-n; the grounded task of the old planner has 466k ground actions at
n = 5, 1.27 million at n = 6): the plain planner (`symbolic.reference.plan_each_domain`: a
random stream per domain, one breadth-first search per domain over the grounded task, reused between
domains that agree on the operators it touched, 10,000 expansions shared) on the same symbolic
problems and seeds; grounding is paid once per n, outside the timings, as the old planner cached it.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

STAGES = ("symbols", "sampling", "search", "verify", "level1")


def pct(xs, q):
    return float(np.percentile(np.asarray(xs), q)) if len(xs) else float("nan")


def ms(x: float) -> str:
    return f"{x * 1000:9.1f}"


def problems_for(args) -> list:
    from tamp.app.problem import StuckScene, random_problem, read_problem_set

    if args.problems:
        return [p for p in read_problem_set(args.problems) if p.n in args.sizes]
    out = []
    for n in args.sizes:
        for i in range(args.per_n):
            k = 1 + i % 3
            seed = args.seed * 1000 + 100 * n + i
            while True:  # a scene in which the random actions keep failing: the next seed, as `tamp problems`
                try:
                    out.append(random_problem(n, k, seed=seed, name=f"n{n}-k{k}-{i:03d}"))
                    break
                except StuckScene:
                    seed += 10_000
            print(f"\rgenerating problems: n = {n}, {i + 1}/{args.per_n}", end="", flush=True)
    print()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", type=Path, default=None, help="models directory (default: the bundled models)")
    ap.add_argument("--problems", type=Path, default=None, help="problem set (default: generated)")
    ap.add_argument("--sizes", type=lambda s: [int(v) for v in s.split(",")], default=[2, 3, 4, 5, 6],
                    help="object counts (default 2,3,4,5,6)")
    ap.add_argument("--per-n", type=int, default=10, help="generated problems per object count (default 10)")
    ap.add_argument("--seed", type=int, default=7, help="seed of the generated problems (default 7)")
    ap.add_argument("--baseline-max-n", type=int, default=4, help="largest n for the old planner (default 4)")
    ap.add_argument("--quick", action="store_true", help="4 problems per n")
    args = ap.parse_args()
    if args.quick:
        args.per_n = 4

    import torch

    from symbolic.grounding import problem_states
    from symbolic.reference import GroundTask, plan_each_domain
    from tamp.planning.config import KinematicsConfig, PlanConfig
    from tamp.planning.level1 import symbolic_problem
    from tamp.planning.models import load_models, pretrained_dir
    from tamp.planning.planners import plan
    from tamp.planning.search import SearchConfig

    torch.set_num_threads(1)
    models = load_models(args.models or pretrained_dir())
    for m in (models.symbolic, models.dynamics):  # the object limit lifted for the measurement
        m.config = dataclasses.replace(m.config, n_max=max(6, max(args.sizes)))
    assert models.domain is not None
    problems = problems_for(args)
    cfg = PlanConfig(kinematics=KinematicsConfig(feasibility=False),  # Level 2 not run
                     search=SearchConfig(max_expansions=1))
    level1 = cfg.level1
    print(f"domain: {len(models.domain)} operators; N = {level1.n_domains}; Level-1 budget {level1.budget} "
          f"generated states; {len(problems)} problems")
    rows: dict[int, list[dict]] = {}
    old: dict[int, list[float]] = {}
    for n in sorted({p.n for p in problems}):
        batch = [p for p in problems if p.n == n]
        t0 = time.perf_counter()
        models.symbolic_planner(cfg.level1.backend).task(n)
        setup = time.perf_counter() - t0
        plan("bilevel", models, batch[0].X_init, batch[0].X_goal, cfg)  # warm-up: first forward passes
        rows[n] = []
        for p in batch:
            r = plan("bilevel", models, p.X_init, p.X_goal, cfg.with_seed(p.seed))
            t = r.timings
            sym = r.symbolic_stats.get("timings", {})
            row = {"symbols": t.get("symbols", 0.0), "sampling": sym.get("sampling", 0.0),
                   "search": t.get("symbolic", 0.0) - sym.get("sampling", 0.0), "verify": t.get("verify", 0.0),
                   "generated": r.symbolic_stats.get("generated", 0), "level": r.level,
                   "timeouts": r.symbolic_stats.get("outcomes", {}).get("timeout", 0)}
            row["level1"] = row["symbols"] + row["sampling"] + row["search"] + row["verify"]
            rows[n].append(row)
        print(f"n = {n}: lifted task built in {setup * 1000:.0f} ms (once per n); {len(batch)} problems", flush=True)
        if n <= args.baseline_max_n:
            t0 = time.perf_counter()
            ground = GroundTask(models.domain, n)
            print(f"        baseline: grounded task of {len(ground.op_index)} actions built in "
                  f"{time.perf_counter() - t0:.1f} s (once per n)", flush=True)
            old[n] = []
            for p in batch:
                sp = symbolic_problem(models, p.X_init, p.X_goal, cfg.level1, cfg.verify)
                init, goal = problem_states(sp)
                out = plan_each_domain(models.domain, ground, init, goal, cfg.level1.n_domains, p.seed, sp.nonempty)
                old[n].append(out["sampling"] + out["search"])

    print("\nLevel 1 per problem, ms: median / p90 / max / mean (new); the old planner's sampling + search")
    print(f"{'n':>2} {'stage':>10} {'median':>9} {'p90':>9} {'max':>9} {'mean':>9}")
    for n, rs in rows.items():
        for stage in STAGES:
            xs = [r[stage] for r in rs]
            print(f"{n:>2} {stage:>10} {ms(pct(xs, 50))} {ms(pct(xs, 90))} {ms(max(xs))} {ms(float(np.mean(xs)))}")
        sym = [r["sampling"] + r["search"] for r in rs]
        gen = [r["generated"] for r in rs]
        print(f"{n:>2} {'symbolic':>10} {ms(pct(sym, 50))} {ms(pct(sym, 90))} {ms(max(sym))} {ms(float(np.mean(sym)))}"
              f"   (generated states median {pct(gen, 50):.0f}, max {max(gen)}; problems with domains out of "
              f"budget {sum(r['timeouts'] > 0 for r in rs)}; solved at Level 1 {sum(r['level'] == 1 for r in rs)}"
              f"/{len(rs)})")
        if n in old:
            o = old[n]
            print(f"{n:>2} {'old':>10} {ms(pct(o, 50))} {ms(pct(o, 90))} {ms(max(o))} {ms(float(np.mean(o)))}"
                  f"   old / new: median {pct(o, 50) / pct(sym, 50):.0f}x, mean {np.mean(o) / np.mean(sym):.0f}x")
    for sizes in ((2, 3, 4), (5, 6)):  # the figures: one median over the problems of these sizes
        pooled = [r["level1"] for n in sizes for r in rows.get(n, [])]
        if len({n for n in sizes if n in rows}) > 1:
            print(f"n = {sizes[0]}-{sizes[-1]} pooled, level1: median {pct(pooled, 50) * 1000:.1f} ms, "
                  f"p90 {pct(pooled, 90) * 1000:.1f}, mean {float(np.mean(pooled)) * 1000:.1f} "
                  f"({len(pooled)} problems)")
    print("\nsymbolic = sampling + search; level1 = symbols + symbolic + verify.")


if __name__ == "__main__":
    main()
