"""Closed-loop benchmark: the loop that does not know k (`bilevel_loop`, today's default of `tamp plan
--replan` and `tamp demo`) against the paper's k - 1 rounds (`bilevel_replan`, the default before it),
on the same problems in one run, with kinematics in the planning loop and execution in the fast world.

    .venv/bin/python bench/closed_loop.py --models tamp/pretrained --seed 777        # 2-4 blocks, 150 problems
    .venv/bin/python bench/closed_loop.py --objects 5,6 --per-cell 6 --seed 21 --workers 2
    .venv/bin/python bench/closed_loop.py ... --noise 0.005 --push 0.03,0.05        # a real cell's faults

Generates a strict problem set (`tamp problems`), evaluates both methods on it (`tamp evaluate`, into
--out, resumable) and prints success per (n, k) for both, the planning time of a round (median, mean,
p95; the baseline's in the same run) and the failure causes of each method.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from collections import Counter, defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

BASELINE, METHOD = "bilevel_replan", "bilevel_loop"


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0..1) of values, nearest rank."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, round(q * len(ordered) + 0.5) - 1))]


def summary(rows: list[dict]) -> str:
    """Success per (n, k) for both methods, time per planning round, causes: the printed table."""
    by = defaultdict(list)
    for r in rows:
        by[(r["method"], r["n"], r["k"])].append(r)
    ns, ks = sorted({r["n"] for r in rows}), sorted({r["k"] for r in rows})
    lines = [f"success (%) per (n, k): {BASELINE} -> {METHOD}", "n \\ k | " + " | ".join(map(str, ks)) + " | all"]
    for n in ns:
        cells = []
        for k in [*ks, None]:
            pair = []
            for m in (BASELINE, METHOD):
                rs = [r for (mm, nn, kk), g in by.items() if mm == m and nn == n and (k is None or kk == k) for r in g]
                pair.append(100 * sum(r["success"] for r in rs) / len(rs) if rs else float("nan"))
            cells.append(f"{pair[0]:.0f} -> {pair[1]:.0f}")
        lines.append(f"{n} | " + " | ".join(cells))
    for m in (BASELINE, METHOD):
        rs = [r for r in rows if r["method"] == m]
        rounds = [r["planning_time_s"] / ((r["rounds"] or 0) + 1) for r in rs]
        total = [r["planning_time_s"] for r in rs]
        causes = Counter(r["cause"][0] for r in rs if r.get("cause"))
        won = sum(r["success"] for r in rs)
        lines.append(f"{m}: {won}/{len(rs)} = {100 * won / len(rs):.1f} %;"
                     f" planning per round median {1e3 * statistics.median(rounds):.0f} ms, mean "
                     f"{1e3 * statistics.mean(rounds):.0f} ms; per problem median {statistics.median(total):.2f} s, "
                     f"mean {statistics.mean(total):.2f} s, p95 {percentile(total, 0.95):.2f} s; actions mean "
                     f"{statistics.mean(r['executed_actions'] for r in rs):.2f}; causes {dict(causes)}")
    return "\n".join(lines)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--models", default="tamp/pretrained")
    p.add_argument("--objects", default="2,3,4")
    p.add_argument("--actions", default="1,2,3,4,5")
    p.add_argument("--per-cell", type=int, default=10)
    p.add_argument("--seed", type=int, default=777)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--noise", default=None, help="observation noise, metres (tamp evaluate --noise)")
    p.add_argument("--push", default=None, help="MIN,MAX metres of one push (tamp evaluate --push)")
    p.add_argument("--out", type=Path, default=None, help="results directory (default runs/bench-closed-loop-...)")
    args = p.parse_args()
    tamp = str(Path(sys.executable).with_name("tamp"))
    faults = ("-noise" + args.noise if args.noise else "") + ("-push" + args.push if args.push else "")
    out = args.out or Path("runs") / f"bench-closed-loop-s{args.seed}-n{args.objects.replace(',', '')}{faults}"
    problems = out.with_suffix(".problems.jsonl")
    out.parent.mkdir(parents=True, exist_ok=True)
    if not problems.exists():
        subprocess.run([tamp, "problems", "--out", str(problems), "--objects", args.objects, "--actions", args.actions,
                        "--per-cell", str(args.per_cell), "--seed", str(args.seed), "--workers", str(args.workers),
                        "--quiet"], check=True)
    command = [tamp, "evaluate", "--models", args.models, "--problems", str(problems), "--out", str(out),
               "--methods", f"{BASELINE},{METHOD}", "--workers", str(args.workers), "--no-report"]
    command += ["--noise", args.noise] if args.noise else []
    command += ["--push", args.push] if args.push else []
    subprocess.run(command, check=True)
    from evaluation.run import read_rows

    print(summary(read_rows(out / "rows.jsonl")))
    return 0


if __name__ == "__main__":
    sys.exit(main())
