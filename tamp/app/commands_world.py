"""`tamp simulate` and `tamp view`: the Drake world and its skill, run directly."""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from tamp.app.args import (
    MAX_OBJECTS,
    Count,
    _html_path,
    check_output_file,
    seed,
)
from tamp.errors import UserError


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
    an exported trajectory file (--trajectory); or write the view of a search record (--search)."""
    if sum(given is not None for given in (args.plan, args.trajectory, args.search)) != 1:
        raise UserError("give a plan file, --trajectory FILE or --search FILE (one of them)")
    if args.search is not None:
        return view_search(args.search, args.out)
    out = args.out or Path("replay.html")
    if args.trajectory is not None:
        return view_trajectory(args.trajectory, out)
    from tamp.app.plan_file import load_plan_file
    from tamp.sim.execute import execute
    from tamp.sim.refine import refine
    from tamp.sim.replay import Timeline

    X, plan = load_plan_file(args.plan)
    check_output_file(out, "--out")
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
    path = timeline.write_html(out)
    print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB)")
    return 0 if refined.failure is None else 1


def view_search(path: Path, out: Path | None) -> int:
    """`tamp view --search`: read a search record (`tamp plan --search`) through its schema and write its view,
    one self-contained HTML page (default: the record's name with .html)."""
    from tamp.app.search_record import read_search_record, view_path
    from tamp.app.search_view import summary, write_search_view

    if out is None:
        out = view_path(path)
    check_output_file(out, "--out")
    record = read_search_record(path)
    written = write_search_view(record, out)
    print(f"{path}: {summary(record)}")
    print(f"search view written to {written} ({written.stat().st_size / 1e3:.0f} kB); open it in a browser")
    return 0


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
          f"consistent and continuous; recorded in the {trajectory.world} world{by}")
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


def add_simulate(sub) -> None:
    """`tamp simulate`."""
    p = sub.add_parser(
        "simulate",
        help="random pick-place actions on a random scene, with an optional Meshcat replay",
        description="Reset a random scene and execute random pick-place actions with the real skill "
        "(IK, OMPL motions, physics after release). Prints one line per action: the action, what "
        "happened and where the time went.",
    )
    p.add_argument("--objects", type=int, default=3, help=f"number of blocks, 1..{MAX_OBJECTS} (default 3)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the scene and the actions (default 0)")
    p.add_argument("--steps", type=Count(1, 10_000), default=5, help="number of random actions (default 5)")
    p.add_argument("--json", action="store_true", help="print JSON lines instead of text")
    p.add_argument("--replay", type=_html_path, metavar="OUT.html",
                   help="write a self-contained Meshcat HTML replay of the arm and blocks")
    p.set_defaults(func=cmd_simulate)


def add_view(sub) -> None:
    """`tamp view`."""
    p = sub.add_parser(
        "view",
        help="execute a plan file or an exported trajectory with the full arm under physics, write a replay; or "
        "write the view of a search record",
        description="Refine a plan (JSON: {\"X\": [[x, y, z, small, large], ...], \"actions\": "
        "[[pick, grasp_offset, place, release_offset], ...]}) into collision-free joint "
        "trajectories, execute them with the arm under Drake physics, and write a self-contained "
        "Meshcat HTML replay. If an action cannot be refined, the actions before it are executed and "
        "the command exits with status 1. With --trajectory FILE (written by `tamp plan` or `tamp demo "
        "--trajectory`), execute that file's motion instead, to check it before sending it to an arm. With --search "
        "FILE (written by `tamp plan --search`), write the page that shows what the planner considered: Level 1's "
        "ranked symbolic plans, Level 2's tree, their predicted scenes and the refinement of the chosen plan.",
    )
    p.add_argument("plan", nargs="?", type=Path, default=None, help="plan file (JSON)")
    p.add_argument("--trajectory", type=Path, default=None, metavar="FILE",
                   help="instead of a plan, execute a trajectory file (`tamp plan/demo --trajectory`) with the arm "
                   "under physics from its recorded initial scene: the file is checked first (format, robot, "
                   "joint limits, continuity; a bad file is a one-line error, exit 2, nothing written), then "
                   "each action's and the final scene are compared with the recorded execution (exit 1 if a "
                   "grasp missed or, for a file recorded in the full world, a block ends over 2 mm away)")
    p.add_argument("--search", type=Path, default=None, metavar="FILE",
                   help="instead, write the view of a search record (`tamp plan --search FILE`): one self-contained "
                   "HTML page that works offline, with the closed loop's rounds as tabs, Level 1's candidates, Level "
                   "2's tree (filters, a timeline of the expansions) and each one's predicted scene; a bad record is "
                   "a one-line error, exit 2, nothing written")
    p.add_argument("--out", type=_html_path, default=None, metavar="OUT.html",
                   help="the page to write (default replay.html; with --search, the record's name with .html)")
    p.set_defaults(func=cmd_view)
