"""Tower goals: every block stacked, centred, on one, from the initial states of a strict problem set; the
bundled models plan them with today's search and with a baseline's settings, in one run.

    .venv/bin/python bench/towers.py --seed 6303                       # 25 towers of 3 and 25 of 4 blocks
    .venv/bin/python bench/towers.py --seed 6303 --baseline "[search] release_targets = false"

Random play rarely makes a tower, so the strict sets hold few; a user asks for one first. The goals are
made in the fast world (block 0 centred on block 1, block 2 on block 0, ...; a stack that did not stand is
left out), written to OUT/problems.jsonl, and evaluated (`tamp evaluate`, resumable) into OUT/baseline and
OUT/new; printed as `bench/dynamics.py` prints, per method.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.dynamics import figures, print_pair, run  # noqa: E402


def towers(source: Path, n: int, count: int) -> list[dict]:
    """Up to `count` tower problems of n blocks from the initial states of `source` (a `tamp problems` file)."""
    from tamp.app.runner import execute_plan
    from tamp.planning.vocabulary import BLOCK_HEIGHT

    made: list[dict] = []
    for text in source.read_text().splitlines():
        problem = json.loads(text)
        X_init = np.asarray(problem["X_init"], dtype=float)
        if len(X_init) != n:
            continue
        order = [1, 0, *range(2, n)]  # 0 on 1, 2 on 0, 3 on 2
        plan = [(order[i + 1], 0, order[i], 0) for i in range(n - 1)]
        X_goal = np.asarray(execute_plan(plan, X_init, X_init).X_final)
        levels = sorted(np.round(X_goal[:, 2] / BLOCK_HEIGHT - 0.5).astype(int).tolist())
        if levels != list(range(n)) or np.ptp(X_goal[:, 0]) > 0.01 or np.ptp(X_goal[:, 1]) > 0.01:
            continue  # the stack did not stand
        made.append({"name": f"tower{n}-{len(made):03d}", "X_init": problem["X_init"],
                     "X_goal": np.round(X_goal, 5).tolist(), "seed": problem["seed"], "k": len(plan),
                     "actions": [list(a) for a in plan], "protocol": "strict", "moved": len(plan)})
        if len(made) == count:
            break
    return made


def heights(text: str) -> list[int]:
    """"3,4" as tower heights, each 2-6 blocks (the models' scenes)."""
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers of blocks such as 3,4, got {text!r}") \
            from None
    if not values or any(not 2 <= v <= 6 for v in values):
        raise argparse.ArgumentTypeError(f"tower heights must be 2 to 6 blocks, got {text!r}")
    return values


def main() -> int | str:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seed", type=int, default=6303, help="seed of the strict set whose initial states are used")
    p.add_argument("--per-n", type=int, default=25, help="towers of each height")
    p.add_argument("--objects", type=heights, default=heights("3,4"), help="tower heights (numbers of blocks)")
    p.add_argument("--methods", default="bilevel,bilevel_loop")
    p.add_argument("--models", default="tamp/pretrained")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--baseline", default="[search] release_targets = false", metavar="TOML",
                   help="the baseline's configuration, a TOML table written to OUT/baseline.toml (default: the "
                   "paper's pruning targets)")
    p.add_argument("--out", type=Path, default=None, help="results directory (default runs/bench-towers-sSEED)")
    args = p.parse_args()
    tamp = str(Path(sys.executable).with_name("tamp"))
    out = args.out or Path("runs") / f"bench-towers-s{args.seed}"
    out.mkdir(parents=True, exist_ok=True)
    problems = out / "problems.jsonl"
    if not problems.exists():
        source = out / "strict.jsonl"
        subprocess.run([tamp, "problems", "--out", str(source), "--objects", ",".join(map(str, args.objects)),
                        "--per-cell", "10", "--seed", str(args.seed), "--workers", str(args.workers), "--quiet"],
                       check=True)
        made = [t for n in args.objects for t in towers(source, n, args.per_n)]
        partial = problems.with_suffix(".part")  # written whole, then renamed: an interrupted run makes it again
        partial.write_text("".join(json.dumps(t) + "\n" for t in made))
        partial.replace(problems)
    from evaluation.run import read_rows

    rows = {}
    for name in ("baseline", "new"):
        command = [tamp, "evaluate", "--models", args.models, "--problems", str(problems), "--out", str(out / name),
                   "--methods", args.methods, "--workers", str(args.workers), "--no-report"]
        if name == "baseline":
            config = out / "baseline.toml"
            config.write_text(args.baseline.replace("] ", "]\n", 1) + "\n")
            command += ["--config", str(config)]
        if subprocess.run(command).returncode != 0:  # tamp evaluate has said why, in one line
            return f"bench: the {name} evaluation stopped (its message is above); nothing compared"
        rows[name] = read_rows(out / name / "rows.jsonl")
    for method in args.methods.split(","):
        base = [r for r in rows["baseline"] if r["method"] == method]
        new = [r for r in rows["new"] if r["method"] == method]
        a, b = figures(base), figures(new)
        flags = args.baseline_flags or "the defaults"
        print(f"{method} ({len(new)} tower problems from seed {args.seed}; baseline: {flags}):")
        print_pair(a, b)
    return 0


if __name__ == "__main__":
    run(main)
