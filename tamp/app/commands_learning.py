"""`tamp train` and `tamp ablate-activations`: the networks and the paper's Table I."""
from __future__ import annotations

import argparse
from pathlib import Path

from tamp.app.args import (
    WORKERS_LIMIT,
    Count,
    check_output_dir,
    check_output_file,
    fraction,
    non_negative_float,
    non_negative_int,
    positive_float,
    positive_int,
    seed,
)
from tamp.errors import UserError

# learned.ACTIVATIONS, spelled out so that `tamp --help` does not import torch (tests check they agree).
BOTTLENECKS = ("gumbel_sigmoid", "sigmoid", "tanh", "none")
RELATION_ENCODERS = ("attention", "pairwise")  # learned.RELATIONS
POSITION_AXES = ("xy", "x")  # learned.model.POSITION_AXES
TRAIN_PATIENCE = 100  # learned.TrainConfig.fast().patience_epochs, for the same reason


def cmd_train(args: argparse.Namespace) -> int:
    """Train a Symbolic (gumbel_sigmoid) or Dynamics (sigmoid) Model on a dataset."""
    from learned import ModelConfig, read_meta, train_model
    from learned.train import last_path

    check_output_file(args.out, "--out")
    if args.resume and not last_path(Path(args.out)).is_file():
        raise UserError(f"--resume: no training state at {last_path(Path(args.out))} to continue from "
                         "(leave out --resume to start a new training)")
    if args.position_axes is not None and not args.position_loss:
        raise UserError("--position-axes changes what --position-loss asks: give --position-loss too")
    for flag, given in (("--offset-from-relations", args.offset_from_relations),
                        ("--offset-radius-cm", args.offset_radius_cm is not None)):
        if given and not args.offset_loss:
            raise UserError(f"{flag} changes what --offset-loss asks: give --offset-loss too")
    asked = {k: v for k, v in (("activation", args.bottleneck), ("d_z", args.d_z), ("heads", args.heads),
                               ("hidden", args.hidden), ("layers", args.layers),
                               ("arm_input", False if args.no_arm_input else None),
                               ("relations", args.relations),
                               ("type_symbol", True if args.type_symbol else None),
                               ("whole_action", True if args.whole_action else None),
                               ("relative_messages", True if args.relative_messages else None),
                               ("offset_decoder", True if args.offset_loss else None),
                               ("offset_from_relations", True if args.offset_from_relations else None),
                               ("position_decoder", True if args.position_loss else None),
                               ("position_axes", args.position_axes),
                               ("transition_decoder", True if args.transition_loss else None))
             if v is not None}
    asked["n_max"] = max(int(read_meta(d)["n_max"]) for d in args.data)  # the object limit of the data
    if args.extra_data and args.ensemble is None:
        raise UserError("--extra-data is drawn into each ensemble member's resample: give --ensemble too")
    if not args.extra_share > 0:
        raise UserError("--extra-share must be above 0 (the share of each resample drawn from --extra-data)")
    if args.ensemble is not None and args.bottleneck == "gumbel_sigmoid":
        raise UserError("--ensemble trains a Dynamics Model: leave out --bottleneck gumbel_sigmoid")
    if args.extra_data:
        asked["n_max"] = max(asked["n_max"], *(int(read_meta(d)["n_max"]) for d in args.extra_data))
    if args.init is None:
        config = ModelConfig.from_dict(asked)
    else:  # fine-tuning: the network of --init, which the flags given must agree with
        from learned.ensemble import member_models

        try:
            initial = member_models(args.init)[0].config.to_dict()
        except ValueError as error:
            raise UserError(f"--init: {error}") from None
        config = ModelConfig.from_dict({**initial, "spread": False, **asked})
    settings = _train_config(args, only_moved=args.only_moved, val_fraction=args.val_fraction,
                             bit_usage=args.bit_usage, offset_weight=args.offset_loss,
                             offset_radius_m=None if args.offset_radius_cm is None else args.offset_radius_cm / 100,
                             position_weight=args.position_loss, transition_weight=args.transition_loss,
                             effect_loss=args.effect_loss,
                             time_limit_s=None if args.time_limit_min is None else 60 * args.time_limit_min)
    if args.ensemble is not None:
        return _train_ensemble(args, config, settings)
    result = train_model(args.data, config, settings, args.out, resume=args.resume, init=args.init)
    print(f"best validation effect error {result.best_val_cm:.2f} cm (epoch {result.best_epoch}) -> {result.out_path}")
    print(f"stopped: {result.stop_reason.value} after {result.epochs_reached} epochs (batch {settings.batch_size}, "
          f"lr {settings.lr:.3g}, {settings.precision})"
          + ("" if result.finished else "; unfinished: rerun with --resume to continue"))
    return 0


def _train_ensemble(args: argparse.Namespace, config, settings) -> int:
    """`tamp train --ensemble M`: M bootstrap members with spread heads, written as one file."""
    from learned.ensemble_train import EnsembleConfig, cleanup_members, train_ensemble

    ensemble = EnsembleConfig(members=args.ensemble, extra_share=args.extra_share, workers=args.workers)
    try:
        result = train_ensemble(args.data, args.out, extra=args.extra_data or None, config=config, train=settings,
                                ensemble=ensemble, init=args.init)
    except TimeoutError as error:
        print(f"unfinished: {error}")
        return 0
    for f in result.members:
        print(f"member {f['member']}: validation effect error {f['val_err_cm']:.2f} cm (epoch {f['best_epoch']}), "
              f"spread: {100 * f['val_coverage95']:.1f} % of objects inside their 95 % ellipsoid")
    cleanup_members(args.out, args.ensemble)
    print(f"ensemble of {args.ensemble} -> {result.out_path}")
    return 0


def _add_train_arguments(p: argparse.ArgumentParser) -> None:
    """How to train, for `train` and `ablate-activations`: learned.TrainConfig.fast()'s defaults, spelled
    out so that --help does not import torch (a test checks they agree); `_train_config` reads them."""
    p.add_argument("--batch-size", type=Count(1, 1 << 20), default=1024,
                   help="Adam batch size (default 1024; the paper's: 128)")
    p.add_argument("--lr", type=positive_float, default=None,
                   help="Adam learning rate (default 1e-4 * batch size / 128; the paper's: 1e-4 at batch 128)")
    p.add_argument("--patience", type=non_negative_int, default=TRAIN_PATIENCE, metavar="EPOCHS",
                   help=f"stop once the validation error has not improved for this many epochs (default "
                   f"{TRAIN_PATIENCE}; 0: train all --epochs)")
    p.add_argument("--precision", choices=("float32", "bfloat16"), default=None,
                   help="forward/backward precision (default: bfloat16 autocast where the CPU has native "
                   "bfloat16, else float32; weights and loss stay float32)")
    p.add_argument("--seed", type=seed, default=0,
                   help="seed of the split, the initial weights and the batches")
    p.add_argument("--threads", type=Count(1, 256), default=1, help="torch threads (default 1)")


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
        from tamp.records import output_dir

        with output_dir(args.out_dir, "--out-dir", own=("ablation.json", "models"), into_existing=args.resume):
            result = ablate_activations(args.data, runs=args.runs, train=_train_config(args), out_dir=args.out_dir,
                                        resume=args.resume)
    print(format_ablation_markdown(result))
    print(f"written to {args.out_dir}/ablation.md and ablation.json")
    return 0


def add_train(sub) -> None:
    """`tamp train`."""
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
    p.add_argument("--d-z", type=Count(1, 64), default=None,
                   help="unary symbol bits per object (default: learned.ModelConfig's; more bits, more operators)")
    p.add_argument("--heads", type=Count(1, 64), default=None,
                   help="relation types = attention heads (default: learned.ModelConfig's)")
    p.add_argument("--hidden", type=Count(1, 4096), default=None,
                   help="width of every MLP's hidden layers (default: learned.ModelConfig's, 128)")
    p.add_argument("--layers", type=Count(1, 64), default=None,
                   help="hidden layers per MLP (default: learned.ModelConfig's, 2)")
    p.add_argument("--relations", choices=RELATION_ENCODERS, default=None,
                   help="relation encoder: attention = the paper's q_k(x_i) . k_k(x_j) (default, or --init's); "
                   "pairwise = an MLP of x_i, x_j and their offset x_j - x_i, which can learn spatial relations "
                   "(on, aligned, near)")
    p.add_argument("--type-symbol", action="store_true",
                   help="give the decoder each block's type (large or not) as a fixed unary symbol after the "
                   "learned bits, so that no learned bit or relation is spent on it (the domain then has d_z + 1 "
                   "unary symbols)")
    p.add_argument("--whole-action", action="store_true",
                   help="both objects of an action read all of it: the picked block the release offset and the "
                   "target's type, the target the grasp offset and the picked block's type, so the picked block knows "
                   "where it lands (on a cube or beside it); with --init, the network is widened with zero weights and "
                   "predicts as before until it trains (default: the paper's encoding)")
    p.add_argument("--relative-messages", action="store_true",
                   help="a Dynamics Model whose every message also reads where the sending object stands from the "
                   "receiving one (x_j - x_i), so that offsets reach the decoder exactly, for steps from stacks and "
                   "leaning blocks; each message is then an MLP per pair of blocks, so every prediction the "
                   "planner makes costs more (docs/practice-and-doubt.md) (default: the paper's messages; not "
                   "with --bottleneck gumbel_sigmoid)")
    p.add_argument("--bit-usage", type=non_negative_float, default=0.0, metavar="WEIGHT",
                   help="weight of a penalty on learned bits and relations set in under 5 %% or over 95 %% of a "
                   "batch, so that the effect loss cannot leave a relation constant (default 0: the paper's loss)")
    p.add_argument("--offset-loss", type=non_negative_float, default=0.0, metavar="WEIGHT",
                   help="weight of a loss that reads each pair's offset x_j - x_i back from the pair's bits alone, so "
                   "that relations say where blocks stand on the table, which the effect loss never asks (default 0: "
                   "the paper's loss)")
    p.add_argument("--offset-radius-cm", type=positive_float, default=None, metavar="CM",
                   help="with --offset-loss: read back only the offsets of pairs whose centres lie within this "
                   "distance on the table, farther pairs as no offset, so that relations say where a neighbour "
                   "stands and moving a block far from a bystander leaves their relations unchanged (default: "
                   "every pair)")
    p.add_argument("--offset-from-relations", action="store_true",
                   help="with --offset-loss: read the offset back from the pair's relations alone, not its unary "
                   "bits too, meant to make a relation say which block stands higher (docs/learned-symbols.md)")
    p.add_argument("--position-loss", type=non_negative_float, default=0.0, metavar="WEIGHT",
                   help="weight of a loss that reads each block's place on the table back from its unary bits alone, "
                   "so that a unary bit says in which part of the table a block stands, a symbol only the moved "
                   "block's step changes (default 0: the paper's loss)")
    p.add_argument("--position-axes", choices=POSITION_AXES, default=None,
                   help="with --position-loss: the table axes read back, x and y (default) or x alone; the grasp and "
                   "release offsets are along y, so a block placed beside or on a target lands at the target's x, "
                   "and x-only places are ones an operator can predict")
    p.add_argument("--transition-loss", type=non_negative_float, default=0.0, metavar="WEIGHT",
                   help="weight of a loss that predicts the bits read after each step from the bits before it and "
                   "the action, so that the bits are ones operators can predict (default 0: the paper's loss)")
    p.add_argument("--effect-loss", choices=("squared", "distance"), default="squared",
                   help="the effect loss per object: squared distance (default: the paper's Eq. 1, which predicts the "
                   "mean of a step's outcomes) or the distance itself (a median: a block that comes to rest on a cube "
                   "or beside it is predicted where it more often rests, not between the two)")
    _add_train_arguments(p)
    p.add_argument("--time-limit-min", type=positive_float, default=None, metavar="MIN",
                   help="stop after the epoch that passes this wall time; the run is unfinished, --resume continues")
    p.add_argument("--val-fraction", type=fraction, default=0.1, help="validation fraction, in [0, 1) (default 0.1)")
    p.add_argument("--resume", action="store_true", help="continue from <out>.last.pt")
    p.add_argument("--init", type=Path, default=None, metavar="CHECKPOINT",
                   help="fine-tune: start from this model's weights and input normalisation (e.g. "
                   "tamp/pretrained/paper/dynamics.pt, trained on 2-4 blocks, on data with 5 and 6) instead of random "
                   "ones; its network settings are kept (--bottleneck, --d-z, --heads, --no-arm-input must agree "
                   "if given) and the object limit is the data's")
    p.add_argument("--ensemble", type=Count(1, 64), default=None, metavar="M",
                   help="a Dynamics Model that knows its doubt: M members, each trained on a bootstrap resample and "
                   "given a head that predicts how widely each effect scatters; the planner takes their mean and "
                   "the rows their 95 %% bound (docs/beyond-the-paper.md). --init may be an ensemble (member m "
                   "starts from its member m) or one model. A stopped run continues where each member was")
    p.add_argument("--extra-data", nargs="+", default=[], metavar="DIR",
                   help="with --ensemble: datasets of the robot's own executed steps (tamp practice), drawn into each "
                   "member's resample at --extra-share beside the --data")
    p.add_argument("--extra-share", type=fraction, default=0.25,
                   help="with --extra-data: the share of each member's resample drawn from it (default 0.25)")
    p.add_argument("--workers", type=Count(1, WORKERS_LIMIT), default=1,
                   help="with --ensemble: members trained at a time, one process and one torch thread each (default 1)")
    p.add_argument("--no-arm-input", action="store_true",
                   help="leave the arm's pick-to-place displacement out of the action encoding, so that "
                   "positions reach the decoder only through the symbols (the Symbolic Model)")
    p.add_argument("--only-moved", action="store_true",
                   help="train on the transitions that moved the picked block (as the paper's authors do for "
                   "the Symbolic Model; grasps of nothing and blocked motions left out)")
    p.set_defaults(func=cmd_train)


def add_ablate_activations(sub) -> None:
    """`tamp ablate-activations`."""
    p = sub.add_parser(
        "ablate-activations",
        help="Table I: effect error of the four bottleneck activations over several seeds",
        description="Train one model per activation (gumbel_sigmoid, tanh, none, sigmoid) and seed, "
        "and report the mean effect-prediction error (cm) on a held-out test split, as Markdown and JSON.",
    )
    p.add_argument("--data", required=True, help="dataset directory")
    p.add_argument("--runs", type=Count(1, 1000), default=3, help="seeds per activation (default 3; the paper: 10)")
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
    p.add_argument("--workers", type=Count(1, WORKERS_LIMIT), default=1,
                   help="with --finish: runs trained at a time, one process and one torch thread each (default 1)")
    _add_train_arguments(p)
    p.set_defaults(func=cmd_ablate)
