"""Level-1 (probabilistic symbolic planning) time per problem at N sampled domains, n = 2, 3, 4.

    .venv/bin/python bench/symbolic.py            # defaults: N = 100, 20 problems per n
    .venv/bin/python bench/symbolic.py --quick    # fewer problems, for a smoke run

Operators come from the noisy symbolic blocks world (`symbolic.blocksworld`, 20k transitions per n,
~300 operators for n = 3). Problems: random scene, goal after k = 1..5 random effective actions.
Backends (see `symbolic.planner`): python (in-process BFS), fd (translate once + search binary per
distinct domain, parallel) and the naive baseline fd-naive (driver per sampled domain). The naive
baseline is measured on --naive-domains domains per problem and scaled linearly to N (it has no
dedup or reuse, so its cost is linear in N); the scaled figure is labelled as such. Side by side,
the python and naive FD plans are compared domain by domain (outcome, plan length, identical plan).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from symbolic import blocksworld as bw
from symbolic import fast_downward as fd
from symbolic.operators import learn_operators, stats
from symbolic.pddl import DomainWriter, problem_pddl
from symbolic.planner import SymbolicPlanner
from symbolic.sampling import sample_choices


def pct(xs, q):
    return float(np.percentile(np.asarray(xs), q)) if len(xs) else float("nan")


def fmt(x):
    return f"{x * 1000:8.1f} ms"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--domains", type=int, default=100, help="N sampled domains per problem")
    ap.add_argument("--problems", type=int, default=20, help="problems per n (python backend)")
    ap.add_argument("--fd-problems", type=int, default=3, help="problems per n for the fd backend")
    ap.add_argument("--naive-problems", type=int, default=2, help="problems per n for fd-naive")
    ap.add_argument("--naive-domains", type=int, default=10, help="domains per problem for fd-naive")
    ap.add_argument("--transitions", type=int, default=20000)
    ap.add_argument("--sizes", type=int, nargs="+", default=[2, 3, 4])
    ap.add_argument("--search", default="astar(lmcut())")
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.problems, args.fd_problems, args.naive_problems, args.naive_domains = 5, 1, 1, 4
    N = args.domains
    summary = []
    for n in args.sizes:
        t0 = time.perf_counter()
        ops = learn_operators(bw.random_dataset(args.transitions, (n,), seed=n, p_large=0.003))
        st = stats(ops)
        ppddl_kb = len(DomainWriter(ops).ppddl()) / 1024
        print(f"\n=== n = {n}: {st['n_operators']} operators ({st['n_probabilistic']} probabilistic, "
              f"max {st['effects_per_operator']['max']} effects), PPDDL {ppddl_kb:.0f} KB, "
              f"learned in {time.perf_counter() - t0:.1f} s")
        problems = [bw.random_problem(n, 1 + i % 5, seed=1000 * n + i, p_large=0.003)[0] for i in range(args.problems)]

        py = SymbolicPlanner(ops, backend="python", search=args.search)
        t0 = time.perf_counter()
        py.ground(n)
        print(f"python: grounding once per (operator set, n): {time.perf_counter() - t0:.3f} s, "
              f"{len(py.ground(n))} ground actions")
        rows = []
        for p in problems:
            t0 = time.perf_counter()
            res = py.plan_probabilistic(p, N, seed=0)
            rows.append((time.perf_counter() - t0, res))
        total = [t for t, _ in rows]
        parts = {k: [r.timings.get(k, 0.0) for _, r in rows] for k in ("sampling", "grounding", "planner", "parsing")}
        solved = sum(bool(r.plans) for _, r in rows)
        print(f"python  N={N}: per problem median {fmt(pct(total, 50))}  p90 {fmt(pct(total, 90))}  "
              f"| median split: sampling {fmt(pct(parts['sampling'], 50))}, planner {fmt(pct(parts['planner'], 50))}, "
              f"parsing {fmt(pct(parts['parsing'], 50))}, per-problem setup {fmt(pct(parts['grounding'], 50))}")
        print(f"        searches per problem (median) {pct([r.n_searches for _, r in rows], 50):.0f} of "
              f"{pct([r.n_unique_domains for _, r in rows], 50):.0f} distinct domains; "
              f"{solved}/{len(rows)} problems with a plan; top plan share median "
              f"{pct([r.plans[0].probability for _, r in rows if r.plans], 50):.2f}")

        fdp = SymbolicPlanner(ops, backend="fd", search=args.search, time_limit=60)
        fd_rows = []
        for p in problems[: args.fd_problems]:
            t0 = time.perf_counter()
            res = fdp.plan_probabilistic(p, N, seed=0)
            fd_rows.append((time.perf_counter() - t0, res))
        fd_total = [t for t, _ in fd_rows]
        if fd_rows:
            print(f"fd      N={N}: per problem median {fmt(pct(fd_total, 50))}  p90 {fmt(pct(fd_total, 90))}  "
                  f"| median split: sampling {fmt(pct([r.timings['sampling'] for _, r in fd_rows], 50))}, "
                  f"planner (translate + {pct([r.n_searches - 1 for _, r in fd_rows], 50):.0f} searches on "
                  f"{fdp.workers} workers) {fmt(pct([r.timings['planner'] for _, r in fd_rows], 50))}, "
                  f"parsing {fmt(pct([r.timings['parsing'] for _, r in fd_rows], 50))}")

        naive = SymbolicPlanner(ops, backend="fd-naive", search=args.search, time_limit=60)
        calls, agree_status, agree_len, same_plan, compared = [], 0, 0, 0, 0
        write_t = []
        for p in problems[: args.naive_problems]:
            choices = sample_choices(ops, args.naive_domains, seed=0)
            for c in choices:
                t0 = time.perf_counter()
                domain = naive._domain_text(c, n)
                write_t.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                b = fd.run_fast_downward(domain, problem_pddl(ops, p), args.search, 60)
                calls.append(time.perf_counter() - t0)
                a = py.plan(p, c)
                compared += 1
                agree_status += a.status == b.status
                if a.solved and b.solved:
                    agree_len += len(a.plan) == len(b.plan)
                    same_plan += a.plan == b.plan
                elif a.status == b.status:
                    agree_len += 1
                    same_plan += 1
        if calls:
            per_call = pct(calls, 50)
            naive_problem = (per_call + pct(write_t, 50)) * N
            print(f"fd-naive: one driver call per domain: median {fmt(per_call)} per call (+{fmt(pct(write_t, 50))} "
                  f"writing) -> {naive_problem:.2f} s per problem at N={N} (scaled from {len(calls)} calls)")
            print(f"side by side on {compared} (problem, domain) pairs, python vs FD {args.search}: "
                  f"same outcome {agree_status}/{compared}, same plan length {agree_len}/{compared}, "
                  f"identical plan {same_plan}/{compared}")
            summary.append((n, st["n_operators"], pct(total, 50), pct(total, 90),
                            pct(fd_total, 50) if fd_rows else float("nan"), naive_problem))
    print("\n=== summary: Level-1 seconds per problem at N = %d (median; python p90)" % N)
    print(f"{'n':>2} {'ops':>5} {'python':>9} {'p90':>9} {'fd':>9} {'fd-naive*':>10} "
          f"{'naive/python':>13} {'naive/fd':>9}")
    for n, nops, med, p90, fdm, nv in summary:
        print(f"{n:>2} {nops:>5} {med:9.4f} {p90:9.4f} {fdm:9.3f} {nv:10.2f} {nv / med:12.0f}x {nv / fdm:8.1f}x")
    print("* fd-naive scaled linearly from --naive-domains calls per problem to N.")


if __name__ == "__main__":
    main()
