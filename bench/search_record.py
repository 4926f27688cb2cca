"""The search record's cost: planning with and without it on the same problems, and its size.

    .venv/bin/python bench/search_record.py                          # 30 problems of the held-out set
    .venv/bin/python bench/search_record.py --every 1 --size-count 5

Paired and interleaved: each problem of --problems (every --every-th) is planned by `bilevel` with
kinematics, as `tamp plan` plans it, once without a record and once with one (a `Recorder` active and the
round built with its candidates' facts, `tamp.planning.search_record.round_record`, as `tamp plan --search`
does; writing the file is not counted), the order alternating from problem to problem, each call with a
fresh kinematic checker. Prints the median planning time of each, the ratio of the medians and the median of
the per-problem ratios (target: at most 1.10), and the record's JSON size for the largest search met. Then the
size of the record of searches that run to the 1,500-node budget (`_sizes`: --size-count problems with the most
blocks, a goal out of reach), target at most 2 MB, and the time to build it.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--problems", type=Path, default=ROOT / "results/problems/strict-n2-4-s781.jsonl.gz",
                    help="problem set (default: the held-out strict-n2-4-s781)")
    ap.add_argument("--every", type=int, default=5, help="plan every N-th problem of the set (default 5: 30 of 150)")
    ap.add_argument("--size-count", type=int, default=2,
                    help="searches to the node budget measured for the record's size (default 2)")
    args = ap.parse_args()

    import torch

    from tamp.app.problem import read_problem_set
    from tamp.app.runner import kinematics_for
    from tamp.planning.config import PlanConfig
    from tamp.planning.models import load_bit_names, load_models, pretrained_dir
    from tamp.planning.planners import plan
    from tamp.planning.search_record import facts_reader, round_record
    from tamp.planning.search_trace import Recorder, recording

    torch.set_num_threads(1)
    models = load_models(pretrained_dir(), need_symbolic=True)
    names = load_bit_names(pretrained_dir())
    assert models.domain is not None  # need_symbolic
    problems = read_problem_set(args.problems)[::args.every]
    off: list[float] = []
    on: list[float] = []
    largest = {"expanded": -1, "bytes": 0, "name": ""}  # the largest search met and its record round's size

    def timed(p, record: bool) -> float:
        cfg = PlanConfig().with_seed(p.seed)
        kinematics = kinematics_for("bilevel", cfg)
        assert kinematics is not None  # the default configuration checks kinematics
        kinematics.reset(p.X_init)
        recorder = Recorder() if record else None
        t = time.perf_counter()
        with recording(recorder):
            result = plan("bilevel", models, p.X_init, p.X_goal, cfg, kinematics=kinematics)
        if recorder is not None:
            facts = facts_reader(models.domain.n_unary, models.domain.n_relations, names, p.n)
            round_ = round_record(0, result, recorder, p.X_init, facts)
        seconds = time.perf_counter() - t
        if recorder is not None and recorder.tree is not None and len(recorder.tree.order) > largest["expanded"]:
            largest.update(expanded=len(recorder.tree.order), name=p.name,
                           bytes=len(json.dumps(round_, separators=(",", ":"))))
        return seconds

    for i, p in enumerate(problems):
        first = i % 2 == 0  # alternate which variant runs first
        for record in ((False, True) if first else (True, False)):
            (on if record else off).append(timed(p, record))
        print(f"\rplanning: {i + 1}/{len(problems)}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    ratios = [b / a for a, b in zip(off, on)]
    print(f"{len(problems)} problems of {args.problems.name} (every {args.every}th), bilevel with kinematics, "
          f"paired and interleaved")
    print("| planning | median (s) | mean (s) |")
    print("|---|---|---|")
    print(f"| without the record | {statistics.median(off):.3f} | {statistics.mean(off):.3f} |")
    print(f"| with the record | {statistics.median(on):.3f} | {statistics.mean(on):.3f} |")
    print(f"ratio of the medians {statistics.median(on) / statistics.median(off):.3f}; median of the per-problem "
          f"ratios {statistics.median(ratios):.3f} (target <= 1.10)")
    print(f"largest search met: {largest['name']}, {largest['expanded']} expansions, record round "
          f"{largest['bytes'] / 1e6:.2f} MB")
    _sizes(problems, args.size_count, models)


def _sizes(problems: list, count: int, models) -> None:
    """The record's size for searches that run to the node budget: the continuous search alone (no kinematics,
    so nothing prunes its tree) toward the goal of `count` of `problems` with block 0's goal lifted 30 cm
    (out of reach: the search expands its 1,500 nodes)."""
    from tamp.planning.results import PlanResult
    from tamp.planning.search import SearchConfig, continuous_search
    from tamp.planning.search_record import round_record
    from tamp.planning.search_trace import Recorder, recording

    print("| problem (goal out of reach) | n | expansions | successors generated | nodes kept | truncated | "
          "record (MB) | search (s) | record built (s) |")
    print("|---|---|---|---|---|---|---|---|---|")
    for p in sorted(problems, key=lambda p: -p.n)[:count]:
        goal = p.X_goal.copy()
        goal[0, 2] += 0.3
        recorder = Recorder()
        t = time.perf_counter()
        with recording(recorder):
            out = continuous_search(models.require_dynamics(), p.X_init, goal, SearchConfig())
        t_search = time.perf_counter() - t
        round_ = round_record(0, PlanResult("cfs", None, search=out), recorder, p.X_init)
        t_built = time.perf_counter() - t - t_search
        tree, size = round_["level2"], len(json.dumps(round_, separators=(",", ":")))
        print(f"| {p.name} | {p.n} | {tree['expanded']} | {tree['generated']} | {len(tree['nodes'])} | "
              f"{tree['truncated']} | {size / 1e6:.2f} | {t_search:.1f} | {t_built:.2f} |", flush=True)


if __name__ == "__main__":
    main()
