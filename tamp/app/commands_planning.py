"""`tamp plan` and `tamp demo`: planning with the learned models, refined and executed."""
from __future__ import annotations

import argparse
import textwrap
from pathlib import Path

from tamp.app.args import (
    MAX_K,
    MAX_OBJECTS,
    MODELS_HELP,
    Count,
    _html_path,
    check_output_file,
    models_directory,
    seed,
)
from tamp.errors import UserError
from tamp.sim.world_types import FIDELITIES


def cmd_plan(args: argparse.Namespace) -> int:
    """Plan a problem file with the learned models; refine, execute and replay the plan."""
    from tamp.app.plan_command import options_from_args, run_plan
    from tamp.planning.models import pretrained_dir

    return run_plan(args.problem, args.models or pretrained_dir(), options_from_args(args))


def cmd_demo(args: argparse.Namespace) -> int:
    """A random problem planned, refined, executed under physics, summarised and replayed."""
    from dataclasses import replace

    from tamp.app.demo import DemoConfig, run_demo
    from tamp.app.faults import Faults
    from tamp.app.plan_command import check_search_output
    from tamp.app.settings import settings_of

    check_output_file(args.replay, "--replay")
    if args.open_loop and args.max_actions is not None:
        raise UserError("--max-actions sets the closed loop; --open-loop executes one plan")
    settings = settings_of(args)
    planner = settings.planner
    if settings.perception.cameras_on:  # the closed loop learns the cameras' error and looks again after a failure
        planner = replace(planner, loop=Faults().known_to(planner.loop, cameras=True))
    if args.trajectory is not None:
        check_output_file(args.trajectory, "--trajectory")
    check_search_output(args.search)
    cfg = DemoConfig(seed=args.seed, objects=args.objects, actions=args.actions, models=args.models,
                     fidelity=args.fidelity, replay=args.replay, candidates=args.candidates,
                     replan=not args.open_loop, trajectory=args.trajectory, planner=planner, search=args.search,
                     perception=settings.perception)
    return 0 if run_demo(cfg).success else 1


def add_plan(sub) -> None:
    """`tamp plan`."""
    from tamp.app.plan_command import STEPS_HELP as PLAN_STEPS_HELP
    from tamp.app.plan_command import add_arguments as add_plan_arguments

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


def add_demo(sub) -> None:
    """`tamp demo`."""
    from tamp.app.plan_command import add_max_actions_argument, add_search_argument, add_trajectory_argument
    from tamp.app.settings import add_config_arguments

    p = sub.add_parser(
        "demo",
        help="solve a random 3-block problem end to end with the bundled models; summary and replay",
        description="Generate a random problem (--objects blocks, the goal after --actions random "
        "actions), solve it with the bilevel planner, refine the plan into arm trajectories, execute "
        "them with the full arm under physics and print a summary: the problem, the plan and the level "
        "that produced it, each symbolic candidate's verification error, planning, refinement and "
        "execution times, the final error and success (every block within 5 cm of its goal). By "
        "default the loop is closed: after each action the scene is observed and the plan made again "
        "from it, until the goal is reached or --max-actions actions were sent (a round that finds no plan "
        "first searches again over every action); --open-loop executes the first plan to its end. The "
        "Meshcat HTML replay shows the goal (green) and the Dynamics Model's predicted blocks after "
        "each action (orange) as translucent blocks beside the executed ones. Exit status 0 on "
        "success, 1 if there was no plan, the plan could not be refined or it missed the goal. The "
        "planner's settings come from the configuration (--preset, --config; `tamp config show`).",
    )
    p.add_argument("--seed", type=seed, default=0, help="seed of the problem and the planner (default 0)")
    p.add_argument("--objects", type=Count(1, MAX_OBJECTS), default=3, help="number of blocks (default 3)")
    p.add_argument("--actions", type=Count(1, MAX_K), default=3,
                   help="k: random actions that generate the goal (default 3)")
    p.add_argument("--models", type=models_directory, default=None,
                   help=MODELS_HELP + "; default: pretrained")
    p.add_argument("--fidelity", choices=FIDELITIES, default="full",
                   help="execute with the arm under physics (full, default) or in the fast world")
    p.add_argument("--replay", type=_html_path, default=Path("demo_replay.html"), metavar="OUT.html",
                   help="replay file (default demo_replay.html)")
    p.add_argument("--open-loop", action="store_true",
                   help="execute one plan to its end (the paper's Algorithm 1) instead of the closed loop "
                   "that executes the first action, observes the scene and plans again until the goal")
    p.add_argument("--candidates", type=Count(0, 10_000), default=0, metavar="N",
                   help="also execute the first N symbolic candidates that failed verification and write "
                   "a replay of each (OUT.candidateI.html, I their number in the candidate list)")
    add_search_argument(p)
    add_trajectory_argument(p)
    add_max_actions_argument(p, "closed loop")
    add_config_arguments(p)
    p.set_defaults(func=cmd_demo)
