"""The ablation of our extensions: each switched off alone against the default, on the same problems.

    .venv/bin/python bench/ablation.py --problems results/problems/strict-n2-4-s781.jsonl.gz --out runs/ablation
    .venv/bin/python bench/ablation.py --problems P.jsonl --only search.look_on,loop.widen

One `tamp evaluate` per extension (OUT/NAME, resumable) with a configuration file that switches it off, and
one of the default (OUT/default), all on the same problems and methods: success of the default and without
the extension, and the problems each one alone solves (paired). Planning time is measured apart, since
evaluations minutes apart run under other loads: with `--time` (open-loop methods), each problem is planned
with the default and without the extension back to back in this process, in alternating order, and the
ratio is per problem (below 1: faster without it), mean and median. An extension whose removal changes
neither success nor time beyond noise does not pay.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# each extension beyond the paper, and the TOML that switches it off (tamp/planning/config.py says what it does)
EXTENSIONS = {
    "level1.focus_from": "[level1]\nfocus_from = false", "level1.serial": "[level1]\nserial = false",
    "level1.wait_beyond": "[level1]\nwait_beyond = false",
    "search.greedy_from": "[search]\ngreedy_from = false", "search.greedy_stall": "[search]\ngreedy_stall = false",
    "search.resolution": "[search]\nresolution = 0.01", "search.look_on": "[search]\nlook_on = 0",
    "search.release_targets": "[search]\nrelease_targets = false",
    "loop.keep_plan": "[loop]\nkeep_plan = false", "loop.commit": "[loop]\ncommit = false",
    "loop.widen": "[loop]\nwiden = false", "loop.stall": "[loop]\nstall = false",
}


def _evaluate(tamp: str, args: argparse.Namespace, out: Path, toml: str | None) -> list[dict]:
    from evaluation.run import read_rows

    command = [tamp, "evaluate", "--models", args.models, "--problems", str(args.problems), "--out", str(out),
               "--methods", args.methods, "--workers", str(args.workers), "--quiet", "--no-report"]
    if toml is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out.parent / f"{out.name}.toml").write_text(toml + "\n")
        command += ["--config", str(out.parent / f"{out.name}.toml")]
    if subprocess.run(command).returncode != 0:  # tamp evaluate has said why, in one line
        raise SystemExit(f"bench: the evaluation into {out} stopped (its message is above)")
    return read_rows(out / "rows.jsonl")


def _compare(name: str, base: list[dict], rows: list[dict], methods: list[str]) -> list[str]:
    lines = []
    for method in methods:
        b = {r["problem"]: r for r in base if r["method"] == method}
        a = {r["problem"]: r for r in rows if r["method"] == method}
        both = sorted(set(a) & set(b))
        if not both:
            continue
        ratios = [a[p]["planning_time_s"] / b[p]["planning_time_s"] for p in both if b[p]["planning_time_s"] > 0]
        gained = sum(a[p]["success"] and not b[p]["success"] for p in both)
        lost = sum(b[p]["success"] and not a[p]["success"] for p in both)
        lines.append(f"| {name} | {method} | {100 * sum(b[p]['success'] for p in both) / len(both):.1f} | "
                     f"{100 * sum(a[p]['success'] for p in both) / len(both):.1f} | {gained} | {lost} | "
                     f"{statistics.fmean(ratios):.2f} | {statistics.median(ratios):.2f} | {len(both)} |")
    return lines


def paired_times(problems: Path, models_dir: str, method: str, toml: str) -> list[float]:
    """Per problem, planning time without the extension over the default's, planned back to back (open loop)."""
    import time

    import torch

    from guarded.config import parse_toml
    from tamp.app.problem import read_problem_set
    from tamp.app.runner import kinematics_for
    from tamp.planning.config import PlanConfig, overlay
    from tamp.planning.models import load_models
    from tamp.planning.planners import plan

    torch.set_num_threads(1)
    models = load_models(models_dir)
    configs = (PlanConfig(), overlay(PlanConfig(), parse_toml(toml, "extension"), "extension"))
    warm: set[int] = set()
    ratios = []
    for i, p in enumerate(read_problem_set(problems)):
        seconds = [0.0, 0.0]
        for which in ((0, 1) if i % 2 == 0 else (1, 0)) if p.n in warm else (0, 0, 1):  # warm up each n first
            cfg = configs[which].with_seed(p.seed)
            kinematics = kinematics_for(method, cfg)
            if kinematics is not None:
                kinematics.reset(p.X_init)
            start = time.perf_counter()
            plan(method, models, p.X_init, p.X_goal, cfg, kinematics=kinematics)
            seconds[which] = time.perf_counter() - start
        warm.add(p.n)
        ratios.append(seconds[1] / seconds[0])
    return ratios


def main() -> int | str:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=Path, required=True, help="a held-out problem set (tamp problems)")
    p.add_argument("--out", type=Path, required=True, help="results directory (one folder per extension)")
    p.add_argument("--models", default="tamp/pretrained")
    p.add_argument("--methods", default="bilevel,bilevel_loop")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--only", default=None, help="comma-separated extensions (default: every one of EXTENSIONS)")
    p.add_argument("--time", default=None, metavar="METHOD",
                   help="instead of evaluating: time METHOD's planning calls paired per problem (e.g. bilevel)")
    args = p.parse_args()
    names = list(EXTENSIONS) if args.only is None else args.only.split(",")
    unknown = [n for n in names if n not in EXTENSIONS]
    if unknown:
        return f"bench: unknown extension {unknown[0]}; known: {', '.join(EXTENSIONS)}"
    if args.time is not None:
        print("| without | method | time ratio mean | median | p90 | problems |\n|---|---|---|---|---|---|")
        for name in names:
            r = sorted(paired_times(args.problems, args.models, args.time, EXTENSIONS[name]))
            print(f"| {name} | {args.time} | {statistics.fmean(r):.2f} | {statistics.median(r):.2f} | "
                  f"{r[int(0.9 * (len(r) - 1))]:.2f} | {len(r)} |", flush=True)
        return 0
    tamp = str(Path(sys.executable).with_name("tamp"))
    methods = args.methods.split(",")
    base = _evaluate(tamp, args, args.out / "default", None)
    table = ["| without | method | default success (%) | without (%) | solved only without | solved only with | "
             "time ratio mean | median | problems |", "|---|---|---|---|---|---|---|---|---|"]
    for name in names:
        table += _compare(name, base, _evaluate(tamp, args, args.out / name.replace(".", "-"), EXTENSIONS[name]),
                          methods)
        print("\n".join(table), flush=True)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit("bench: interrupted; run the same command again to resume")
