"""The two ways a plan meets the world, one implementation each, used by `tamp demo`, `tamp plan`
and `tamp evaluate`:

- open loop (`execute_plan`): refine the whole plan from the initial scene (IK, OMPL motions,
  grasps, in a `fast` World), then execute the refined actions: `fast` takes the refinement's own
  outcome, `full` runs the time-parameterized trajectory with the arm under physics. Actions before
  a refinement failure run, none after it.
- closed loop (`run_closed_loop`): in a World of the chosen fidelity, execute the first action of
  each plan, observe the scene and plan again (`tamp.planning.closed_loop.plan_closed_loop`: until the
  goal or the loop's action budget, or the paper's k - 1 rounds); an action that cannot be refined
  changes nothing and the loop goes on from the observed scene.

Both take an optional `Timeline` to record a replay, and a `World` to reuse (its Drake plants are
cached per block layout); the planners see the simulator only through `kinematics_for`. `run_episode` is
the one entry of the three commands: a problem run either way, returned as an `Episode`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from tamp.app.faults import Faults, push
from tamp.app.observation import MARGIN_OF_EPS, CameraObserver, Observed, TruthObserver
from tamp.planning.closed_loop import ClosedLoopResult, loop_outcome, plan_closed_loop
from tamp.planning.config import PlanConfig
from tamp.planning.models import Models
from tamp.planning.planners import METHODS, plan
from tamp.planning.results import PlanResult
from tamp.planning.verify import goal_error, rollout
from tamp.planning.vocabulary import Outcome, PickPlace
from tamp.sim import World, WorldConfig
from tamp.sim.execute import execute
from tamp.sim.kinematic_checker import FeasibilityChecker
from tamp.sim.refine import FAILURE_STAGES, failed_at, refine
from tamp.sim.replay import Timeline
from tamp.sim.skill import Scene
from tamp.sim.trajectory import FailureStage, RefinedPlan, RefinementFailure, refined_action
from tamp.sim.trajectory_file import PlanTrajectory, TrajectoryError, action_motion
from tamp.sim.world_types import StepInfo, StepStatus, fidelity_of

if TYPE_CHECKING:  # the rig loads VTK: built by the commands that observe through it
    from tamp.sim.cameras import CameraRig


def kinematics_for(method: str, config: PlanConfig) -> FeasibilityChecker | None:
    """The kinematic feasibility checker a planning call uses: one for the methods that put
    kinematics in the planning loop (`Planner.kinematic`) when `config.kinematics.feasibility`, else None."""
    if not (config.kinematics.feasibility and METHODS[method].kinematic):
        return None
    return FeasibilityChecker()


def executing_world(fidelity: str = "fast") -> World:
    """A World for executed plans: paths simplified (they are run, not just checked)."""
    fidelity_of(fidelity)
    return World(WorldConfig(fidelity=fidelity, simplify_paths=True))


@dataclass
class Execution:
    """A plan refined and executed from X_init: outcome and times (seconds)."""

    refined: RefinedPlan
    X_after: list[np.ndarray]  # executed state after each action that ran
    X_final: np.ndarray  # after the executed actions (X_init when none ran)
    error: float  # metres: max per-object distance of X_final to the goal
    refine_time: float
    execute_time: float  # wall clock; 0 in the fast world, where refinement already executed the plan
    sim_time: float  # simulated seconds of execution (arm motion and settling); fast: arm motion alone
    notes: list[str] = field(default_factory=list)  # per-action remarks of the executor (missed grasps)
    fidelity: str = "fast"  # the world that executed it

    @property
    def success(self) -> bool:
        """Every action refined (the goal test is the caller's: it knows eps)."""
        return self.refined.success


def execute_plan(actions: Sequence[PickPlace | Sequence[int]], X_init: np.ndarray, X_goal: np.ndarray,
                 fidelity: str = "fast", *, world: World | None = None,
                 timeline: Timeline | None = None) -> Execution:
    """Refine `actions` from X_init and execute them (see the module docstring). `world`: a `fast`
    World to refine in (default: a new one); it is left at the refined actions' outcome."""
    fidelity_of(fidelity)
    world = world or executing_world("fast")
    world.observer = timeline if fidelity == "fast" else None
    refined = refine([PickPlace(*a) for a in actions], X_init, world=world)
    world.observer = None
    if fidelity == "fast":
        X_after = [s.X_after for s in refined.steps]
        X_final, execute_time, notes = refined.X_predicted, 0.0, []
        sim_time = sum(s.duration for s in refined.steps)
    else:
        t = time.perf_counter()
        executed = execute(refined, observer=timeline, partial=True)
        execute_time = time.perf_counter() - t
        X_after = [a.X_after for a in executed.log]
        X_final, sim_time = executed.X_final, executed.sim_time
        notes = [f"action {a.index}: {a.note}" for a in executed.log if a.note]
    if not refined.steps:  # nothing ran: the scene as given
        X_final = np.asarray(X_init, dtype=float)
    if timeline is not None and not timeline.times:  # nothing ran: show the initial scene
        timeline.scene_started(refined.scene_init, refined.q_init)
    return Execution(refined, X_after, X_final, goal_error(X_final, X_goal), refined.refine_time,
                     execute_time, sim_time, notes, fidelity)


@dataclass
class ClosedLoopRun:
    """A closed loop and what each executed action did in the world."""

    loop: ClosedLoopResult
    infos: list[StepInfo] = field(default_factory=list)  # per executed action
    step_times: list[tuple[float, float]] = field(default_factory=list)  # (refine, execute) wall s per action
    # replay time each action began (None: the arm never moved)
    action_starts: list[float | None] = field(default_factory=list)
    scene_init: Scene | None = None  # the world's exact scene and arm joints before the first action
    q_init: np.ndarray | None = None
    # the world's state after each executed action (loop.states: as observed, with `faults` noise and all)
    X_after: list[np.ndarray] = field(default_factory=list)
    fidelity: str = "fast"  # the world that executed the actions
    faults: list[str] = field(default_factory=list)  # the faults injected (`Faults`), in words
    observations: list[Observed] = field(default_factory=list)  # what the loop observed, in order
    sigma_m: float | None = None  # with the cameras: the perception's error the loop learned (metres, per x or y)

    def perception_record(self) -> dict | None:
        """With the cameras: what the loop observed, for a row (None: it observed the truth)."""
        if self.sigma_m is None and not any(o.scene is not None for o in self.observations):
            return None
        errors = [e for o in self.observations for e in o.errors_m]
        said = [s for o in self.observations for s in o.said]
        return {"observations": len(self.observations), "looks": sum(o.looks for o in self.observations),
                "said": said[:10], "failures": sum(1 for o in self.observations if o.said),
                "sigma_m": self.sigma_m, "error_median_m": float(np.median(errors)) if errors else None,
                "error_max_m": max(errors, default=None)}

    @property
    def X_final(self) -> np.ndarray:
        """The world's final state (with observation noise, the loop saw it otherwise)."""
        if self.X_after:
            return self.X_after[-1]
        return self.scene_init.X() if self.scene_init is not None else self.loop.states[0]

    @property
    def error(self) -> float:
        """Metres: max per-object distance of the world's final state to the goal."""
        return goal_error(self.X_final, self.loop.X_goal)

    @property
    def first_failure(self) -> RefinementFailure | None:
        """The first executed action the world could not carry out (IK, motion or grasp)."""
        for index, (action, info) in enumerate(zip(self.loop.executed, self.infos)):
            if info.status != StepStatus.OK:
                return RefinementFailure(index, PickPlace(*action),
                                         FAILURE_STAGES.get(info.status, FailureStage.MOTION), failed_at(info),
                                         info.reason)
        return None


@dataclass
class Episode:
    """A problem's first plan and how it met the world: open loop (`execution`; None when no plan was
    executed) or closed loop (`run`). `tamp plan` and `tamp demo` report it; its outcome is counted as
    `tamp evaluate` counts a row's."""

    first: PlanResult | None  # the first planning call (closed loop: its first round; None: no round ran)
    eps: float  # metres: the success tolerance
    execution: Execution | None = None
    run: ClosedLoopRun | None = None

    @property
    def outcome(self) -> Outcome | None:
        """Success, no plan, a kinematic or refinement failure or a wrong plan (closed loop: judged by where it
        ended); None for a plan that was not executed (planning only, or an empty plan)."""
        if self.run is not None:  # where the world ended (with observation noise the loop saw it otherwise)
            return loop_outcome(self.run.loop, self.run.error)
        if self.first is None or not self.first.solved:
            return Outcome.NO_PLAN
        if self.execution is None:
            return None
        failure = self.execution.refined.failure
        return Outcome.of(True, None if failure is None else failure.stage, self.execution.error, self.eps)

    @property
    def motion(self) -> Execution | ClosedLoopRun | None:
        """What moved the arm, for the trajectory file (`executed_trajectory`)."""
        return self.run if self.run is not None else self.execution


StepCallback = Callable[[PickPlace, np.ndarray, StepInfo, float], None]  # (action, X observed, info, wall s)


def run_closed_loop(method: str, models: Models, X_init: np.ndarray, X_goal: np.ndarray, rounds: int | None,
                    config: PlanConfig, fidelity: str = "fast", *, world: World | None = None,
                    kinematics: FeasibilityChecker | None = None, timeline: Timeline | None = None,
                    planner: Callable[..., PlanResult] | None = None,
                    on_round: Callable[[int, PlanResult], None] | None = None,
                    on_step: StepCallback | None = None, faults: Faults | None = None,
                    fault_seed: int = 0, cameras: CameraRig | None = None,
                    on_seen: Callable[[Observed], None] | None = None) -> ClosedLoopRun:
    """Plan, execute the first action in a World of `fidelity`, observe, plan again: until the goal or
    config.loop's action budget (`rounds` None), or the paper's `rounds` replanning rounds (the last
    plan runs to its end). `planner` and `on_round` are passed to `plan_closed_loop`, `on_step` is called after
    every executed action, `on_seen` after every observation. The loop observes the truth (`faults` disturb the
    world and the observations, `tamp.app.faults`, drawn from `fault_seed`), or with `cameras` the blocks the rig
    perceives (`tamp.app.observation.CameraObserver`): then the planner, `kinematics` and the skill take the
    perceived poses, and the loop stops the perception's learned error inside eps (when config.loop leaves
    stop_margin to it)."""
    world = world or executing_world(fidelity)
    world.observer = timeline
    world.reset(X=X_init)
    assert world.scene is not None  # reset above
    scene_init, q_init = world.scene, world.q.copy()
    X_after: list[np.ndarray] = []
    infos: list[StepInfo] = []
    step_times: list[tuple[float, float]] = []
    action_starts: list[float | None] = []
    rng = np.random.default_rng(fault_seed)
    injected: list[str] = []
    predict = None if models.dynamics is None else \
        (lambda X, action: rollout(models.require_dynamics(), X, [action])[-1])
    observer: TruthObserver | CameraObserver = TruthObserver(faults, rng) if cameras is None else \
        CameraObserver(cameras, rng, X_init, predict, timeline)
    seen = observer.first(world.scene)

    def observed(now: Observed) -> np.ndarray:  # the observation, to whoever plans from it
        nonlocal seen
        seen = now
        if kinematics is not None:
            kinematics.observe(now.scene or world.scene, world.q)
        if on_seen is not None:
            on_seen(now)
        return now.X

    def step(action: PickPlace) -> np.ndarray:
        t, marks = time.perf_counter(), len(timeline.action_starts) if timeline is not None else 0
        X, info = world.step(action, seen=seen.scene)
        seconds = time.perf_counter() - t
        if faults is not None and faults.push_m is not None and len(infos) == 0:  # the one push, after action 1
            scene, note = push(world.scene, faults, rng)
            world.set_scene(scene, world.q)
            X = world.X
            injected.append(note)
        X_after.append(X)
        started = timeline is not None and len(timeline.action_starts) > marks  # it moved the arm
        action_starts.append(timeline.action_starts[marks] if timeline is not None and started else None)
        execute = info.timings.get("execute", 0.0)  # full fidelity; the fast world's step is all refinement
        step_times.append((seconds - execute, execute))
        infos.append(info)
        X = observed(observer.after(world.scene, action))
        if on_step is not None:
            on_step(action, X, info, seconds)
        return X

    def look() -> np.ndarray:  # the scene observed again, without acting (with new noise)
        assert world.scene is not None  # reset above
        return observed(observer.again(world.scene))

    if faults is not None and faults.noise_m > 0:
        injected.append(faults.noise_words)
    learned = cameras is not None and config.loop.stop_margin is None  # the loop learns its margin from the cameras
    margin = (lambda: min(observer.stop_margin(), MARGIN_OF_EPS * config.verify.eps)) if learned else None
    try:
        X0 = observed(seen)
        loop = plan_closed_loop(method, models, X0, X_goal, step, rounds, config, on_round=on_round,
                                planner=planner, kinematics=kinematics, look=look, margin=margin)
    finally:
        world.observer = None
    return ClosedLoopRun(loop, infos, step_times, action_starts, scene_init, q_init, X_after, world.config.fidelity,
                         injected, observer.observations, getattr(observer, "sigma_m", None))


def run_episode(method: str, models: Models, X_init: np.ndarray, X_goal: np.ndarray, config: PlanConfig,
                fidelity: str = "fast", *, closed_loop: bool = False, rounds: int | None = None,
                first: PlanResult | None = None, world: World | None = None,
                kinematics: FeasibilityChecker | None = None, timeline: Timeline | None = None,
                planner: Callable[..., PlanResult] | None = None,
                on_round: Callable[[int, PlanResult], None] | None = None, on_step: StepCallback | None = None,
                faults: Faults | None = None, fault_seed: int = 0, cameras: CameraRig | None = None,
                on_seen: Callable[[Observed], None] | None = None) -> Episode:
    """One problem run the one way `tamp plan`, `tamp demo` and `tamp evaluate` run it. Closed loop
    (`run_closed_loop`; `rounds` None: until the goal, else the paper's rounds; `planner`, `on_round`,
    `on_step`, `faults`, `cameras`, `on_seen` as there), or open loop: the plan (`first`, else planned now with
    `kinematics`) refined and executed in a World of `fidelity` (`execute_plan`; `world`: the fast world to refine
    in) when there is one."""
    if closed_loop:
        run = run_closed_loop(method, models, X_init, X_goal, rounds, config, fidelity, world=world,
                              kinematics=kinematics, timeline=timeline, planner=planner, on_round=on_round,
                              on_step=on_step, faults=faults, fault_seed=fault_seed, cameras=cameras,
                              on_seen=on_seen)
        return Episode(run.loop.rounds[0] if run.loop.rounds else None, config.verify.eps, run=run)
    result = first if first is not None else plan(method, models, X_init, X_goal, config, kinematics=kinematics)
    if not result.solved:
        return Episode(result, config.verify.eps)
    assert result.plan is not None  # solved
    execution = execute_plan(result.plan, X_init, X_goal, fidelity, world=world, timeline=timeline)
    return Episode(result, config.verify.eps, execution=execution)


def executed_trajectory(run: Execution | ClosedLoopRun, source: str = "", configuration: dict | None = None
                        ) -> PlanTrajectory:
    """The motion a run executed, action by action in order, from its exact initial scene, as the
    trajectory file holds it (`tamp.sim.trajectory_file.write_trajectory` writes it). Open loop:
    the refined actions that ran. Closed loop: each executed action's refined trajectory (rebuilt
    from the paths its world planned, as the world timed them); actions that moved nothing are
    listed as skipped. TrajectoryError if the arm was put home without a motion (the fast world,
    when the retreat after a release was blocked): that run is not one continuous trajectory."""
    if isinstance(run, Execution):
        steps = run.refined.steps[:len(run.X_after)]
        motions = [action_motion(k, step, X) for k, (step, X) in enumerate(zip(steps, run.X_after))]
        return PlanTrajectory(run.refined.scene_init, run.refined.q_init, motions, run.fidelity, source,
                              configuration=configuration or {})
    assert run.scene_init is not None and run.q_init is not None  # set by run_closed_loop
    motions, skipped = [], []
    X_before = run.scene_init.X()
    for k, (info, X) in enumerate(zip(run.infos, run.X_after)):
        if info.status != StepStatus.OK:
            skipped.append({"index": k, "action": list(map(int, info.action)), "reason": info.reason})
        elif "retreat" not in info.paths:
            raise TrajectoryError(f"executed action {k}: {info.reason}; the arm was put home without a motion, "
                                  "so the run is not one continuous trajectory (no trajectory written)")
        else:
            step = refined_action(info.action, info, X_before, X, info.paths["approach"][0])
            motions.append(action_motion(k, step, X))
        X_before = X
    return PlanTrajectory(run.scene_init, run.q_init, motions, run.fidelity, source, skipped,
                          configuration=configuration or {})
