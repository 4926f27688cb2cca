"""Where a planning call's time goes: `bilevel` against `cfs`, stage by stage, on the same problems, per block count.

    .venv/bin/python bench/cost.py --problems results/problems/strict-n2-4-s781.jsonl.gz
    .venv/bin/python bench/cost.py --problems results/problems/strict-n5-6-s778.jsonl.gz --config my.toml
    .venv/bin/python bench/cost.py --objects 5,6 --actions 1,3,5,8 --per-cell 3 --seed 11
    .venv/bin/python bench/cost.py --problems results/problems/strict-n5-6-s45.jsonl.gz --against change.toml

Each problem is planned, refined and executed in the fast world by both methods, one after the other in one
process (paired: the same problems under the same load; the method that goes first alternates), as `tamp
evaluate --workers 1` does: kinematics in the planning loop, the configuration's defaults (or --config's),
the one-off costs per block count paid before anything is timed. Printed per n:

- success (every block within eps of its goal) and the share of `bilevel`'s plans that came from Level 1;
- planning time, mean / median / p95, with the final refinement of the returned plan and without it (the
  paper's planning times have no motion refinement);
- each stage's mean, in ms: Level 1's symbols (the Symbolic Model on both scenes), symbolic (the planner over
  N sampled domains) and verify (the Dynamics Model's rollouts); the continuous search; the kinematic
  check; the refinement into motion; the rest of the call;
- the ratio bilevel / cfs of the means and of the medians, with and without refinement (below 1: bilevel
  is faster).

--against FILE plans `bilevel` a second time under FILE's configuration (over --config's), reported as
`bilevel'` with its ratios to `cfs` and to `bilevel`: a change measured before and after in one sitting, on the
same problems under the same load (the three methods' order rotates from problem to problem).

--rows FILE also writes every row (`tamp evaluate`'s row format) as JSON lines, for `tamp report`-style
digging, written whole or not at all; nothing else is written.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tamp.app.args import int_list  # noqa: E402

METHODS = ("cfs", "bilevel")
STAGES = ("symbols", "symbolic", "verify", "search", "feasibility", "refine", "rest")


def stages_ms(row: dict) -> dict[str, float]:
    """A row's planning time split into STAGES, in ms (the rest: what no stage's clock covers)."""
    level1 = row.get("level1_stages_s") or {}
    split = {"symbols": level1.get("symbols", 0.0), "symbolic": level1.get("symbolic", 0.0),
             "verify": level1.get("verify", 0.0), "search": row.get("search_time_s") or 0.0,
             "feasibility": row.get("feasibility_time_s") or 0.0, "refine": row.get("plan_refine_time_s") or 0.0}
    split["rest"] = max(0.0, row["planning_time_s"] - sum(split.values()))
    return {k: 1000 * v for k, v in split.items()}


def summary(values: list[float]) -> str:
    """mean / median / p95 of values in ms."""
    return (f"{statistics.fmean(values):7.1f} {statistics.median(values):7.1f} "
            f"{float(np.percentile(values, 95)):7.1f}")


AGAINST = "bilevel'"  # the name of `bilevel` under --against's configuration in the rows and tables


def ratio_line(name: str, of: tuple[list[float], list[float]], to: tuple[list[float], list[float]]) -> str:
    """The ratios of mean and median planning time of one method to another, with and without refinement."""
    (at, ab), (tt, tb) = of, to
    return (f"{name}: with refinement mean {statistics.fmean(at) / statistics.fmean(tt):.2f}, median "
            f"{statistics.median(at) / statistics.median(tt):.2f}; without mean "
            f"{statistics.fmean(ab) / statistics.fmean(tb):.2f}, median "
            f"{statistics.median(ab) / statistics.median(tb):.2f}")


def report(rows: list[dict]) -> str:
    """The per-n tables of the bench (see the module's docstring)."""
    lines = []
    methods = [*METHODS, *([AGAINST] if any(r["method"] == AGAINST for r in rows) else [])]
    for n in sorted({r["n"] for r in rows}):
        of = {m: sorted((r for r in rows if r["n"] == n and r["method"] == m), key=lambda r: r["problem"])
              for m in methods}
        if not all(of.values()):
            continue
        share = {m: sum(r["level"] == 1 for r in of[m]) / len(of[m]) for m in methods if m != "cfs"}
        lines.append(f"\nn = {n}: {len(of['cfs'])} problems; plans from Level 1: "
                     + ", ".join(f"{m} {100 * v:.0f} %" for m, v in share.items()))
        lines.append(f"{'method':>8} {'success':>8} | {'with refinement, ms':^23} | {'without':^23} | "
                     + " ".join(f"{s:>8}" for s in STAGES))
        lines.append(f"{'':>8} {'':>8} | {'mean':>7} {'median':>7} {'p95':>7} | {'mean':>7} {'median':>7} "
                     f"{'p95':>7} | " + " ".join(f"{'mean':>8}" for _ in STAGES))
        means = {}
        for m, rs in of.items():
            split = [stages_ms(r) for r in rs]
            total = [1000 * r["planning_time_s"] for r in rs]
            bare = [t - s["refine"] for t, s in zip(total, split)]
            means[m] = (total, bare)
            lines.append(f"{m:>8} {100 * statistics.fmean(r['success'] for r in rs):7.1f}% | {summary(total)} | "
                         f"{summary(bare)} | " + " ".join(f"{statistics.fmean(s[k] for s in split):8.1f}"
                                                          for k in STAGES))
        lines.append(ratio_line("bilevel / cfs", means["bilevel"], means["cfs"]))
        if AGAINST in means:
            lines.append(ratio_line(f"{AGAINST} / cfs", means[AGAINST], means["cfs"]))
            lines.append(ratio_line(f"{AGAINST} / bilevel", means[AGAINST], means["bilevel"]))
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--problems", type=Path, help="problem set (tamp problems --out); else generated")
    p.add_argument("--objects", type=int_list, default=(5, 6), help="generated problems: block counts (default 5,6)")
    p.add_argument("--actions", type=int_list, default=(1, 2, 3, 4, 5),
                   help="generated problems: random actions per goal (default 1,2,3,4,5)")
    p.add_argument("--per-cell", type=int, default=2, help="generated problems per (n, k) (default 2)")
    p.add_argument("--seed", type=int, default=11, help="generated problems' seed (default 11)")
    p.add_argument("--models", default="tamp/pretrained", help="models directory (default: the bundled ones)")
    p.add_argument("--config", type=Path, help="configuration file (tamp config show); default: the defaults")
    p.add_argument("--against", type=Path, help="a second configuration file: bilevel planned under it too, as "
                                                "bilevel' (a change before and after, paired)")
    p.add_argument("--rows", type=Path, help="also write every row here (JSON lines)")
    args = p.parse_args()

    import torch

    from evaluation.configuration import EvalConfig
    from evaluation.methods import load_method_models
    from evaluation.problems import generate_problems
    from evaluation.run import Evaluator, row_line
    from guarded.config import read_toml
    from tamp.app.problem import read_problem_set
    from tamp.app.settings import load_settings
    from tamp.planning.config import overlay
    from tamp.records import atomic_write_text

    torch.set_num_threads(1)
    if args.problems is not None:
        problems = read_problem_set(args.problems)
    else:
        problems = generate_problems(args.objects, args.actions, args.per_cell, args.seed)
    config = EvalConfig(planner=load_settings(config=args.config).planner, progress=False)
    against = None if args.against is None else replace(config, planner=overlay(
        config.planner, read_toml(args.against, "configuration"), str(args.against), also=("evaluation", "perception")))
    evaluator = Evaluator(load_method_models(args.models, list(METHODS)), config)
    runs = [(m, config) for m in METHODS] + ([] if against is None else [(AGAINST, against)])
    rows, started = [], time.perf_counter()
    for i, problem in enumerate(problems):
        for name, cfg in runs[i % len(runs):] + runs[:i % len(runs)]:  # the order rotates
            evaluator.config = cfg
            row = evaluator.run(problem, "bilevel" if name == AGAINST else name)
            rows.append({**row, "method": name})
        print(f"\r{i + 1}/{len(problems)} problems, {time.perf_counter() - started:.0f} s", end="", file=sys.stderr)
    print(file=sys.stderr)
    errors = [r for r in rows if r["outcome"] == "error"]
    for r in errors:
        print(f"error: {r['problem']} {r['method']}: {r['error']}", file=sys.stderr)
    rows = [r for r in rows if r["outcome"] != "error"]
    source = args.problems or (f"generated: n {','.join(map(str, args.objects))}, k "
                               f"{','.join(map(str, args.actions))}, {args.per_cell} per cell, seed {args.seed}")
    print(f"# {source}; models {args.models}; configuration {args.config or 'the defaults'}"
          + ("" if args.against is None else f"; {AGAINST}: {args.against}"))
    print(report(rows))
    if args.rows is not None:
        atomic_write_text(args.rows, "".join(row_line(r) for r in rows))


if __name__ == "__main__":
    main()
