"""The `tamp` command line: one subcommand per step of the pipeline, each in a `commands_*` module by group."""
from __future__ import annotations

import argparse
import gc
import os
import sys

from tamp.app import (
    commands_data,
    commands_learning,
    commands_planning,
    commands_symbolic,
    commands_world,
    perceive_command,
    settings,
)
from tamp.app.args import Count
from tamp.errors import is_user_error


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="tamp",
        description="Bilevel task-and-motion planning for a UR10e picking and placing blocks in Drake.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    commands_world.add_simulate(sub)
    commands_data.add_collect(sub)
    commands_data.add_dataset_stats(sub)
    commands_world.add_view(sub)
    perceive_command.add_perceive(sub)
    commands_learning.add_train(sub)
    commands_learning.add_ablate_activations(sub)
    commands_symbolic.add_domain(sub)
    commands_symbolic.add_pddl(sub)
    commands_symbolic.add_symbols(sub)
    commands_planning.add_plan(sub)
    commands_planning.add_demo(sub)
    settings.add_config(sub)
    _add_plugin_commands(sub)
    for command in sub.choices.values():
        state_limits(command)
    return parser


def state_limits(parser: argparse.ArgumentParser) -> None:
    """Say in the help of every count flag (type `Count`) the largest value it takes, where it does not yet."""
    for action in parser._actions:
        if isinstance(action.type, Count) and action.help and f"{action.type.limit:,}" not in action.help:
            action.help += f" (at most {action.type.limit:,})"


def _add_plugin_commands(sub) -> None:
    """Subcommands of the packages above `tamp` (e.g. `evaluate`, `reproduce` from `evaluation`).

    They register through the `tamp.commands` entry-point group (see pyproject.toml), each a function
    `register(subparsers)`, so that `tamp` itself never imports the packages that import it.
    """
    from importlib.metadata import entry_points

    for ep in sorted(entry_points(group="tamp.commands"), key=lambda e: e.name):
        ep.load()(sub)


def _interrupted(error: BaseException) -> bool:
    """Whether `error` was raised because of a KeyboardInterrupt (its cause or context, at any depth)."""
    seen: set[int] = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__  # type: ignore[assignment]
    return False


def main(argv: list[str] | None = None) -> int:
    """Run one command; returns the exit code (2 for a user error, with a one-line message; any other
    exception propagates with its traceback)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except Exception as error:
        if _interrupted(error):  # Ctrl-C inside an import that wraps it (pydrake: ImportError "initialization failed")
            print(f"tamp {args.command}: interrupted", file=sys.stderr)
            code = 130
        elif not is_user_error(error):
            raise  # a bug: the traceback says where
        else:
            print(f"tamp {args.command}: error: {error}", file=sys.stderr)
            code = 2
    except KeyboardInterrupt:
        print(f"tamp {args.command}: interrupted", file=sys.stderr)
        code = 130
    if code == 130:
        # an interrupted process pool (tamp.app.parallel) is unreachable now but held in reference cycles:
        # collected here, its queues release their semaphores before `entry` leaves without a teardown
        gc.collect()
    return code


def entry() -> None:
    """Console-script entry point."""
    try:
        code = main()
        sys.stdout.flush()
        sys.stderr.flush()
    except BrokenPipeError:  # the reader of stdout went away (`tamp ... | head`): nothing more to say
        code = 0
    except KeyboardInterrupt:  # Ctrl-C before the command ran (while its modules load)
        print("tamp: interrupted", file=sys.stderr)
        code = 130
    # OMPL's nanobind bindings print "leaked instances" warnings at interpreter exit; nothing is
    # left to clean up here, so leave without running the interpreter's teardown.
    os._exit(code)


if __name__ == "__main__":
    entry()
