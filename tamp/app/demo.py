"""`tamp demo`: one random problem solved end to end, with a replay that shows the model's predictions.

A random scene of `objects` blocks and the goal after `actions` random actions that moved something
(`tamp.app.problem.random_problem`) is planned with the bilevel planner and the pretrained models shipped
in the package (or --models), refined into joint trajectories, executed with the full arm under
physics (or in the fast world), and summarised. The Meshcat replay shows, beside the executed
blocks, the goal (translucent green) and the Dynamics Model's predicted blocks after the current
action (translucent orange), as in the paper's Fig. 3. With `candidates` = N, the first N symbolic
candidates that failed verification are executed the same way, each into its own replay, so one
can see why verification rejected them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tamp.app.observation import rig_for
from tamp.app.plan_command import (
    LEVELS,
    print_cause,
    print_perception,
    print_result,
    print_seen,
    search_recording,
    write_executed_trajectory,
)
from tamp.app.plan_file import fmt_action
from tamp.app.problem import Problem, random_problem
from tamp.app.runner import ClosedLoopRun, Episode, Execution, execute_plan, kinematics_for, run_episode
from tamp.app.search_record import SearchRecording
from tamp.app.settings import Settings, settings_record
from tamp.app.step_report import (
    closed_loop_steps,
    open_loop_steps,
    panel_entries,
    print_steps,
    steps_document,
    steps_path,
    write_steps,
)
from tamp.errors import UserError
from tamp.planning.causes import stop_record
from tamp.planning.closed_loop import ClosedLoopResult
from tamp.planning.config import PlanConfig
from tamp.planning.planners import plan
from tamp.planning.results import PlanResult
from tamp.planning.search_trace import recording
from tamp.planning.steps import dynamics_errors
from tamp.planning.verify import goal_error, goal_errors, rollout
from tamp.planning.vocabulary import TYPE_NAMES, Outcome, PickPlace
from tamp.sim.kinematic_checker import FeasibilityChecker
from tamp.sim.perception_config import PerceptionConfig
from tamp.sim.replay import Timeline
from tamp.sim.world_types import WorldConfig, fidelity_of

DEFAULT_REPLAY = Path("demo_replay.html")


@dataclass(frozen=True)
class DemoConfig:
    """Options of `tamp demo` (see the module docstring)."""

    seed: int = 0  # seeds the scene, the goal-generating actions and the sampled symbolic domains
    objects: int = 3
    actions: int = 3  # k: random actions that generate the goal
    models: Path | None = None  # models directory; None: the pretrained models in the package
    fidelity: str = "full"  # full: the arm under physics; fast: the refinement's own world
    replay: Path | None = DEFAULT_REPLAY
    candidates: int = 0  # also replay this many symbolic candidates that failed verification
    replan: bool = True  # closed loop: execute, observe, plan again until the goal (or the action budget); False:
    #   one plan, executed open loop
    trajectory: Path | None = None  # write the executed arm motion here (docs/trajectories.md)
    planner: PlanConfig = PlanConfig()  # the planner's settings, `tamp plan`'s (its seed is the demo's)
    perception: PerceptionConfig = PerceptionConfig()  # what the closed loop observes: the truth or the cameras
    search: Path | None = None  # write the search record here (docs/search-record.md)


@dataclass
class DemoResult:
    problem: Problem
    result: PlanResult | None  # the first plan (None: the closed loop observing through the cameras planned none)
    execution: Execution | None  # None: no plan
    eps: float  # metres
    replays: list[Path] = field(default_factory=list)
    loop: ClosedLoopResult | None = None  # closed loop (replan): every round and executed action
    loop_run: ClosedLoopRun | None = None  # closed loop: the run in the world (its steps and motion)
    step_times: list[tuple[float, float]] = field(default_factory=list)  # closed loop: (refine, execute) s
    steps: list[dict] = field(default_factory=list)  # per executed step (tamp.app.step_report records)
    search: SearchRecording | None = None  # the search record being made (cfg.search)

    @property
    def episode(self) -> Episode:
        return Episode(self.result, self.eps, self.execution, self.loop_run)

    @property
    def outcome(self) -> Outcome:
        """As `tamp evaluate` counts it (closed loop: no plan, wrong plan or success)."""
        outcome = self.episode.outcome
        assert outcome is not None  # a demo executes every plan it finds
        return outcome

    @property
    def success(self) -> bool:
        return self.outcome == Outcome.SUCCESS


def run_demo(cfg: DemoConfig = DemoConfig()) -> DemoResult:
    """Generate, plan, refine, execute (closed loop unless cfg.replan is False), print the summary and
    write the replay(s)."""
    import torch

    from tamp.planning.models import load_bit_names, load_models, pretrained_dir

    fidelity_of(cfg.fidelity)
    if cfg.candidates < 0:
        raise UserError(f"candidates must be 0 or more, got {cfg.candidates}")
    if cfg.candidates and cfg.replay is None:
        raise UserError("candidate replays need a replay path")
    torch.set_num_threads(1)
    models_dir = pretrained_dir() if cfg.models is None else Path(cfg.models)
    models = load_models(models_dir)
    names = load_bit_names(models_dir)
    models.require_objects(cfg.objects, f"--objects {cfg.objects}: the scene")
    plan_cfg = cfg.planner.with_seed(cfg.seed)
    kinematics = kinematics_for("bilevel", plan_cfg)

    problem = random_problem(cfg.objects, cfg.actions, cfg.seed)
    _print_problem(problem, models_dir)
    result = None
    search = None if cfg.search is None else search_recording(problem, _source(cfg), models, names, _record(cfg),
                                                              cfg.replay)
    if cfg.replan and cfg.perception.cameras_on:  # the first plan too is made from what the cameras see
        print(f"\nplanning (bilevel, {plan_cfg.level1.n_domains} sampled domains) from what the cameras see: "
              "round 0 of the closed loop", flush=True)
    else:
        print(f"\nplanning (bilevel, {plan_cfg.level1.n_domains} sampled domains):", flush=True)
        if kinematics is not None:
            kinematics.reset(problem.X_init)
        with recording(None if search is None else search.recorder):
            result = plan("bilevel", models, problem.X_init, problem.X_goal, plan_cfg, kinematics=kinematics)
        if search is not None and not cfg.replan:
            search.planned(result, problem.X_init)  # the closed loop's first round takes it from the recorder
        print_result(result, plan_cfg.verify.tau_verify, indent="  ")
    out = DemoResult(problem, result, None, plan_cfg.verify.eps, search=search)

    timeline = Timeline() if cfg.replay is not None else None
    episode = _closed_loop_episode if cfg.replan else _open_loop_episode
    episode(out, models, names, plan_cfg, kinematics, cfg, timeline)
    if cfg.candidates:
        _replay_candidates(out, models, cfg)
    if cfg.trajectory is not None:
        write_executed_trajectory(out.episode.motion, cfg.trajectory, _source(cfg), _record(cfg))
    if search is not None:
        assert cfg.search is not None  # the recording is made for it
        search.write(cfg.search)
    return out


def _closed_loop_episode(out: DemoResult, models, names, plan_cfg: PlanConfig, kinematics: FeasibilityChecker | None,
                         cfg: DemoConfig, timeline: Timeline | None) -> None:
    """Execute, observe and plan again until the goal (`_closed_loop`), then the steps, the summary, the
    cause of a failure and the replay."""
    problem = out.problem
    with recording(None if out.search is None else out.search.recorder):
        run = _closed_loop(problem, models, plan_cfg, kinematics, cfg, out.result, timeline, out.step_times,
                           out.search)
    out.loop, out.loop_run, out.steps = run.loop, run, closed_loop_steps(models, run, names)
    if out.result is None and run.loop.rounds:
        out.result = run.loop.rounds[0]
    print_steps(out.steps, blank_line=True)
    _print_loop_summary(out, cfg)
    print_cause(out.outcome, dynamics_errors(models, run.loop.states, run.loop.executed, worst=True),
                stop_record(run.loop.stop, run.loop.rounds[-1] if run.loop.rounds else None), None,
                indent="  ")
    if timeline is not None:
        timeline.caption = [f"tamp demo --seed {cfg.seed}: {problem.n} blocks, goal from {problem.k} random "
                            f"actions, closed loop", _verdict(out)]
        timeline.show_goal(problem.X_goal)
        assert cfg.replay is not None  # the timeline exists for it
        _write_steps(timeline, out, cfg, names)
        path = timeline.write_html(cfg.replay)
        out.replays.append(path)
        print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB): open it in a browser", flush=True)


def _open_loop_episode(out: DemoResult, models, names, plan_cfg: PlanConfig, kinematics: FeasibilityChecker | None,
                       cfg: DemoConfig, timeline: Timeline | None) -> None:
    """Refine and execute the one plan (if any), then the steps, the summary and the replay."""
    problem, result = out.problem, out.result
    assert result is not None  # open loop: planned before
    if result.solved:
        assert result.plan is not None  # solved
        what = "the arm under physics" if cfg.fidelity == "full" else "the fast world"
        print(f"\nrefining and executing {len(result.plan)} action(s) with {what}:", flush=True)
        out.execution = run_episode("bilevel", models, problem.X_init, problem.X_goal, plan_cfg, cfg.fidelity,
                                    first=result, timeline=timeline).execution
        assert out.execution is not None  # a plan to execute
        _print_execution(out.execution, result.plan, result.predicted, problem.X_goal, cfg.fidelity)
        out.steps = open_loop_steps(models, result, problem.X_init, out.execution, names,
                                    timeline.action_starts if timeline is not None else ())
        print_steps(out.steps, blank_line=True)
    elif timeline is not None:  # show the problem: the initial scene and the goal
        from tamp.sim import World

        world = World(WorldConfig())
        world.observer = timeline
        world.reset(X=problem.X_init)
    _print_summary(out, cfg)
    if timeline is not None:
        assert cfg.replay is not None  # the timeline exists for it
        timeline.caption = [f"tamp demo --seed {cfg.seed}: {problem.n} blocks, goal from {problem.k} random actions",
                            _verdict(out)]
        _write_steps(timeline, out, cfg, names)
        _write_replay(timeline, problem.X_goal, None if out.execution is None else result.predicted, cfg.replay, out)


def _source(cfg: DemoConfig) -> str:
    """The command line of a demo, as a trajectory file records it."""
    return (f"tamp demo --seed {cfg.seed} --objects {cfg.objects} --actions {cfg.actions} --fidelity {cfg.fidelity}"
            + ("" if cfg.replan else " --open-loop") + ("" if cfg.models is None else f" --models {cfg.models}"))


def _record(cfg: DemoConfig) -> dict:
    """The configuration the demo planned with, as its outputs record it."""
    return settings_record(Settings(planner=cfg.planner.with_seed(cfg.seed), perception=cfg.perception))


def _write_steps(timeline: Timeline, out: DemoResult, cfg: DemoConfig, names) -> None:
    """The steps as JSON beside the replay, and the replay's step panel."""
    if not out.steps or cfg.replay is None:
        return
    level = None if out.result is None else out.result.level
    path = write_steps(steps_path(cfg.replay), steps_document(f"tamp demo --seed {cfg.seed}", "bilevel",
                                                               level, out.steps, names, _record(cfg)))
    timeline.show_panel(panel_entries(out.steps, timeline.t_end))
    print(f"steps written to {path}")


def _write_replay(timeline: Timeline, X_goal, predicted, path: Path, out: DemoResult) -> None:
    timeline.show_goal(X_goal)
    if predicted is not None:
        timeline.show_predictions(predicted)
    path = timeline.write_html(path)
    out.replays.append(path)
    print(f"replay written to {path} ({path.stat().st_size / 1e6:.1f} MB): open it in a browser", flush=True)


def _replay_candidates(out: DemoResult, models, cfg: DemoConfig) -> None:
    """Execute the first `cfg.candidates` candidates that failed verification, one replay each."""
    assert cfg.replay is not None  # candidates need a replay path (checked in demo())
    if out.result is None:
        print("\nno first plan; no candidate replays")
        return
    problem, rejected = out.problem, [(i, c) for i, c in enumerate(out.result.candidates, 1) if c.verified is False]
    if not rejected:
        print("\nno symbolic candidate failed verification; no candidate replays")
        return
    shown = rejected[:cfg.candidates]
    print(f"\nreplaying {len(shown)} of the {len(rejected)} candidate(s) that failed verification "
          f"(numbers as in the list above):", flush=True)
    for rank, c in shown:
        assert c.error is not None  # verified (and rejected): its error is known
        actions = [PickPlace(*a) for a in c.actions]
        predicted = rollout(models.require_dynamics(), problem.X_init, c.actions)
        timeline = Timeline()
        ex = execute_plan(actions, problem.X_init, problem.X_goal, cfg.fidelity, timeline=timeline)
        ran = f"all {len(actions)} action(s)" if ex.refined.success else \
            f"{len(ex.refined.steps)} of {len(actions)} action(s), refinement failed: {ex.refined.failure}"
        if not ex.refined.success:
            verdict = "it could not be carried out"
        elif ex.error < out.eps:
            verdict = "it reached the goal: verification rejected a plan that works"
        else:
            verdict = "it missed the goal, as verification predicted"
        print(f"  candidate {rank} {list(c.actions)}: predicted {c.error * 100:.1f} cm from the goal; "
              f"executed {ran}; final error {ex.error * 100:.1f} cm: {verdict}")
        timeline.caption = [f"tamp demo --seed {cfg.seed}: candidate {rank}, rejected by verification "
                            f"(predicted {c.error * 100:.1f} cm from the goal)",
                            f"executed: final error {ex.error * 100:.1f} cm"]
        path = cfg.replay.with_name(f"{cfg.replay.stem}.candidate{rank}{cfg.replay.suffix}")
        _write_replay(timeline, problem.X_goal, predicted, path, out)


def _print_problem(problem: Problem, models_dir: Path) -> None:
    print(f"problem (seed {problem.seed}): {problem.n} blocks; the goal is where {problem.k} random actions "
          f"took them ({', '.join(str(tuple(a)) for a in problem.actions)}); initial error "
          f"{goal_error(problem.X_init, problem.X_goal) * 100:.1f} cm")
    for i, (x, g) in enumerate(zip(problem.X_init, problem.X_goal)):
        kind = TYPE_NAMES[int(np.argmax(x[3:]))]
        print(f"  block {i} ({kind:5s}): ({x[0]:.3f}, {x[1]:.3f}, {x[2]:.3f}) m -> goal "
              f"({g[0]:.3f}, {g[1]:.3f}, {g[2]:.3f}) m, {np.linalg.norm(g[:3] - x[:3]) * 100:.1f} cm away")
    print(f"models: {models_dir}")


def _print_execution(ex: Execution, actions, predicted, X_goal, fidelity: str) -> None:
    r = ex.refined
    if r.success:
        print(f"  refinement: ok, {len(r.steps)} action(s) in {ex.refine_time:.2f} s, "
              f"{sum(s.duration for s in r.steps):.1f} s of arm motion")
    else:
        print(f"  refinement: failed: {r.failure}; executing the {len(r.steps)} action(s) before it")
    for k, X in enumerate(ex.X_after):
        off = goal_errors(X, predicted[k + 1]).max()
        print(f"  action {k} ({fmt_action(actions[k])}): blocks within {off * 100:.1f} cm of the Dynamics "
              f"Model's prediction, {goal_error(X, X_goal) * 100:.1f} cm from the goal")
    for note in ex.notes:
        print(f"  {note}")
    if fidelity == "full":
        print(f"  execution (full): {ex.sim_time:.1f} s simulated in {ex.execute_time:.1f} s")


def _verdict(out: DemoResult) -> str:
    if out.loop is not None:
        met = "success" if out.loop.success else "goal missed"
        return (f"{len(out.loop.executed)} action(s) in {len(out.loop.rounds)} round(s); final error "
                f"{out.loop.error * 100:.1f} cm (eps {out.eps * 100:g} cm): {met}")
    ex = out.execution
    if ex is None:
        return "no plan: " + "; ".join(out.result.reasons if out.result is not None else [])
    if not ex.refined.success:
        return f"refinement failed at {ex.refined.failure}"
    met = "success" if ex.error < out.eps else "goal missed"
    return f"final error {ex.error * 100:.1f} cm (eps {out.eps * 100:g} cm): {met}"


def _print_summary(out: DemoResult, cfg: DemoConfig) -> None:
    result, ex = out.result, out.execution
    assert result is not None  # open loop: planned before
    print(f"\nsummary (seed {cfg.seed}, {cfg.fidelity} execution):")
    if result.solved:
        assert result.plan is not None and result.level is not None and result.predicted_error is not None  # solved
        print(f"  plan        {len(result.plan)} action(s) from {LEVELS[result.level]}; predicted error "
              f"{result.predicted_error * 100:.1f} cm")
        for reason in result.reasons:  # why Level 1 did not give the plan
            print(f"              {reason}")
    else:
        print(f"  plan        none: {'; '.join(result.reasons)}")
    times = f"  times       planning {result.timings['total']:.2f} s"
    if ex is not None:
        times += f", refinement {ex.refine_time:.2f} s"
        times += f", execution {ex.execute_time:.1f} s" if cfg.fidelity == "full" else \
            " (execution: the refinement world's, included)"
    print(times)
    if ex is not None:
        print(f"  final error {ex.error * 100:.1f} cm (max over blocks; eps {out.eps * 100:g} cm)")
    not_refined = f"failure: the plan could not be refined into arm motions ({ex.refined.failure if ex else ''})"
    outcome = {Outcome.SUCCESS: "success: every block within eps of its goal",
               Outcome.NO_PLAN: "failure: the planner found no plan",
               Outcome.KINEMATIC_FAILURE: not_refined, Outcome.REFINEMENT_FAILURE: not_refined,
               Outcome.WRONG_PLAN: "failure: the plan was executed but missed the goal"}[out.outcome]
    print(f"  outcome     {outcome}", flush=True)


def _closed_loop(problem: Problem, models, plan_cfg: PlanConfig, kinematics: FeasibilityChecker | None,
                 cfg: DemoConfig, first: PlanResult | None, timeline: Timeline | None,
                 step_times: list[tuple[float, float]], search: SearchRecording | None = None) -> ClosedLoopRun:
    """Execute the first action of the plan, observe the scene, plan again from it until the goal is
    reached or the loop's action budget is spent (a round keeps the rest of the last plan while it is
    on course, and widens its search when it finds no plan), in a World of the demo's fidelity: each
    action is refined and executed there, an action that cannot be refined changes nothing and the
    loop goes on. The first round reuses the plan already printed (`first`; None: it plans). The replay shows
    each round's prediction of the action it executed, and with the cameras what they saw."""
    cameras = rig_for(cfg.perception)
    observing = f"observing through {len(cfg.perception.cameras())} cameras" if cameras is not None else \
        "observing the simulator's truth"
    print(f"\nclosed loop ({cfg.fidelity} world, {observing}): execute, observe, plan again until the goal; at "
          f"most {plan_cfg.loop.max_actions} actions", flush=True)
    planned: list[tuple[int, PlanResult]] = []  # (index of the round's first executed action, result)
    executed: list[PickPlace] = []

    def plan_round(method, models_, X, X_goal, config, **kinematics):
        return first if not planned and first is not None else plan(method, models_, X, X_goal, config, **kinematics)

    def on_round(r: int, result: PlanResult) -> None:  # every round, planned anew or kept
        planned.append((len(executed), result))
        if search is not None:
            search.planned(result)
        if r > 0 or first is None:
            how = "kept the rest of the last plan" if result.kept else \
                "searched over every action from the observed scene" if result.widened else \
                "replanned from the observed scene"
            print(f"round {r}: {how}", flush=True)
            print_result(result, plan_cfg.verify.tau_verify, indent="  ")

    def show_step(action: PickPlace, X: np.ndarray, info, seconds: float) -> None:
        executed.append(action)
        if search is not None:
            search.executed(action, X)
        why = f" ({info.reason})" if info.status != "ok" and info.reason else ""
        print(f"  executed {fmt_action(action)}: {info.status}{why}; blocks {goal_error(X, problem.X_goal) * 100:.1f} "
              f"cm from the goal, {seconds:.1f} s", flush=True)

    run = run_episode("bilevel", models, problem.X_init, problem.X_goal, plan_cfg, cfg.fidelity, closed_loop=True,
                      kinematics=kinematics, timeline=timeline, planner=plan_round, on_round=on_round,
                      on_step=show_step, cameras=cameras, on_seen=print_seen).run
    assert run is not None  # a closed loop
    step_times.extend(run.step_times)
    if timeline is not None:
        _show_loop_predictions(timeline, planned, run.action_starts)
    return run


def _show_loop_predictions(timeline: Timeline, planned: list[tuple[int, PlanResult]],
                           starts: list[float | None]) -> None:
    """Ghosts of each round's predictions, each from the replay time its action started (actions that
    never moved the arm, e.g. not refinable, have no start and no ghost)."""
    from tamp.sim.replay import PREDICTED_RGBA, Ghosts

    states, times = [], []
    for r, (first, result) in enumerate(planned):
        end = planned[r + 1][0] if r + 1 < len(planned) else len(starts)
        for i in range(end - first):
            start = starts[first + i]
            if result.predicted is not None and i + 1 < len(result.predicted) and start is not None:
                states.append(result.predicted[i + 1])
                times.append(start)
    if states:
        timeline.ghosts.append(Ghosts("predicted", np.stack(states), times, PREDICTED_RGBA,
                                      "Dynamics Model's prediction after the current action"))


def _round_summary(r: PlanResult) -> str:
    if r.level is None:
        return "no plan"
    assert r.predicted_error is not None  # solved
    return f"level {r.level} (predicted {r.predicted_error * 100:.1f} cm from the goal)"


def _print_loop_summary(out: DemoResult, cfg: DemoConfig) -> None:
    loop = out.loop
    assert loop is not None  # closed loop: set before the summary
    print(f"\nsummary (seed {cfg.seed}, {cfg.fidelity} execution, closed loop):")
    levels = ", ".join(_round_summary(r) for r in loop.rounds)
    print(f"  plans       {len(loop.rounds)} round(s): {levels}; {len(loop.executed)} action(s) executed")
    for a in loop.executed:
        print(f"              {fmt_action(a)}")
    print(f"  ended       {loop.reason}")
    planning = sum(r.timings.get("total", 0.0) for r in loop.rounds)
    refine, execute = (sum(t[i] for t in out.step_times) for i in (0, 1))
    times = f"  times       planning {planning:.2f} s (all rounds), refinement {refine:.2f} s"
    print(times + (f", execution {execute:.1f} s" if cfg.fidelity == "full" else
                   " (execution: the refinement world's, included)"))
    run = out.loop_run
    assert run is not None  # set with the loop
    print(f"  final error {run.error * 100:.1f} cm (max over blocks; eps {out.eps * 100:g} cm)"
          + ("" if run.perception_record() is None else f"; as the cameras saw it {loop.error * 100:.1f} cm"))
    print_perception(run, indent="  ")
    outcome = {Outcome.SUCCESS: "success: every block within eps of its goal",
               Outcome.NO_PLAN: "failure: the planner found no plan",
               Outcome.WRONG_PLAN: f"failure: the goal was not reached ({loop.reason})"}[out.outcome]
    print(f"  outcome     {outcome}", flush=True)
