"""`tamp plan`: plan a problem file with the learned models, refine and execute the plan, report.

Open loop: plan with the chosen method, then (unless --execute none) refine the plan and execute it
in the Drake world: `fast` (the refinement's own world: planned, checked motions, kinematic carry,
physics after release) or `full` (the refined trajectory under physics). --replan executes action
by action in a World of that fidelity and plans again from each observed state until the goal (with
--rounds: the paper's loop of that many rounds).
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tamp.app.args import (
    MODELS_HELP,
    check_output_file,
    json_path,
    models_directory,
    non_negative_int,
    positive_int,
)
from tamp.app.faults import Faults, add_fault_arguments, faults_of
from tamp.app.plan_file import fmt_action
from tamp.app.search_record import SearchRecording, view_path
from tamp.app.settings import Settings, add_config_arguments, settings_of, settings_record
from tamp.errors import UserError
from tamp.planning.causes import cause_of, stop_record
from tamp.planning.config import PlanConfig
from tamp.planning.planners import METHODS, plan
from tamp.planning.results import PlanResult
from tamp.planning.search_record import facts_reader
from tamp.planning.search_trace import recording
from tamp.planning.steps import dynamics_errors
from tamp.planning.verify import goal_error
from tamp.planning.vocabulary import Outcome
from tamp.sim.world_types import FIDELITIES

if TYPE_CHECKING:  # the runner loads Drake: imported when a plan is run
    from tamp.app.observation import Observed
    from tamp.app.runner import ClosedLoopRun

STEPS_HELP = """\
reading the per-step output (the same in OUT.steps.json and the replay's panel; docs/studying-refinement.md):
  step k: the action (pick a block at a grasp offset, place it on a block at a release offset)
  symbols before   the Symbolic Model's bits on the observed state, as the facts they name
                   (MODELS/symbols.json from `tamp symbols`; unnamed bits keep raw names, r0(o1,o2)=1)
  operator         the learned operator grounding the action, the effect expected, its probability
  motion           refinement: IK branch, each motion's planner (direct or rrtconnect) and time, or
                   the stage where it failed and why
  observed         the symbols after the step: "the expected symbols", or MISMATCH and the bits
  Dynamics Model   its position error predicting the step from the observed state (mean over blocks)
"""

LEVELS = {1: "level 1 (verified symbolic plan)", 2: "level 2 (continuous search)"}


@dataclass
class PlanOptions:
    """`tamp plan`: what to plan with, and how to execute the plan."""

    method: str = "bilevel"
    execute: str = "fast"  # none | fast | full
    replan: bool = False
    rounds: int | None = None  # the paper's loop with this many replanning rounds; None: until the goal
    replay: Path | None = None
    planner: PlanConfig = PlanConfig()  # its seed is replaced by the problem's
    max_actions_given: bool = False  # --max-actions was given (it sets the loop that runs until the goal)
    settings: Settings = Settings()  # the resolved configuration, recorded in the outputs
    steps: Path | None = None  # per-step JSON (default: beside the replay, if any)
    trajectory: Path | None = None  # the executed joint trajectory (docs/trajectories.md)
    faults: Faults = Faults()  # with replan: observation noise and a push, drawn from the problem's seed
    name: str | None = None  # the problem of a problem set (`tamp problems`) to plan
    search: Path | None = None  # the search record (docs/search-record.md)


def _ms(t: float) -> str:
    return f"{t * 1e3:.1f} ms" if t < 1 else f"{t:.2f} s"


def print_result(result: PlanResult, tau: float, indent: str = "") -> None:
    p = indent
    if result.solved:
        assert result.plan is not None and result.level is not None and result.predicted_error is not None  # solved
        source = f", kept: the rest of the last round's plan, from {LEVELS[result.level]}" if result.kept else \
            f" from {LEVELS[result.level]}"
        print(f"{p}{result.method}: plan of {len(result.plan)} action(s){source}; "
              f"predicted final error {result.predicted_error * 100:.1f} cm")
    else:
        print(f"{p}{result.method}: no plan")
    if result.candidates and not result.kept:
        print(f"{p}  symbolic candidates, most frequent first (tau_verify {tau * 100:g} cm):")
        for i, c in enumerate(result.candidates[:10]):
            check = "not checked" if c.error is None else \
                f"error {c.error * 100:.1f} cm, {'verified' if c.verified else 'unverified'}"
            chosen = "  <- plan" if result.level == 1 and result.plan == list(c.actions) else ""
            source = f"one block at a time (blocks {', '.join(map(str, c.stages))})" if c.stages is not None \
                else f"{c.count:3d} domains ({c.probability:.2f})"
            print(f"{p}    {i + 1}. {source}: {list(c.actions)}; {check}{chosen}")
        if len(result.candidates) > 10:
            print(f"{p}    ... {len(result.candidates) - 10} more")
    if result.search is not None:
        s = result.search
        print(f"{p}  continuous search: {s.reason}; {s.generated} successors in {s.predict_calls} model calls")
    for k, a in enumerate(result.plan or []):
        print(f"{p}  action {k}: {fmt_action(a)}")
    shown = ("kept", "remembered")  # why the last plan was kept (on course, or its rollout); a miss the loop trusts
    for reason in result.reasons if not result.solved else [r for r in result.reasons if r.startswith(shown)]:
        print(f"{p}  {reason}")  # and why no plan
    rejected = result.rejected_dict()
    if rejected is not None:
        for level, counts in rejected.items():
            what = "candidate plans" if level == "level 1" else "successors"
            text = ", ".join(f"{reason} {count}" for reason, count in counts.items()) or "none"
            print(f"{p}  kinematic feasibility, {level}: {what} rejected: {text}")
        for x in result.refinements:
            outcome = "refined" if x["failed_action"] is None else \
                f"failed at action {x['failed_action']} ({x['reason']}: {x['message']})"
            print(f"{p}  full refinement of a level-{x['level']} plan of {len(x['plan'])} action(s): {outcome}")
    stages = ("keep", "symbols", "symbolic", "verify", "search", "feasibility", "refine", "total")
    print(f"{p}  timings: " + ", ".join(f"{k} {_ms(result.timings[k])}" for k in stages if k in result.timings))


# The runners load the simulator (Drake): imported when a plan is run, so that `tamp --help` and
# argument errors stay fast.

# Each runner returns (exit code, per-step records, the Episode: None when nothing was executed).

def _open_loop(problem, models, options: PlanOptions, cfg: PlanConfig, timeline, names,
               search: SearchRecording | None = None) -> tuple[int, list[dict], Any]:
    from tamp.app.runner import kinematics_for, run_episode
    from tamp.app.step_report import open_loop_steps

    kinematics = kinematics_for(options.method, cfg)
    if kinematics is not None:
        kinematics.reset(problem.X_init)
    with recording(None if search is None else search.recorder):
        result = plan(options.method, models, problem.X_init, problem.X_goal, cfg, kinematics=kinematics)
    if search is not None:
        search.planned(result, problem.X_init)
    print_result(result, cfg.verify.tau_verify)
    if not result.solved:
        print_cause("no_plan", None, stop_record(None, result), None)
        return 1, [], None
    if options.execute == "none" or not result.plan:
        if not result.plan:
            print("empty plan: the initial state already meets the goal; nothing to execute")
        return 0, [], None
    episode = run_episode(options.method, models, problem.X_init, problem.X_goal, cfg, options.execute, first=result,
                          timeline=timeline)
    ex = episode.execution
    assert ex is not None  # a plan to execute
    records = open_loop_steps(models, result, problem.X_init, ex, names,
                              timeline.action_starts if timeline is not None else ())
    _print_steps(records)
    if ex.refined.success:
        print(f"refinement: ok, {len(ex.refined.steps)} action(s) refined in {ex.refine_time:.2f} s, "
              f"{sum(s.duration for s in ex.refined.steps):.1f} s of arm motion")
    else:
        print(f"refinement: failed: {ex.refined.failure}; executing the {len(ex.refined.steps)} action(s) before it")
    ok = ex.error < cfg.verify.eps
    print(f"execution ({options.execute}): final error {ex.error * 100:.1f} cm (max over objects) -> "
          f"{'success' if ok else 'failure'} (eps {cfg.verify.eps * 100:g} cm)")
    failure = ex.refined.failure
    outcome = episode.outcome
    assert outcome is not None  # executed
    print_cause(outcome, dynamics_errors(models, [problem.X_init, *ex.X_after], result.plan, worst=True),
                stop_record(None, result), None if failure is None else failure.record())
    return (0 if outcome == Outcome.SUCCESS else 1), records, episode


def print_cause(outcome: str, step_miss_m, stop: dict, refine_failure: dict | None, indent: str = "") -> None:
    """The cause of a failed run (`tamp.planning.causes`), in one line; nothing for a success."""
    found = cause_of(outcome, step_miss_m, stop, refine_failure)
    if found is not None:
        print(f"{indent}cause: {found[1]} ({found[0]})")


def _print_steps(records: list[dict]) -> None:
    from tamp.app.step_report import print_steps  # it loads torch: imported when steps are printed

    print_steps(records)


def print_seen(seen: Observed, indent: str = "  ") -> None:
    """What perception said of one observation of the closed loop (nothing when it said nothing)."""
    for words in seen.said:
        print(f"{indent}perception: {words}")


def print_perception(run: ClosedLoopRun, indent: str = "") -> None:
    """With the cameras: how the loop's observations went, the error it learned and the truth's (never used)."""
    record = run.perception_record()
    if record is None:
        return
    learned = "none" if record["sigma_m"] is None else f"{record['sigma_m'] * 1000:.2f} mm"
    truth = "" if record["error_median_m"] is None else \
        f"; against the truth (not seen by the loop): median {record['error_median_m'] * 1000:.1f} mm, max " \
        f"{record['error_max_m'] * 1000:.1f} mm"
    print(f"{indent}perception  {record['observations']} observations ({record['looks']} renderings of the rig), "
          f"{record['failures']} with a failure said; learned error {learned} per x or y{truth}")


def _closed_loop(problem, models, options: PlanOptions, cfg: PlanConfig, timeline, names,
                 search: SearchRecording | None = None) -> tuple[int, list[dict], Any]:
    from tamp.app.observation import rig_for
    from tamp.app.runner import kinematics_for, run_episode
    from tamp.app.step_report import closed_loop_steps

    faults = options.faults if options.faults.any else None
    cameras = rig_for(options.settings.perception)
    seen = " (observed)" if cameras is not None or (faults is not None and faults.noise_m > 0) else ""

    def show_step(action, X, info, seconds) -> None:
        print(f"  executed {fmt_action(action)}: {info.status}{': ' + info.reason if info.reason else ''}; "
              f"now {goal_error(X, problem.X_goal) * 100:.1f} cm from the goal{seen}")
        if search is not None:
            search.executed(action, X)

    def show_round(r: int, result: PlanResult) -> None:
        if search is not None:
            search.planned(result)
        print(f"round {r}:")
        print_result(result, cfg.verify.tau_verify, indent="  ")

    if options.rounds is None:
        print(f"closed loop: plan again after every action until the goal, at most {cfg.loop.max_actions} actions, "
              f"executing in the {options.execute} world")
    else:
        print(f"closed loop (the paper's): up to {options.rounds} replanning round(s), executing in the "
              f"{options.execute} world")
    if faults is not None:
        print(f"faults (drawn from the problem's seed, as `tamp evaluate` draws them): {faults.describe()}")
    if cameras is not None:
        print(f"observing through {len(cameras.sensors)} cameras (perception.observe = \"cameras\"): the planner, "
              "the kinematic check and the skill take the perceived poses")
    with recording(None if search is None else search.recorder):
        episode = run_episode(options.method, models, problem.X_init, problem.X_goal, cfg, options.execute,
                              closed_loop=True, rounds=options.rounds, kinematics=kinematics_for(options.method, cfg),
                              timeline=timeline, on_round=show_round, on_step=show_step, faults=faults,
                              fault_seed=problem.seed, cameras=cameras, on_seen=print_seen)
    run = episode.run
    assert run is not None  # a closed loop
    out = run.loop
    records = closed_loop_steps(models, run, names)
    _print_steps(records)
    print(f"closed loop ended: {out.reason}")
    if run.faults:
        print(f"faults injected: {'; '.join(run.faults)}")
    outcome = episode.outcome
    assert outcome is not None  # a closed loop's outcome is where it ended
    observed = f", observed {out.error * 100:.1f} cm" if seen else ""
    print(f"execution ({options.execute}): {len(out.executed)} action(s), final error {run.error * 100:.1f} cm "
          f"(max over objects{observed}) -> {'success' if outcome == Outcome.SUCCESS else 'failure'} "
          f"(eps {cfg.verify.eps * 100:g} cm)")
    print_perception(run)
    print_cause(outcome, dynamics_errors(models, out.states, out.executed, worst=True),
                stop_record(out.stop, out.rounds[-1] if out.rounds else None), None)
    return (0 if outcome == Outcome.SUCCESS else 1), records, episode


def run_plan(problem_path: Path, models_dir: Path, options: PlanOptions) -> int:
    """The `tamp plan` command; returns the exit code (0: solved, and reached the goal if executed)."""
    import torch

    from tamp.app.problem import pick_problem
    from tamp.planning.models import load_bit_names, load_models

    # Planning runs many small forward passes: one thread is faster, and much faster when another
    # process keeps the second core busy (a 2-thread pass then waits for it: 20-40x slower, measured).
    torch.set_num_threads(1)
    problem = pick_problem(problem_path, options.name)
    if options.rounds is not None and not options.replan:
        raise UserError("--rounds sets the replanning rounds of the closed loop; give it with --replan")
    if options.max_actions_given and (not options.replan or options.rounds is not None):
        raise UserError("--max-actions sets the loop that runs until the goal; give it with --replan and no --rounds")
    if options.faults.any and not options.replan:
        raise UserError("--noise and --push disturb the closed loop; give them with --replan")
    if options.replan and options.execute == "none":
        raise UserError("--replan executes actions and observes the world; it needs --execute fast or full")
    if options.replay is not None and options.execute == "none":
        raise UserError("--replay needs an execution (--execute fast or full)")
    if options.replay is not None:
        check_output_file(options.replay, "--replay")
    check_search_output(options.search)
    steps_file = options.steps
    if steps_file is None and options.replay is not None:
        from tamp.app.step_report import steps_path

        steps_file = steps_path(options.replay)
    if options.trajectory is not None:
        if options.execute == "none":
            raise UserError("--trajectory records the executed motion; it needs --execute fast or full")
        check_output_file(options.trajectory, "--trajectory")
    if steps_file is not None:
        if options.execute == "none":
            raise UserError("--steps records executed steps; it needs --execute fast or full")
        check_output_file(steps_file, "--steps")
    models = load_models(models_dir, need_symbolic=True if options.method != "cfs" else None)
    names = load_bit_names(models_dir)
    cfg = options.planner.with_seed(problem.seed)
    models.require_objects(problem.n, str(problem_path))
    k = "?" if problem.k is None else problem.k
    symbolic = "" if options.method == "cfs" else f"; symbolic planner {cfg.level1.backend}"
    which = str(problem_path) if options.name is None else f"{problem_path} --name {options.name}"
    print(f"problem {which}: {problem.n} objects, k = {k}, seed {problem.seed}; initial error "
          f"{goal_error(problem.X_init, problem.X_goal) * 100:.1f} cm{symbolic}")
    timeline = None
    if options.replay is not None:
        from tamp.sim.replay import Timeline

        timeline = Timeline()
    runner = _closed_loop if options.replan else _open_loop
    search = None if options.search is None else search_recording(
        problem, which, models, names, settings_record(replace(options.settings, planner=cfg)), options.replay)
    code, records, episode = runner(problem, models, options, cfg, timeline, names, search)
    if search is not None:
        assert options.search is not None  # the recording is made for it
        search.write(options.search)
    if steps_file is not None and records:
        from tamp.app.step_report import steps_document, write_steps

        write_steps(steps_file, steps_document(which, options.method, None, records, names,
                                               settings_record(replace(options.settings, planner=cfg))))
        print(f"steps written to {steps_file}")
    if timeline is not None:
        from tamp.app.step_report import panel_entries

        timeline.show_panel(panel_entries(records, timeline.t_end))
        if timeline.times:
            assert options.replay is not None  # the timeline exists for it
            path = timeline.write_html(options.replay)
            print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB)")
        else:
            print("nothing was executed; no replay written")
    if options.trajectory is not None:
        source = (f"tamp plan --problem {which} --method {options.method} --execute {options.execute}"
                  + (" --replan" if options.replan else ""))
        write_executed_trajectory(None if episode is None else episode.motion, options.trajectory, source,
                                  settings_record(replace(options.settings, planner=cfg)))
    return code


def search_recording(problem, source: str, models, names, configuration: dict,
                     replay: Path | None = None) -> SearchRecording:
    """The search record of a run of `problem` (`source`: how the run named it; `replay`: its Meshcat replay)."""
    facts = None if models.domain is None else \
        facts_reader(models.domain.n_unary, models.domain.n_relations, names, problem.n)
    return SearchRecording({"name": problem.name, "X_init": problem.X_init, "X_goal": problem.X_goal,
                            "source": source}, configuration, names, facts, replay=replay)


def write_executed_trajectory(executed, path: Path, source: str, configuration: dict) -> None:
    """`--trajectory` of `tamp plan` and `tamp demo`: write what `executed` (an Execution or a
    ClosedLoopRun; None: nothing ran) moved, with the `configuration` that planned it, and say so."""
    import time

    from tamp.app.runner import executed_trajectory
    from tamp.sim.trajectory_file import write_trajectory

    if executed is None:
        print("nothing was executed; no trajectory written")
        return
    t = time.perf_counter()
    trajectory = executed_trajectory(executed, source, configuration)
    if not trajectory.actions:
        print("no executed action moved the arm; no trajectory written")
        return
    written = write_trajectory(path, trajectory)
    segments = sum(len(a.segments) for a in trajectory.actions)
    print(f"trajectory written to {written} ({len(trajectory.actions)} action(s), {segments} segments, "
          f"{trajectory.samples} samples, {written.stat().st_size / 1e3:.0f} kB, in {time.perf_counter() - t:.2f} s)")


def add_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of `tamp plan`."""
    p.add_argument("--problem", type=Path, required=True,
                   help="problem file (JSON: X_init, X_goal, k, seed), or a problem set of `tamp problems` "
                   "(JSON Lines; pick its problem with --name)")
    p.add_argument("--name", default=None, help="the problem of a problem set to plan (e.g. n4-k3-002)")
    p.add_argument("--models", type=models_directory, default=None, help=MODELS_HELP + "; default: pretrained")
    p.add_argument("--method", choices=tuple(METHODS), default="bilevel",
                   help="planner (default bilevel: verified symbolic plan, else continuous search; "
                   "bilevel_alg1: the paper's Algorithm 1 without our Level-1 extensions)")
    p.add_argument("--replan", action="store_true",
                   help="closed loop: execute the first action, observe, plan again, until the goal is reached or "
                   "--max-actions actions were sent; a round that finds no plan first searches again over every "
                   "action (loop.widen = false: it stops)")
    p.add_argument("--rounds", type=non_negative_int, default=None,
                   help="with --replan, the paper's loop instead: this many replanning rounds (the paper gives k - 1 "
                   "for a goal of k random actions), the last plan executed to its end, and it stops when a round "
                   "finds no plan")
    p.add_argument("--execute", choices=("none", *FIDELITIES), default="fast",
                   help="refine and execute the plan in the fast world (default) or with the arm under "
                   "physics (full), or not at all")
    p.add_argument("--replay", type=Path, default=None, metavar="OUT.html",
                   help="write a Meshcat HTML replay, with a panel showing each step's symbols as the timeline "
                   "plays (open OUT.html#step=2 to start at step 2); the steps' JSON goes beside it, "
                   "OUT.steps.json")
    p.add_argument("--steps", type=Path, default=None, metavar="OUT.json",
                   help="write the per-step record as JSON (default: beside the replay, if any)")
    add_search_argument(p)
    add_trajectory_argument(p)
    add_fault_arguments(p, "with --replan")
    add_max_actions_argument(p, "with --replan")
    add_config_arguments(p)


def add_max_actions_argument(p: argparse.ArgumentParser, which: str) -> None:
    """--max-actions: the action budget of the loop that runs until the goal (`LoopConfig.max_actions`)."""
    p.add_argument("--max-actions", type=positive_int, default=None, metavar="N",
                   help=f"{which}: give up after sending N actions (default: loop.max_actions of "
                   "the configuration, 30: a goal of k <= 5 random actions needs 5, the rest is room for detours)")


def add_search_argument(p: argparse.ArgumentParser) -> None:
    """--search of `tamp plan` and `tamp demo`."""
    p.add_argument("--search", type=json_path, default=None, metavar="OUT.json",
                   help="write the search record: what each planning call considered (Level 1's candidates, the "
                   "continuous search's tree, refinements, the closed loop's rounds; docs/search-record.md) and "
                   "its view beside it, OUT.html (one offline page; `tamp view --search` writes it again)")


def check_search_output(path: Path | None) -> None:
    """--search's record and the view written beside it (`view_path`), checked before any work."""
    if path is not None:
        for out in (path, view_path(path)):
            check_output_file(out, "--search")


def add_trajectory_argument(p: argparse.ArgumentParser) -> None:
    """--trajectory of `tamp plan` and `tamp demo`."""
    p.add_argument("--trajectory", type=json_path, default=None, metavar="OUT.json",
                   help="write the executed arm motion for a real UR10e or another simulator: per action and "
                   "motion, joint positions (rad), velocities (rad/s), accelerations (rad/s^2) and times, each "
                   "motion shaped as a ROS trajectory_msgs/JointTrajectory, the gripper's close and open events, "
                   "the joint names and limits; checked against the UR10e model's limits (docs/trajectories.md; "
                   "`tamp view --trajectory OUT.json` executes it again)")


def options_from_args(args: argparse.Namespace) -> PlanOptions:
    if args.replay is not None and args.replay.suffix.lower() not in (".html", ".htm"):
        raise UserError(f"the replay is an HTML file; give a path ending in .html, got {args.replay}")
    if args.steps is not None and args.steps.suffix.lower() != ".json":
        raise UserError(f"the steps file is JSON; give a path ending in .json, got {args.steps}")
    faults, settings = faults_of(args), settings_of(args)
    # the loop knows its noise (with the cameras: it learns it)
    planner = replace(settings.planner, loop=faults.known_to(settings.planner.loop, settings.perception.cameras_on))
    settings = replace(settings, planner=planner)
    return PlanOptions(args.method, args.execute, args.replan, args.rounds, args.replay, planner,
                       args.max_actions is not None, settings, args.steps, args.trajectory, faults, args.name,
                       args.search)
