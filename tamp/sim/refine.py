"""Refinement: a plan of pick-place actions -> IK configurations, collision-free paths and one
time-parameterized joint trajectory, following the scene as it evolves.

Each action is planned by the `fast` world from the scene the previous actions left (their outcome
simulated there), with OMPL paths simplified because they will be executed. Refinement stops at the
first action that cannot be refined and says which action, which waypoint or motion, and why; a
failed plan never carries a whole-plan trajectory.
"""
from __future__ import annotations

import dataclasses
import time
from typing import Iterable

import numpy as np

from tamp.planning.validate import check_scene
from tamp.planning.vocabulary import PickPlace
from tamp.sim.skill import Scene
from tamp.sim.trajectory import FailureStage, RefinedPlan, RefinementFailure, concatenate, refined_action
from tamp.sim.world import World, validate_action
from tamp.sim.world_types import StepInfo, StepStatus, WorldConfig

FAILURE_STAGES = {  # StepInfo.status of a failed action -> refinement stage
    StepStatus.IK_FAILURE: FailureStage.IK, StepStatus.MOTION_FAILURE: FailureStage.MOTION,
    StepStatus.NOTHING_GRASPED: FailureStage.GRASP}


def refine(
    plan: Iterable[PickPlace | Iterable[int]],
    X_init: np.ndarray | None = None,
    *,
    scene: Scene | None = None,
    q_start: np.ndarray | None = None,
    config: WorldConfig | None = None,
    world: World | None = None,
) -> RefinedPlan:
    """Refine `plan` from X_init (blocks upright) or from an exact `scene` and arm configuration.

    `world` (a `fast` World, ideally with `simplify_paths=True`) may be given to reuse its cached
    Drake plants; it is left at the predicted final scene.
    """
    if (X_init is None) == (scene is None):
        raise ValueError("refine takes exactly one of X_init or scene")
    if world is None:
        world = World(dataclasses.replace(config or WorldConfig(), fidelity="fast", simplify_paths=True))
    if scene is None:
        # the scene the world can hold; a block out of reach is the IK failure of the action picking it
        assert X_init is not None  # exactly one of X_init and scene (checked above)
        check_scene(X_init, where="refine()", field="X_init", upright=True, within_reach=False)
        world.reset(X=X_init)
    else:
        world.set_scene(scene, world.q if q_start is None else q_start)
    if q_start is not None:
        world.q = np.array(q_start, dtype=float)
    assert world.scene is not None  # reset or set_scene above
    actions = [validate_action(a, world.scene.n) for a in plan]
    result = RefinedPlan(X_init=world.X, actions=actions, scene_init=world.scene, q_init=world.q.copy())
    t_plan = time.perf_counter()
    for k, action in enumerate(actions):
        t0 = time.perf_counter()
        X_before, q_before = world.X, world.q.copy()
        X_after, info = world.step(action)
        result.infos.append(info)
        failure = step_failure(info)
        if failure is not None:
            result.failure = RefinementFailure(k, action, *failure)
            break
        step = refined_action(action, info, X_before, X_after, q_before)
        step.refine_time = time.perf_counter() - t0
        result.steps.append(step)
    result.refine_time = time.perf_counter() - t_plan
    if result.success and result.steps:
        result.trajectory, result.start_times = concatenate(result.steps)
    return result


def step_failure(info: StepInfo) -> tuple[FailureStage, str, str] | None:
    """(stage, where, reason) of an action that did not refine (its StepInfo), or None if it did:
    every IK and motion found, the block grasped and the retreat after release free."""
    if info.status == StepStatus.OK and info.motion_success.get("retreat", False):
        return None
    return (FAILURE_STAGES.get(info.status, FailureStage.MOTION), failed_at(info),
            info.reason or "the retreat after release was blocked")


def failed_at(info: StepInfo) -> str:
    """The first waypoint (IK) or motion of a failed action, or "grasp" / "retreat"."""
    for name, ok in list(info.ik_success.items()) + list(info.motion_success.items()):
        if not ok:
            return name
    return "grasp" if info.status == StepStatus.NOTHING_GRASPED else "retreat"
