"""Where a `bilevel` planning call spends its time: the kinematic check's parts, the Dynamics Model, the rest.

    .venv/bin/python bench/search_profile.py --problems P.jsonl --names n3-k3-000,n4-k4-000

Plans each named problem twice with the bundled models and kinematics in the loop (the first call warms
the collision models and the symbolic grounding), profiles the second with cProfile and times a third
without it; cProfile's shares are applied to the unprofiled wall time, since the profiler slows the many
small calls more than the few large ones. Prints one markdown table, a column per problem. Run it from
two checkouts on an idle machine to compare a change with its baseline.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

ROOT = Path.cwd() if (Path.cwd() / "tamp").is_dir() else Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

# (row, file of the function, its name, file whose calls of it count; None: the geometry functions below)
PARTS = [
    ("kinematic check", "tamp/sim/kinematic_checker.py", "check", "tamp/planning/kinematic_check.py"),
    ("- closed-form IK", "tamp/sim/kinematics.py", "solve_chain", "tamp/sim/kinematic_checker.py"),
    ("- attaching the carried boxes", "tamp/sim/motion.py", "attach", "tamp/sim/kinematic_checker.py"),
    ("- waypoint geometry (grasp, corners, stacking, box test)", "tamp/sim/", None, "tamp/sim/kinematic_checker.py"),
    ("- collision queries", "tamp/sim/motion.py", "is_valid", "tamp/sim/kinematic_checker.py"),
    ("Dynamics Model, successors", "tamp/planning/search.py", "predict_positions", "tamp/planning/search.py"),
    ("refinement of the plans found (IK, OMPL)", "tamp/sim/kinematic_checker.py", "refine",
     "tamp/planning/kinematic_check.py"),
]
GEOMETRY = ("approach_poses", "held_block", "pick_waypoints", "pick_place_waypoints", "_place_occupied",
            "carried_shapes", "predicted_scene")
REST = "the search's own work, Level 1"


def from_callers(stats: pstats.Stats, file: str, names: tuple[str, ...], caller_file: str) -> float:
    """Cumulative seconds of the functions `names` of `file`, counting only the calls made from `caller_file`."""
    total = 0.0
    for (path, _, func), (_, _, _, _, callers) in stats.stats.items():  # type: ignore[attr-defined]
        if func in names and file in path:
            total += sum(ct for (cpath, _, _), (_, _, _, ct) in callers.items() if cpath.endswith(caller_file))
    return total


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--problems", type=Path, required=True, help="problem set (tamp problems --out)")
    p.add_argument("--names", required=True, help="comma-separated problem names")
    p.add_argument("--models", default=str(ROOT / "tamp" / "pretrained"))
    args = p.parse_args()

    import torch

    from tamp.app.problem import read_problem_set
    from tamp.planning.config import PlanConfig
    from tamp.planning.models import load_models
    from tamp.planning.planners import plan
    from tamp.sim.kinematic_checker import FeasibilityChecker
    try:
        from tamp.sim.kinematics import forget_ik_answers
    except ImportError:  # a checkout from before IK answers were remembered
        forget_ik_answers = None

    torch.set_num_threads(1)
    problems = {problem.name: problem for problem in read_problem_set(args.problems)}
    models = load_models(args.models)
    checker = FeasibilityChecker()
    columns: list[tuple[str, dict[str, float]]] = []
    for name in args.names.split(","):
        problem = problems[name]

        def call(problem=problem):
            checker.reset(problem.X_init)
            if forget_ik_answers is not None:
                forget_ik_answers()  # as a fresh process would: no IK answer remembered from the call before
            return plan("bilevel", models, problem.X_init, problem.X_goal, PlanConfig().with_seed(problem.seed),
                        kinematics=checker)

        call()
        profiler = cProfile.Profile()
        profiler.enable()
        result = call()
        profiler.disable()
        t = time.perf_counter()
        call()
        wall = time.perf_counter() - t
        stats = pstats.Stats(profiler)
        profiled = from_callers(stats, "tamp/planning/planners.py", ("plan",), "search_profile.py")
        values = {"planning call": wall}
        for row, file, func, caller in PARTS:
            values[row] = wall * from_callers(stats, file, (func,) if func else GEOMETRY, caller) / profiled
        values[REST] = wall - values["kinematic check"] - values[PARTS[5][0]] - values[PARTS[6][0]]
        search = result.search
        status = "no search" if search is None else f"{search.expanded:,} expansions, {search.status}"
        columns.append((f"{name} ({status})", values))

    print("| seconds (share) | " + " | ".join(title for title, _ in columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    for row in ["planning call", *(part[0] for part in PARTS), REST]:
        cells = [f"{v[row]:.2f}" if row == "planning call" else f"{v[row]:.2f} ({v[row] / v['planning call']:.0%})"
                 for _, v in columns]
        print(f"| {row} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
