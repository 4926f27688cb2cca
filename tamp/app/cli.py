"""The `tamp` command line: one subcommand per step of the pipeline."""
from __future__ import annotations

import argparse
import json
import os
import sys
import textwrap
from pathlib import Path

import numpy as np

from tamp.app.args import (
    _html_path,
    check_output_dir,
    check_output_file,
    fraction,
    non_negative_int,
    positive_float,
    positive_int,
    probability,
)
from tamp.app.parallel import add_arguments as add_parallel_arguments
from tamp.errors import UserError, is_user_error

# learned.ACTIVATIONS, spelled out so that `tamp --help` does not import torch (tests check they agree).
BOTTLENECKS = ("gumbel_sigmoid", "sigmoid", "tanh", "none")
TRAIN_PATIENCE = 100  # learned.TrainConfig.fast().patience_epochs, for the same reason


def cmd_simulate(args: argparse.Namespace) -> int:
    """Random pick-place actions on a random scene, one line per action."""
    from tamp.sim import World, WorldConfig
    from tamp.sim.replay import Timeline

    if args.replay:
        check_output_file(args.replay, "--replay")
    timeline = Timeline() if args.replay else None
    world = World(WorldConfig(), seed=args.seed, observer=timeline)
    X = world.reset(n_objects=args.objects)
    rng = np.random.default_rng(args.seed)
    if args.json:
        print(json.dumps({"seed": args.seed, "X": np.round(X, 4).tolist()}))
    else:
        print(f"scene (seed {args.seed}): {args.objects} blocks")
        for i, x in enumerate(X):
            kind = "small" if x[3] == 1 else "large"
            print(f"  {i}: {kind:5s} at ({x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}) m")
    for k in range(args.steps):
        actions = world.actions()
        action = actions[rng.integers(len(actions))]
        X_next, info = world.step(action)
        moved = np.linalg.norm(X_next[:, :3] - X[:, :3], axis=1)
        if args.json:
            record = info.to_dict()
            record["X_next"] = np.round(X_next, 4).tolist()
            print(json.dumps(record))
        else:
            t = info.timings
            what = info.status if info.status == "ok" else f"{info.status}: {info.reason}"
            print(f"step {k}: pick {action.pick} at {action.grasp_offset:+d}, place on {action.place} at "
                  f"{action.release_offset:+d} -> {what}; moved {moved.max() * 100:.1f} cm max; "
                  f"{t.get('total', 0) * 1e3:.0f} ms (IK {t.get('ik', 0) * 1e3:.1f}, motion "
                  f"{t.get('motion', 0) * 1e3:.0f}, physics {t.get('physics', 0) * 1e3:.0f})")
        X = X_next
    if args.replay:
        assert timeline is not None  # made for --replay
        path = timeline.write_html(args.replay)
        print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB); open it in a browser",
              file=sys.stderr if args.json else sys.stdout)
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    """Refine a plan file, execute it with the arm under physics and write the replay; or execute
    an exported trajectory file (--trajectory)."""
    if (args.plan is None) == (args.trajectory is None):
        raise UserError("give a plan file or --trajectory FILE (one of them)")
    if args.trajectory is not None:
        return view_trajectory(args.trajectory, args.out)
    from tamp.app.plan_file import load_plan_file
    from tamp.sim.execute import execute
    from tamp.sim.refine import refine
    from tamp.sim.replay import Timeline

    X, plan = load_plan_file(args.plan)
    check_output_file(args.out, "--out")
    refined = refine(plan, X)
    for k, step in enumerate(refined.steps):
        print(f"action {k} {tuple(step.action)}: refined in {step.refine_time * 1e3:.0f} ms, "
              f"{step.duration:.2f} s of arm motion")
    if refined.failure is not None:
        print(f"refinement failed: {refined.failure}")
        if not refined.steps:
            print("nothing to execute; no replay written")
            return 1
        print(f"executing the {len(refined.steps)} refined action(s) before it, nothing past it")
    timeline = Timeline()
    result = execute(refined, observer=timeline, partial=True)
    for entry in result.log:
        print(f"executed action {entry.index}: {'grasped' if entry.grasped else entry.note}; "
              f"{entry.prediction_error * 100:.1f} cm from the prediction; tracking error "
              f"{entry.max_tracking_error:.4f} rad; {entry.sim_time:.1f} s simulated in {entry.wall_time:.1f} s")
    print("final scene:")
    for i, x in enumerate(result.X_final):
        print(f"  {i}: ({x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}) m")
    path = timeline.write_html(args.out)
    print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0 if refined.failure is None else 1


def view_trajectory(path: Path, out: Path) -> int:
    """`tamp view --trajectory`: check a trajectory file, execute it in the full world from its initial
    scene, compare with the recorded execution and write the replay. Exit 0 if every grasp held and,
    for a file recorded in the full world, every block ends within ROUND_TRIP_TOLERANCE of the
    recorded final scene; 1 otherwise."""
    import time

    from tamp.sim.replay import Timeline
    from tamp.sim.trajectory_file import ROUND_TRIP_TOLERANCE, execute_trajectory, read_trajectory

    trajectory = read_trajectory(path)
    check_output_file(out, "--out")
    by = f" by {trajectory.source}" if trajectory.source else ""
    print(f"{path}: {len(trajectory.actions)} action(s), {trajectory.samples} samples within the UR10e's limits, "
          f"continuous; recorded in the {trajectory.world} world{by}")
    for skipped in trajectory.skipped:
        print(f"  (executed action {skipped.get('index')} moved nothing: {skipped.get('reason', '')})")
    timeline = Timeline()
    t = time.perf_counter()
    result = execute_trajectory(trajectory, observer=timeline)
    seconds = time.perf_counter() - t
    for motion, entry in zip(trajectory.actions, result.log):
        print(f"executed action {motion.index} {tuple(motion.action)}: {'grasped' if entry.grasped else entry.note}; "
              f"blocks within {entry.prediction_error * 1e3:.2f} mm of the recorded execution; tracking error "
              f"{entry.max_tracking_error:.4f} rad; {entry.sim_time:.1f} s simulated")
    deviation = float(np.max(np.linalg.norm(result.X_final[:, :3] - trajectory.X_final[:, :3], axis=1)))
    print(f"executed in the full world in {seconds:.1f} s; final scene: every block within {deviation * 1e3:.2f} mm "
          f"of the recorded one ({trajectory.world} world)")
    for i, x in enumerate(result.X_final):
        print(f"  {i}: ({x[0]:.4f}, {x[1]:.4f}, {x[2]:.4f}) m")
    written = timeline.write_html(out)
    print(f"replay written to {written} ({written.stat().st_size / 1e6:.1f} MB)")
    held = all(entry.grasped for entry in result.log)
    return 0 if held and (trajectory.world != "full" or deviation <= ROUND_TRIP_TOLERANCE) else 1


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
                        actions_per_scene=args.actions_per_scene, scenes_per_shard=args.scenes_per_shard)
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


def cmd_train(args: argparse.Namespace) -> int:
    """Train a Symbolic (gumbel_sigmoid) or Dynamics (sigmoid) Model on a dataset."""
    from learned import ModelConfig, read_meta, train_model
    from learned.train import last_path

    check_output_file(args.out, "--out")
    if args.resume and not last_path(Path(args.out)).is_file():
        raise UserError(f"--resume: no training state at {last_path(Path(args.out))} to continue from "
                         "(leave out --resume to start a new training)")
    asked = {k: v for k, v in (("activation", args.bottleneck), ("d_z", args.d_z), ("heads", args.heads),
                               ("arm_input", False if args.no_arm_input else None)) if v is not None}
    asked["n_max"] = max(int(read_meta(d)["n_max"]) for d in args.data)  # the object limit of the data
    if args.init is None:
        config = ModelConfig.from_dict(asked)
    else:  # fine-tuning: the network of --init, which the flags given must agree with
        from learned import load_model

        config = ModelConfig.from_dict({**load_model(args.init).config.to_dict(), **asked})
    settings = _train_config(args, only_moved=args.only_moved, val_fraction=args.val_fraction,
                             time_limit_s=None if args.time_limit_min is None else 60 * args.time_limit_min)
    result = train_model(args.data, config, settings, args.out, resume=args.resume, init=args.init)
    print(f"best validation effect error {result.best_val_cm:.2f} cm (epoch {result.best_epoch}) -> {result.out_path}")
    print(f"stopped: {result.stop_reason.value} after {result.epochs_reached} epochs (batch {settings.batch_size}, "
          f"lr {settings.lr:.3g}, {settings.precision})"
          + ("" if result.finished else "; unfinished: rerun with --resume to continue"))
    return 0


def _add_train_arguments(p: argparse.ArgumentParser) -> None:
    """How to train, for `train` and `ablate-activations`: learned.TrainConfig.fast()'s defaults, spelled
    out so that --help does not import torch (a test checks they agree); `_train_config` reads them."""
    p.add_argument("--batch-size", type=positive_int, default=1024,
                   help="Adam batch size (default 1024; the paper's: 128)")
    p.add_argument("--lr", type=positive_float, default=None,
                   help="Adam learning rate (default 1e-4 * batch size / 128; the paper's: 1e-4 at batch 128)")
    p.add_argument("--patience", type=non_negative_int, default=TRAIN_PATIENCE, metavar="EPOCHS",
                   help=f"stop once the validation error has not improved for this many epochs (default "
                   f"{TRAIN_PATIENCE}; 0: train all --epochs)")
    p.add_argument("--precision", choices=("float32", "bfloat16"), default=None,
                   help="forward/backward precision (default: bfloat16 autocast where the CPU has native "
                   "bfloat16, else float32; weights and loss stay float32)")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seed of the split, the initial weights and the batches")
    p.add_argument("--threads", type=positive_int, default=1, help="torch threads (default 1)")


def _train_config(args: argparse.Namespace, **changes):
    """The learned.TrainConfig of the flags of `_add_train_arguments` (and --epochs), with `changes`."""
    from learned import TrainConfig

    given = {"epochs": args.epochs, "patience_epochs": args.patience or None, "seed": args.seed,
             "threads": args.threads, **({"lr": args.lr} if args.lr is not None else {}),
             **({"precision": args.precision} if args.precision is not None else {})}
    return TrainConfig.fast(args.batch_size, **given, **changes)


def cmd_ablate(args: argparse.Namespace) -> int:
    """Table I of the paper: effect error per bottleneck activation over several seeds."""
    from learned import ablate_activations, format_ablation_markdown, summarize_ablation_dir

    check_output_dir(args.out_dir, "--out-dir")
    if args.finish is not None and args.resume:
        raise UserError("--finish resumes the runs its table lacks in --out-dir by itself: give it without --resume")
    if args.finish is not None:
        from learned.ablation import finish_ablation, read_table

        try:
            table = read_table(args.finish)
            result = finish_ablation(args.data, table, args.out_dir, args.runs, train=_train_config(args),
                                     workers=args.workers, summarize=args.summarize)
        except ValueError as e:
            raise UserError(f"--finish {args.finish}: {e}") from e
    elif args.summarize:
        try:
            result = summarize_ablation_dir(args.data, args.out_dir, args.runs, train=_train_config(args))
        except ValueError as e:
            raise UserError(f"--summarize: {e}") from e
    else:
        result = ablate_activations(args.data, runs=args.runs, train=_train_config(args), out_dir=args.out_dir,
                                    resume=args.resume)
    print(format_ablation_markdown(result))
    print(f"written to {args.out_dir}/ablation.md and ablation.json")
    return 0


def cmd_symbols(args: argparse.Namespace) -> int:
    """What each learned bit of a Symbolic Model means, on held-out scenes."""
    from learned import load_model
    from learned.interpret import format_symbols_markdown, interpret_symbols, write_symbols_png

    for path, flag in ((args.json, "--json"), (args.png, "--png")):
        if path is not None:
            check_output_file(path, flag)
    model = load_model(args.model)
    scenes = symbol_scenes(args.problems, args.data, args.max_scenes, args.seed)
    report = interpret_symbols(model.symbols, scenes)
    print(f"{args.model}: d_z = {model.config.d_z} unary bit(s), K = {model.config.heads} relation(s), read on "
          f"{len(scenes)} scenes of {args.problems or args.data}")
    print(format_symbols_markdown(report))
    if args.json is not None:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps([b.to_dict() for b in report], indent=1) + "\n")
        print(f"written {args.json}")
    if args.png is not None:
        write_symbols_png(report, args.png)
        print(f"written {args.png}")
    return 0


def symbol_scenes(problems: Path | None, data: Path | None, max_scenes: int, seed: int = 0) -> list[np.ndarray]:
    """Scenes to read symbols on: X_init and X_goal of a problem set, or (at most `max_scenes`,
    drawn with `seed`) the states of a dataset's transitions."""
    if (problems is None) == (data is None):
        raise UserError("give exactly one of --problems (a problem set) or --data (a dataset directory)")
    if problems is not None:
        from tamp.app.problem import read_problem_set

        return [X for p in read_problem_set(problems) for X in (p.X_init, p.X_goal)][:max_scenes]
    from learned import load_transitions

    assert data is not None  # exactly one of problems and data (checked above)
    t = load_transitions(data)
    if len(t) == 0:
        raise UserError(f"{data}: the dataset holds no transitions")
    pick = np.random.default_rng(seed).permutation(len(t))[:max_scenes]
    return [t.X[i, :int(t.n[i])] for i in sorted(pick)]


def cmd_domain(args: argparse.Namespace) -> int:
    """Symbols from the Symbolic Model -> learned PDDL / PPDDL domain and its statistics."""
    from tamp.planning.domain import learn_domain

    check_output_dir(args.out, "--out")
    report = learn_domain(args.model, args.data, args.out, holdout=args.holdout, seed=args.seed,
                          sampled_domains=args.sampled, involved_only=args.involved_only,
                          min_count=args.min_count, min_prob=args.min_prob, only_moved=args.only_moved,
                          any_bottleneck=args.any_bottleneck, max_arity=args.max_arity)
    held = report.get("coverage_holdout") or {}
    print(f"{report['n_operators']} operators from {report['transitions']} transitions -> {args.out}")
    left_out = report["max_arity"]["transitions_left_out"]
    if left_out:
        print(f"  {left_out} training transitions involve more than {report['max_arity']['limit']} objects "
              "(the most the lifted search takes): no operator learned from them")
    for key in ("effects_per_operator", "coverage_train"):
        if key in report:
            print(f"  {key}: {json.dumps(report[key])}")
    print(f"  coverage_holdout: {json.dumps(held)}")
    return 0



def cmd_pddl(args: argparse.Namespace) -> int:
    """A models directory's learned domain (and a problem's symbols) as PDDL files."""
    from tamp.app.problem import load_problem
    from tamp.planning.domain import export_pddl
    from tamp.planning.models import pretrained_dir

    check_output_dir(args.out, "--out")
    problem = None if args.problem is None else load_problem(args.problem)
    paths = export_pddl(args.models or pretrained_dir(), args.out, None if problem is None else problem.X_init,
                        None if problem is None else problem.X_goal,
                        problem_name=(problem.name or args.problem.stem) if problem is not None else "symbolic-task",
                        sampled=args.sampled, seed=args.seed)
    for kind, path in paths.items():
        print(f"{kind}: {path}")
    return 0


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan a problem file with the learned models; refine, execute and replay the plan."""
    from tamp.app.plan_command import options_from_args, run_plan

    return run_plan(args.problem, args.models, options_from_args(args))

def cmd_demo(args: argparse.Namespace) -> int:
    """A random problem planned, refined, executed under physics, summarised and replayed."""
    from tamp.app.demo import DemoConfig, run_demo

    check_output_file(args.replay, "--replay")
    if args.trajectory is not None:
        check_output_file(args.trajectory, "--trajectory")
    cfg = DemoConfig(seed=args.seed, objects=args.objects, actions=args.actions, models=args.models,
                     fidelity=args.fidelity, replay=args.replay, candidates=args.candidates,
                     replan=not args.open_loop, trajectory=args.trajectory)
    return 0 if run_demo(cfg).success else 1


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tamp",
        description="Bilevel task-and-motion planning for a UR10e picking and placing blocks in Drake.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    p = sub.add_parser(
        "simulate",
        help="random pick-place actions on a random scene, with an optional Meshcat replay",
        description="Reset a random scene and execute random pick-place actions with the real skill "
        "(IK, OMPL motions, physics after release). Prints one line per action: the action, what "
        "happened and where the time went.",
    )
    p.add_argument("--objects", type=positive_int, default=3, help="number of blocks, 1..6 (default 3)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the scene and the actions (default 0)")
    p.add_argument("--steps", type=positive_int, default=5, help="number of random actions (default 5)")
    p.add_argument("--json", action="store_true", help="print JSON lines instead of text")
    p.add_argument("--replay", type=_html_path, metavar="OUT.html",
                   help="write a self-contained Meshcat HTML replay of the arm and blocks")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser(
        "collect",
        help="random pick-place interaction data (X, a, X') as dataset shards, in parallel, resumable",
        description="Random scenes and random pick-place actions (all 9 n^2, failing ones included), "
        "a new scene every --actions-per-scene actions, written as .npz shards plus meta.json. The "
        "dataset depends on the parameters only (not on --workers or --backend); running the same "
        "command again after an interruption finishes it, re-collecting missing or corrupt shards.",
    )
    p.add_argument("--samples", type=int, required=True, help="number of transitions")
    p.add_argument("--objects", type=_object_counts, default=(2, 3, 4),
                   help="object counts drawn uniformly per scene, e.g. 2,3,4 (default)")
    p.add_argument("--out", type=Path, required=True, help="dataset directory (new, or the one to resume)")
    add_parallel_arguments(p)
    p.add_argument("--seed", type=non_negative_int, default=0, help="dataset seed (default 0)")
    p.add_argument("--actions-per-scene", type=int, default=10, metavar="M",
                   help="chained random actions per scene (default 10)")
    p.add_argument("--scenes-per-shard", type=int, default=20, metavar="K",
                   help="scenes per shard file, the unit of resumption (default 20)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_collect)

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

    p = sub.add_parser(
        "view",
        help="execute a plan file or an exported trajectory with the full arm under physics, write a replay",
        description="Refine a plan (JSON: {\"X\": [[x, y, z, small, large], ...], \"actions\": "
        "[[pick, grasp_offset, place, release_offset], ...]}) into collision-free joint "
        "trajectories, execute them with the arm under Drake physics, and write a self-contained "
        "Meshcat HTML replay. If an action cannot be refined, the actions before it are executed and "
        "the command exits with status 1. With --trajectory FILE (written by `tamp plan` or `tamp demo "
        "--trajectory`), execute that file's motion instead, to check it before sending it to an arm.",
    )
    p.add_argument("plan", nargs="?", type=Path, default=None, help="plan file (JSON)")
    p.add_argument("--trajectory", type=Path, default=None, metavar="FILE",
                   help="instead of a plan, execute a trajectory file (`tamp plan/demo --trajectory`) with the arm "
                   "under physics from its recorded initial scene: the file is checked first (format, robot, "
                   "joint limits, continuity; a bad file is a one-line error, exit 2, nothing written), then "
                   "each action's and the final scene are compared with the recorded execution (exit 1 if a "
                   "grasp missed or, for a file recorded in the full world, a block ends over 2 mm away)")
    p.add_argument("--out", type=_html_path, default=Path("replay.html"), metavar="OUT.html",
                   help="replay file (default replay.html)")
    p.set_defaults(func=cmd_view)

    p = sub.add_parser(
        "train",
        help="train the Symbolic (gumbel_sigmoid) or Dynamics (sigmoid) Model on a dataset",
        description="Train the effect-prediction network of the paper on a dataset written by "
        "`tamp collect`. The best checkpoint by validation error is written to --out; "
        "<out>.last.pt holds the state to resume from (--resume).",
    )
    p.add_argument("--data", required=True, nargs="+", metavar="DIR",
                   help="dataset directory (tamp collect --out); several are trained on together, e.g. one "
                   "collected with --objects 2,3,4 and one with --objects 5,6 (same world, checked)")
    p.add_argument("--bottleneck", choices=BOTTLENECKS, default=None,
                   help="bottleneck activation: gumbel_sigmoid = Symbolic Model, sigmoid = Dynamics Model "
                   "(default, or --init's)")
    p.add_argument("--epochs", type=positive_int, default=1000,
                   help="training epochs at most (default 1000; --patience usually stops earlier)")
    p.add_argument("--out", required=True, help="checkpoint file to write (e.g. models/dynamics.pt)")
    p.add_argument("--d-z", type=positive_int, default=None,
                   help="unary symbol bits per object (default: learned.ModelConfig's; more bits, more operators)")
    p.add_argument("--heads", type=positive_int, default=None,
                   help="relation types = attention heads (default: learned.ModelConfig's)")
    _add_train_arguments(p)
    p.add_argument("--time-limit-min", type=positive_float, default=None, metavar="MIN",
                   help="stop after the epoch that passes this wall time; the run is unfinished, --resume continues")
    p.add_argument("--val-fraction", type=fraction, default=0.1, help="validation fraction, in [0, 1) (default 0.1)")
    p.add_argument("--resume", action="store_true", help="continue from <out>.last.pt")
    p.add_argument("--init", type=Path, default=None, metavar="CHECKPOINT",
                   help="fine-tune: start from this model's weights and input normalisation (e.g. "
                   "tamp/pretrained/dynamics.pt, trained on 2-4 blocks, on data with 5 and 6) instead of random "
                   "ones; its network settings are kept (--bottleneck, --d-z, --heads, --no-arm-input must agree "
                   "if given) and the object limit is the data's")
    p.add_argument("--no-arm-input", action="store_true",
                   help="leave the arm's pick-to-place displacement out of the action encoding, so that "
                   "positions reach the decoder only through the symbols (the Symbolic Model)")
    p.add_argument("--only-moved", action="store_true",
                   help="train on the transitions that moved the picked block (as the paper's authors do for "
                   "the Symbolic Model; grasps of nothing and blocked motions left out)")
    p.set_defaults(func=cmd_train)

    p = sub.add_parser(
        "ablate-activations",
        help="Table I: effect error of the four bottleneck activations over several seeds",
        description="Train one model per activation (gumbel_sigmoid, tanh, none, sigmoid) and seed, "
        "and report the mean effect-prediction error (cm) on a held-out test split, as Markdown and JSON.",
    )
    p.add_argument("--data", required=True, help="dataset directory")
    p.add_argument("--runs", type=positive_int, default=3, help="seeds per activation (default 3; the paper: 10)")
    p.add_argument("--epochs", type=positive_int, default=20, help="epochs per run (default 20)")
    p.add_argument("--out-dir", default="runs/ablation", help="where ablation.md / ablation.json go")
    p.add_argument("--resume", action="store_true",
                   help="continue the runs begun in --out-dir (a finished run is read back, not trained again)")
    p.add_argument("--summarize", action="store_true",
                   help="train nothing: write the table from the runs already in --out-dir (the finished runs are "
                   "averaged; a run still training is listed with its best model so far). Give the flags the runs "
                   "were trained with; `tamp reproduce --scale paper` keeps its runs in OUT/ablation, trained with "
                   "--epochs 4000 --lr 0.0008 --precision bfloat16")
    p.add_argument("--finish", type=Path, default=None, metavar="ABLATION_JSON",
                   help="complete this table (an ablation.json) to --runs runs per activation: its finished runs "
                   "are kept as it lists them, the others (still training when it was written, or missing) are "
                   "trained in --out-dir, resuming there. For a table whose models are gone, e.g. "
                   "results/paper-scale/ablation.json with --data from `tamp collect --samples 160000 --seed 0`; "
                   "the settings must be the table's (checked). With --summarize: train nothing, write the "
                   "table with those runs as they stand in --out-dir")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="with --finish: runs trained at a time, one process and one torch thread each (default 1)")
    _add_train_arguments(p)
    p.set_defaults(func=cmd_ablate)

    p = sub.add_parser(
        "domain",
        help="learned symbolic domain (PDDL, PPDDL, operators.json) from a Symbolic Model and data",
        description="Compute the Symbolic Model's unary and relational bits before and after every "
        "transition, learn lifted operators (most frequent effect and the empirical distribution), "
        "and write domain.pddl, domain.ppddl, operators.json and stats.json (number of operators, "
        "effects per operator, coverage on held-out transitions). `tamp pddl` writes the PDDL files of an "
        "existing models directory (the bundled one by default) and of a problem.",
    )
    p.add_argument("--model", required=True, help="Symbolic Model checkpoint (tamp train --bottleneck gumbel_sigmoid)")
    p.add_argument("--data", required=True, nargs="+", metavar="DIR",
                   help="dataset directory, or several (learned from together)")
    p.add_argument("--out", required=True, help="output directory")
    p.add_argument("--holdout", type=fraction, default=0.1, help="fraction of transitions held out for coverage")
    p.add_argument("--sampled", type=non_negative_int, default=0, metavar="N", help="also write N sampled PDDL domains")
    p.add_argument("--involved-only", action="store_true",
                   help="operators mention only the objects a transition involves (picked, target, and "
                   "those whose symbols change) rather than every object in the scene: far fewer operators")
    p.add_argument("--only-moved", action="store_true",
                   help="learn from the transitions that moved their picked block (failed grasps and blocked "
                   "motions left out, as the paper's authors do)")
    p.add_argument("--min-count", type=non_negative_int, default=0, metavar="N",
                   help="keep operators seen at least N times (default 0: all; the paper's authors: 51)")
    p.add_argument("--max-arity", type=positive_int, default=None, metavar="A",
                   help="learn no operator from a transition that involves more than A objects (default: the "
                   "most the lifted search takes, 4 with 1 unary bit and 3 relations; larger ones are refused "
                   "by the planner)")
    p.add_argument("--min-prob", type=probability, default=0.0, metavar="P",
                   help="drop effects of probability below P and renormalise (default 0; the paper's authors: 0.1)")
    p.add_argument("--any-bottleneck", action="store_true",
                   help="accept a --model that is not a Symbolic Model (e.g. the Fig. 4 Sigmoid variant)")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.set_defaults(func=cmd_domain)

    p = sub.add_parser(
        "pddl",
        help="export a models directory's learned domain (and a problem) as PDDL for other planners",
        description="Write the learned domain of --models (its domain/operators.json) as domain.pddl "
        "(most frequent effects: a deterministic STRIPS domain with equality) and domain.ppddl (PPDDL "
        "probabilistic effects), with --problem the problem's symbols (from the Symbolic Model) as "
        "problem.pddl, and with --sampled N the distinct domains of N sampled ones, as Level 1 draws them. "
        "Fast Downward and other PDDL planners read domain.pddl and problem.pddl; "
        "`tamp domain` learns a domain from data.",
    )
    p.add_argument("--models", type=Path, default=None,
                   help="models directory (domain/, and symbolic.pt for --problem); default: the bundled models")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--problem", type=Path, default=None, help="problem file (JSON: X_init, X_goal) to export")
    p.add_argument("--sampled", type=non_negative_int, default=0, metavar="N",
                   help="also write the distinct domains among N sampled ones (sampled/, with sampled.json)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the sampled domains (default 0)")
    p.set_defaults(func=cmd_pddl)

    p = sub.add_parser(
        "symbols",
        help="what each learned bit of a Symbolic Model means: its rate and agreement with geometric facts",
        description="Read the Symbolic Model's unary bits, relations r_k(i, j) (i != j) and self relations "
        "r_k(i, i) on held-out scenes (the initial and goal scenes of a problem set, or states of a "
        "dataset) and compare each with facts a reader understands: block type, elevated, on another "
        "block, carrying one, left/right along y, near, on top of, vertical order. Prints a table "
        "(agreement in %, the better of the fact and its negation, and the Matthews correlation phi, "
        "which does not reward agreeing with a rare fact by being always 0); --png draws it.",
    )
    p.add_argument("--model", type=Path, required=True, help="Symbolic Model checkpoint")
    p.add_argument("--problems", type=Path, default=None, help="problem set (tamp problems --out): its scenes")
    p.add_argument("--data", type=Path, default=None, help="or a dataset directory: states of its transitions")
    p.add_argument("--max-scenes", type=positive_int, default=5000, help="scenes read at most (default 5000)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the scenes drawn from --data (default 0)")
    p.add_argument("--png", type=Path, default=None, help="write the table as a heat map (PNG)")
    p.add_argument("--json", type=Path, default=None, help="write every figure as JSON")
    p.set_defaults(func=cmd_symbols)

    from tamp.app.plan_command import STEPS_HELP as PLAN_STEPS_HELP
    from tamp.app.plan_command import add_arguments as add_plan_arguments
    from tamp.app.plan_command import add_trajectory_argument

    p = sub.add_parser(
        "plan",
        help="plan a problem (X_init, X_goal) with the bilevel planner or a baseline; refine, execute, replay",
        description=textwrap.fill(
            "Plan with the learned models in --models DIR (symbolic.pt, dynamics.pt, domain/ from `tamp train` "
            "and `tamp domain`), print the plan, the level that solved it, the verification of each symbolic "
            "candidate and the timings, then refine and execute it in the Drake world and print the final error, "
            "then each step: its symbols, operator, motion and what was observed. Exit status 0 if a plan was "
            "found (and, when executed, reached the goal).", 100),
        epilog=PLAN_STEPS_HELP, formatter_class=argparse.RawDescriptionHelpFormatter,
    )

    add_plan_arguments(p)
    p.set_defaults(func=cmd_plan)

    p = sub.add_parser(
        "demo",
        help="solve a random 3-block problem end to end with the bundled models; summary and replay",
        description="Generate a random problem (--objects blocks, the goal after --actions random "
        "actions), solve it with the bilevel planner, refine the plan into arm trajectories, execute "
        "them with the full arm under physics and print a summary: the problem, the plan and the level "
        "that produced it, each symbolic candidate's verification error, planning, refinement and "
        "execution times, the final error and success (every block within 5 cm of its goal). By "
        "default the loop is closed as in the paper's replanning variant: after each action the scene "
        "is observed and the plan made again from it (up to k - 1 rounds); --open-loop executes the "
        "first plan to its end. The "
        "Meshcat HTML replay shows the goal (green) and the Dynamics Model's predicted blocks after "
        "each action (orange) as translucent blocks beside the executed ones. Exit status 0 on "
        "success, 1 if there was no plan, the plan could not be refined or it missed the goal.",
    )
    p.add_argument("--seed", type=non_negative_int, default=0, help="seed of the problem and the planner (default 0)")
    p.add_argument("--objects", type=positive_int, default=3, help="number of blocks (default 3)")
    p.add_argument("--actions", type=positive_int, default=3,
                   help="k: random actions that generate the goal (default 3)")
    p.add_argument("--models", type=Path, default=None,
                   help="models directory (symbolic.pt, dynamics.pt, domain/); default: the pretrained "
                   "models shipped in the package")
    p.add_argument("--fidelity", choices=("full", "fast"), default="full",
                   help="execute with the arm under physics (full, default) or in the fast world")
    p.add_argument("--replay", type=_html_path, default=Path("demo_replay.html"), metavar="OUT.html",
                   help="replay file (default demo_replay.html)")
    p.add_argument("--open-loop", action="store_true",
                   help="execute one plan to its end (the paper's Algorithm 1) instead of the closed loop "
                   "that executes the first action, observes the scene and plans again until the goal")
    p.add_argument("--candidates", type=non_negative_int, default=0, metavar="N",
                   help="also execute the first N symbolic candidates that failed verification and write "
                   "a replay of each (OUT.candidateI.html, I their number in the candidate list)")
    add_trajectory_argument(p)
    p.set_defaults(func=cmd_demo)
    _add_plugin_commands(sub)
    return parser


def _add_plugin_commands(sub) -> None:
    """Subcommands of the packages above `tamp` (e.g. `evaluate`, `reproduce` from `evaluation`).

    They register through the `tamp.commands` entry-point group (see pyproject.toml), each a function
    `register(subparsers)`, so that `tamp` itself never imports the packages that import it.
    """
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group="tamp.commands"), key=lambda e: e.name):
        ep.load()(sub)


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (2 for a user error, with a one-line message; any other
    exception propagates with its traceback)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except Exception as error:
        if not is_user_error(error):
            raise  # a bug: the traceback says where
        print(f"tamp {args.command}: error: {error}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print(f"tamp {args.command}: interrupted", file=sys.stderr)
        code = 130
    return code


def entry() -> None:
    """Console-script entry point."""
    try:
        code = main()
        sys.stdout.flush()
        sys.stderr.flush()
    except BrokenPipeError:  # the reader of stdout went away (`tamp ... | head`): nothing more to say
        code = 0
    # OMPL's nanobind bindings print "leaked instances" warnings at interpreter exit; nothing is
    # left to clean up here, so leave without running the interpreter's teardown.
    os._exit(code)


if __name__ == "__main__":
    entry()
