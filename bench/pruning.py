"""The continuous search's pruning: the paper's targets against release-point targets, same problems.

    .venv/bin/python bench/pruning.py                         # n = 2..6, k = 1..5, 2 problems per (n, k)
    .venv/bin/python bench/pruning.py --objects 5,6 --per-cell 4 --seed 13

The continuous search alone (`tamp.planning.search.continuous_search`, default SearchConfig: 1,500
expansions), with the bundled Dynamics Model, no kinematics and no execution, on a strict problem set
generated in the Drake world (`evaluation.problems.generate_problems`, seed --seed). Baseline: the
paper's pruning (a misplaced block goes onto the object closest to its goal, or onto itself);
against it, the default pruning, which also offers the object whose release point is closest to the
goal (`SearchConfig.release_targets`). Prints per n: problems whose search reached a goal state
(predicted within 5 cm; execution decides the rest, see `tamp evaluate`), expansions and
search time (median / mean), and the mean-time ratio baseline / default, measured in the same run.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

VARIANTS = {"paper": False, "release": True}  # name -> SearchConfig.release_targets


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", default="2,3,4,5,6", help="object counts (default 2,3,4,5,6)")
    ap.add_argument("--per-cell", type=int, default=2, help="problems per (n, k), k = 1..5 (default 2)")
    ap.add_argument("--seed", type=int, default=41, help="seed of the problem set (default 41)")
    args = ap.parse_args()

    import torch

    from evaluation.problems import generate_problems
    from tamp.planning.models import load_models, pretrained_dir
    from tamp.planning.search import SearchConfig, continuous_search

    torch.set_num_threads(1)
    ns = [int(v) for v in args.objects.split(",")]
    problems = generate_problems(ns, per_cell=args.per_cell, seed=args.seed)
    model = load_models(pretrained_dir(), need_symbolic=False).require_dynamics()
    rows: dict[int, dict[str, list]] = {n: {v: [] for v in VARIANTS} for n in ns}
    for i, p in enumerate(problems):
        for name, release in VARIANTS.items():
            t = time.perf_counter()
            out = continuous_search(model, p.X_init, p.X_goal, replace(SearchConfig(), release_targets=release))
            rows[p.n][name].append((out.solved, out.expanded, time.perf_counter() - t))
        print(f"\rsearching: {i + 1}/{len(problems)}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)

    def med_mean(xs, scale=1.0, digits=0):
        return f"{statistics.median(xs) * scale:.{digits}f} / {statistics.mean(xs) * scale:.{digits}f}"

    print(f"{len(problems)} strict problems, seed {args.seed}, {args.per_cell} per (n, k), k = 1..5; "
          f"node budget {SearchConfig().max_expansions}, no kinematics")
    print("| n | problems | goal reached: paper / release | expansions paper | expansions release | "
          "time paper (ms) | time release (ms) | mean time paper / release |")
    print("|---|---|---|---|---|---|---|---|")
    for n in ns:
        a, b = rows[n]["paper"], rows[n]["release"]
        ta, tb = [r[2] for r in a], [r[2] for r in b]
        print(f"| {n} | {len(a)} | {sum(r[0] for r in a)} / {sum(r[0] for r in b)} | "
              f"{med_mean([r[1] for r in a])} | {med_mean([r[1] for r in b])} | {med_mean(ta, 1e3)} | "
              f"{med_mean(tb, 1e3)} | {statistics.mean(ta) / statistics.mean(tb):.2f}x |")


if __name__ == "__main__":
    main()
