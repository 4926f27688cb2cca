"""The `tamp` command line: one subcommand per step of the pipeline."""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def _html_path(text: str) -> Path:
    path = Path(text)
    if path.suffix.lower() not in (".html", ".htm"):
        raise argparse.ArgumentTypeError(f"the replay is an HTML file; give a path ending in .html, got {text!r}")
    return path


def cmd_simulate(args: argparse.Namespace) -> int:
    """Random pick-place actions on a random scene, one line per action."""
    from tamp import World, WorldConfig
    from tamp.replay import Timeline

    world = World(WorldConfig(), seed=args.seed)
    if args.replay:
        world.timeline = Timeline()
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
        path = world.timeline.write_html(args.replay)
        print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB); open it in a browser",
              file=sys.stderr if args.json else sys.stdout)
    return 0


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
    p.add_argument("--objects", type=_positive_int, default=3, help="number of blocks, 1..6 (default 3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the scene and the actions (default 0)")
    p.add_argument("--steps", type=_positive_int, default=5, help="number of random actions (default 5)")
    p.add_argument("--json", action="store_true", help="print JSON lines instead of text")
    p.add_argument("--replay", type=_html_path, metavar="OUT.html",
                   help="write a self-contained Meshcat HTML replay of the arm and blocks")
    p.set_defaults(func=cmd_simulate)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (2 for a user error, with a one-line message)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except (ValueError, FileNotFoundError, RuntimeError) as error:
        print(f"tamp {args.command}: error: {error}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print(f"tamp {args.command}: interrupted", file=sys.stderr)
        code = 130
    return code


def entry() -> None:
    """Console-script entry point."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    # OMPL's nanobind bindings print "leaked instances" warnings at interpreter exit; nothing is
    # left to clean up here, so leave without running the interpreter's teardown.
    os._exit(code)


if __name__ == "__main__":
    entry()
