"""Dynamics Models side by side: the bundled models (baseline) and new ones (e.g. `tamp practice`'s) planning
the same problems in one run, with kinematics in the planning loop and execution in the fast world.

    .venv/bin/python bench/dynamics.py --new runs/practice/models --seed 4242              # n = 2-4, 150 problems
    .venv/bin/python bench/dynamics.py --new M --objects 5,6 --per-cell 6 --seed 4243       # n = 5-6, 60 problems
    .venv/bin/python bench/dynamics.py --new M --seed 4242 --noise 0.005 --push 0.03,0.05   # a real cell's faults
    .venv/bin/python bench/dynamics.py --new tamp/pretrained --baseline-flags="--config c.toml"   # a planner option

Generates a strict problem set (`tamp problems`), evaluates the methods with each models directory
(`tamp evaluate`, into OUT/baseline and OUT/new, resumable) and prints, per method and models: success
(all and per n), the executed steps that landed 2 and 5 cm or more from the Dynamics Model's prediction and
beyond its own 95 % bound (new models only, when they are an ensemble), planning time per problem (median,
mean, p95), and the new models' figures as ratios or differences against the baseline's, with the problems
gained and lost (paired by problem).
"""
from __future__ import annotations

import argparse
import shlex
import statistics
import subprocess
import sys
from pathlib import Path
from typing import Callable

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def figures(rows: list[dict]) -> dict:
    from evaluation.report.calibration import step_figures

    times = sorted(r["planning_time_s"] for r in rows)
    steps = step_figures([p for r in rows for p in (r.get("predictions") or [])])
    by_n = {n: 100 * statistics.mean(r["success"] for r in rows if r["n"] == n) for n in sorted({r["n"] for r in rows})}
    return {"success": 100 * statistics.mean(r["success"] for r in rows), "by_n": by_n, "steps": steps,
            "median_s": statistics.median(times), "mean_s": statistics.mean(times),
            "p95_s": times[min(len(times) - 1, int(0.95 * len(times)))]}


def line(name: str, f: dict) -> str:
    s = f["steps"]
    bound = "" if s.get("exceeded_pct") is None else f", beyond bound {s['exceeded_pct']:.1f} %"
    per_n = " ".join(f"n={n}: {v:.1f}" for n, v in f["by_n"].items())
    return (f"  {name:9s} success {f['success']:5.1f} % ({per_n}); steps {s.get('steps', 0)}, >= 2 cm "
            f"{s.get('miss_ge_2cm_pct', float('nan')):.1f} %, >= 5 cm {s.get('miss_ge_5cm_pct', float('nan')):.1f} %"
            f"{bound}; planning median {1e3 * f['median_s']:.0f} ms, mean {1e3 * f['mean_s']:.0f} ms, "
            f"p95 {f['p95_s']:.2f} s")


def print_pair(a: dict, b: dict, extra: str = "") -> None:
    """The baseline's figures, the new ones, and new / baseline (`extra`: said after the success change)."""
    print(line("baseline", a))
    print(line("new", b))
    print(f"  new / baseline: success {b['success'] - a['success']:+.1f} points{extra}; planning median "
          f"x{b['median_s'] / a['median_s']:.2f}, mean x{b['mean_s'] / a['mean_s']:.2f}")


def run(main: Callable[[], int | str]) -> None:
    """Exit with main()'s status; Ctrl-C ends in one line (the evaluations keep their rows: the same command
    resumes)."""
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit("bench: interrupted; run the same command again to resume")


def main() -> int | str:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--new", required=True, help="the models directory to measure")
    p.add_argument("--baseline", default="tamp/pretrained", help="the models to measure it against (bundled)")
    p.add_argument("--methods", default="bilevel,bilevel_loop")
    p.add_argument("--objects", default="2,3,4")
    p.add_argument("--per-cell", type=int, default=10)
    p.add_argument("--seed", type=int, default=4242, help="a seed neither model was tuned or practised on")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--noise", default=None, help="observation noise, metres (tamp evaluate --noise)")
    p.add_argument("--push", default=None, help="MIN,MAX metres of one push (tamp evaluate --push)")
    p.add_argument("--max-doubt", default=None, help="METRES: the new models plan with search.max_doubt")
    p.add_argument("--baseline-flags", default="", metavar="FLAGS",
                   help="flags of the baseline's evaluation alone, e.g. --baseline-flags='--config c.toml': "
                   "a planner option measured on the same models")
    p.add_argument("--name", default="new", help="the new models' results folder in OUT (several share OUT/baseline)")
    p.add_argument("--out", type=Path, default=None, help="results directory (default runs/bench-dynamics-...)")
    args = p.parse_args()
    tamp = str(Path(sys.executable).with_name("tamp"))
    faults = ("-noise" + args.noise if args.noise else "") + ("-push" + args.push if args.push else "")
    out = args.out or Path("runs") / f"bench-dynamics-s{args.seed}-n{args.objects.replace(',', '')}{faults}"
    problems = out / "problems.jsonl"
    out.mkdir(parents=True, exist_ok=True)
    if not problems.exists():
        subprocess.run([tamp, "problems", "--out", str(problems), "--objects", args.objects, "--per-cell",
                        str(args.per_cell), "--seed", str(args.seed), "--workers", str(args.workers), "--quiet"],
                       check=True)
    from evaluation.run import read_rows

    rows = {}
    for name, models in (("baseline", args.baseline), (args.name, args.new)):
        command = [tamp, "evaluate", "--models", models, "--problems", str(problems), "--out", str(out / name),
                   "--methods", args.methods, "--workers", str(args.workers), "--no-report"]
        command += ["--noise", args.noise] if args.noise else []
        command += ["--push", args.push] if args.push else []
        if args.max_doubt and name != "baseline":
            config = out / f"{name}.toml"
            config.write_text(f"[search]\nmax_doubt = {float(args.max_doubt)}\n")
            command += ["--config", str(config)]
        command += shlex.split(args.baseline_flags) if name == "baseline" else []
        if subprocess.run(command).returncode != 0:  # tamp evaluate has said why, in one line
            return f"bench: the {name} evaluation stopped (its message is above); nothing compared"
        rows["baseline" if name == "baseline" else "new"] = read_rows(out / name / "rows.jsonl")
    for method in args.methods.split(","):
        base = {r["problem"]: r for r in rows["baseline"] if r["method"] == method}
        new = {r["problem"]: r for r in rows["new"] if r["method"] == method}
        both = sorted(set(base) & set(new))
        a, b = figures([base[k] for k in both]), figures([new[k] for k in both])
        gained = [k for k in both if new[k]["success"] and not base[k]["success"]]
        lost = [k for k in both if base[k]["success"] and not new[k]["success"]]
        print(f"{method} ({len(both)} problems, seed {args.seed}, objects {args.objects}{faults}):")
        sa, sb = a["steps"], b["steps"]
        print_pair(a, b, f" (+{len(gained)} -{len(lost)}); >= 2 cm "
                         f"{sb.get('miss_ge_2cm_pct', 0) - sa.get('miss_ge_2cm_pct', 0):+.1f} points")
        if lost:
            print(f"  lost: {', '.join(lost)}")
    return 0


if __name__ == "__main__":
    run(main)
