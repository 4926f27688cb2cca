"""`tamp collect` and `tamp dataset-stats`: interaction data."""
from __future__ import annotations

import argparse
from pathlib import Path

from tamp.app.args import (
    check_output_dir,
    check_output_file,
    seed,
)
from tamp.app.collect import MAX_ACTIONS_PER_SCENE, MAX_SAMPLES, MAX_SCENES_PER_SHARD, SAMPLINGS
from tamp.app.parallel import add_arguments as add_parallel_arguments


def _object_counts(text: str) -> tuple[int, ...]:
    try:
        return tuple(int(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected object counts like 2,3,4, got {text!r}") from None


def cmd_collect(args: argparse.Namespace) -> int:
    """Random-exploration transitions (X, a, X') into a sharded dataset directory; resumable."""
    from tamp.app.collect import CollectConfig, collect

    check_output_dir(args.out, "--out")
    cfg = CollectConfig(samples=args.samples, objects=args.objects, seed=args.seed,
                        actions_per_scene=args.actions_per_scene, scenes_per_shard=args.scenes_per_shard,
                        sampling=args.sampling)
    report = collect(args.out, cfg, workers=args.workers, backend=args.backend, address=args.address,
                     progress=not args.quiet)
    reused = report.shards - report.shards_written
    rate = report.new_samples / report.seconds if report.seconds > 0 else 0.0
    print(f"{report.directory}: {report.samples} samples in {report.shards} shards "
          f"({report.shards_written} written now, {reused} already there"
          + (f", {len(report.shards_recollected)} corrupt re-collected" if report.shards_recollected else "")
          + f"); {report.new_samples} new samples in {report.seconds:.1f} s ({rate:.1f} samples/s)")
    return 0


def cmd_dataset_stats(args: argparse.Namespace) -> int:
    """Counts, failure reasons, effect magnitudes and outcome classes of a dataset."""
    from tamp.app.dataset_stats import dataset_stats

    check_output_file(args.png if args.png is not None else args.directory / "stats.png", "--png")
    stats = dataset_stats(args.directory, png=args.png)
    print(stats.table())
    if stats.png is not None:
        print(f"histogram written to {stats.png}")
    return 0


def add_collect(sub) -> None:
    """`tamp collect`."""
    p = sub.add_parser(
        "collect",
        help="random pick-place interaction data (X, a, X') as dataset shards, in parallel, resumable",
        description="Random scenes and random pick-place actions (all 9 n^2, failing ones included), "
        "a new scene every --actions-per-scene actions, written as .npz shards plus meta.json. The "
        "dataset depends on the parameters only (not on --workers or --backend); running the same "
        "command again after an interruption finishes it, re-collecting missing or corrupt shards.",
    )
    p.add_argument("--samples", type=int, required=True, help=f"number of transitions (at most {MAX_SAMPLES:,})")
    p.add_argument("--objects", type=_object_counts, default=(2, 3, 4),
                   help="object counts drawn uniformly per scene, e.g. 2,3,4 (default)")
    p.add_argument("--out", type=Path, required=True, help="dataset directory (new, or the one to resume)")
    add_parallel_arguments(p)
    p.add_argument("--seed", type=seed, default=0, help="dataset seed (default 0)")
    p.add_argument("--actions-per-scene", type=int, default=10, metavar="M",
                   help=f"chained random actions per scene (default 10, at most {MAX_ACTIONS_PER_SCENE:,})")
    p.add_argument("--sampling", choices=SAMPLINGS, default="uniform",
                   help="uniform: every action alike, as the paper collects (default); graspable: only actions "
                        "whose grasp point holds a block, so that more of the data moves something (to add to "
                        "uniform data with `tamp train --data A B`)")
    p.add_argument("--scenes-per-shard", type=int, default=20, metavar="K",
                   help=f"scenes per shard file, the unit of resumption (default 20, at most {MAX_SCENES_PER_SHARD:,})")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_collect)


def add_dataset_stats(sub) -> None:
    """`tamp dataset-stats`."""
    p = sub.add_parser(
        "dataset-stats",
        help="counts, no-change reasons, effect sizes and outcome classes of a dataset, with a PNG",
        description="Read every shard of a dataset directory (corrupt shards are reported by name "
        "and skipped) and print counts per object count, why actions changed nothing, how far the "
        "moved object went and the outcome classes (moved, stacked, toppled), plus a PNG histogram.",
    )
    p.add_argument("directory", type=Path, help="dataset directory (meta.json + shard-*.npz)")
    p.add_argument("--png", type=Path, default=None, help="histogram path (default DIR/stats.png)")
    p.set_defaults(func=cmd_dataset_stats)
