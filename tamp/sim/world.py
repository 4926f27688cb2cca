"""The block world: a UR10e on a table with 2-4 blocks and a pick-place skill that really happens.

`World.step` plans the whole action before anything moves: IK for every waypoint, then OMPL
motions checked against the scene (the grasped block attached while carried); only a fully planned
action is executed. In the `fast` fidelity the grasped block follows the gripper kinematically and
physics runs from release until every block is at rest. In the `full` fidelity the same plan is
time-parameterized and the arm follows it under Drake physics (tamp/sim/execute.py); the `fast` outcome
is kept in `info.X_predicted`. An action that is kinematically impossible or closes the jaws on
nothing changes nothing, and `StepInfo` says why. What happens is reported to the world's
`observer` (tamp/sim/observer.py), e.g. a replay's Timeline.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Iterable

import numpy as np
from pydrake.math import RigidTransform

from tamp.errors import UserError
from tamp.planning.validate import MAX_OBJECTS, check_scene
from tamp.planning.vocabulary import BLOCK_SIZES, LARGE, OFFSETS, SMALL, PickPlace
from tamp.sim.execute import Executor
from tamp.sim.kinematics import Q_HOME, drake_ik, solve_chain
from tamp.sim.motion import MotionPlanner
from tamp.sim.observer import Carried, PhysicsFrame, WorldObserver
from tamp.sim.physics import BlockPhysics
from tamp.sim.plants import build_motion_scene, build_physics_scene
from tamp.sim.skill import (
    Scene,
    Waypoints,
    approach_poses,
    carried_shapes,
    grasp_pose,
    held_block,
    pick_place_waypoints,
    topdown,
)
from tamp.sim.trajectory import RefinedPlan, refined_action
from tamp.sim.world_types import StepInfo, StepStatus, WorldConfig

MOTIONS = ("approach", "descend", "liftoff", "lift", "transfer", "lower", "retreat")
LAYOUT_ATTEMPTS = 20  # random layouts tried before a crowded scene is refused (8 bars rarely fit the workspace)


@dataclass
class MotionSeeds:
    """RRTConnect's seeds: a function of the scene's seed, the step and the motion only, so that a
    scene's motions do not depend on what was planned before it."""

    scene: int = 0
    step: int = 0  # actions planned in this scene

    def restart(self, scene_seed: int) -> None:
        self.scene, self.step = int(scene_seed), 0

    def of(self, motion: str) -> int:
        return (self.scene * 1_000_003 + self.step * 16 + MOTIONS.index(motion)) % (2**31 - 1)


class World:
    """Random or given block scenes and the pick-place skill on them.

    `observer` is told what happens (scenes, actions, motions, physics frames); `motion_seeds`,
    when given, is shared with the world that owns it (the full fidelity's predicting world)."""

    def __init__(self, config: WorldConfig | None = None, seed: int = 0, *,
                 observer: WorldObserver | None = None, motion_seeds: MotionSeeds | None = None) -> None:
        self.config = config or WorldConfig()
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.q = Q_HOME.copy()
        self.scene: Scene | None = None
        self.observer = observer
        self.motion_seeds = motion_seeds if motion_seeds is not None else MotionSeeds()
        self._layouts: dict[tuple[int, ...], tuple[MotionPlanner, BlockPhysics]] = {}
        # The full fidelity plans and predicts each action with a fast world (executed paths
        # simplified) that shares its motion seeds, then executes it under physics with an
        # executor built once per block layout.
        self._predictor: World | None = None
        self._executors: dict[tuple[int, ...], Executor] = {}
        if self.config.fidelity == "full":
            self._predictor = World(dataclasses.replace(self.config, fidelity="fast", simplify_paths=True), seed,
                                    motion_seeds=self.motion_seeds)

    @property
    def observer(self) -> WorldObserver:
        """Who is told what happens; a `WorldObserver` that ignores it all when nobody watches."""
        return self._observer

    @observer.setter
    def observer(self, observer: WorldObserver | None) -> None:
        self._observer = observer if observer is not None else WorldObserver()

    # --- scenes ------------------------------------------------------------------------------
    def reset(self, n_objects: int | None = None, X: np.ndarray | None = None, seed: int | None = None) -> np.ndarray:
        """A random scene of n_objects blocks, or the scene X (blocks upright, axis-aligned).

        Blocks settle under physics before the state is returned; the arm goes home. With `seed`
        the scene and its motion plans depend on that seed alone, not on earlier scenes (used to
        collect data in parallel with a seed per scene).
        """
        if (n_objects is None) == (X is None):
            raise ValueError("reset takes exactly one of n_objects or X")
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        self.motion_seeds.restart(int(self.rng.integers(2**31 - 1)))
        if X is not None:
            types, positions = _parse_X(X)
        else:
            if isinstance(n_objects, bool) or not isinstance(n_objects, (int, np.integer)) \
                    or not 1 <= n_objects <= MAX_OBJECTS:
                raise UserError(f"n_objects must be an integer in 1..{MAX_OBJECTS}, got {n_objects!r}")
            types, positions = self._random_layout(int(n_objects))
        self.q = Q_HOME.copy()
        scene = Scene(types, [RigidTransform(p) for p in positions])
        _, physics = self._layout(types)
        settled = physics.settle(scene.X_WB)
        self.scene = Scene(types, settled.X_WB)
        self.observer.scene_started(self.scene, self.q)
        return self.scene.X()

    def set_scene(self, scene: Scene, q: np.ndarray, motion_seed: int | None = None) -> None:
        """Continue from an exact simulator state (block poses with orientation, arm joints); with
        `motion_seed` the motion plans from here depend on that seed alone, as after `reset(seed=...)`."""
        if motion_seed is not None:
            self.motion_seeds.restart(motion_seed)
        self.observer.scene_started(scene, q)
        self.scene = Scene(np.array(scene.types), list(scene.X_WB))
        self.q = np.array(q, dtype=float)

    def _random_layout(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Random block types and resting positions: blocks placed one by one where they overlap none placed
        so far; a layout in which a block finds no place starts again (crowded scenes: 7-8 blocks, many bars)."""
        cfg = self.config
        types = (self.rng.random(n) < cfg.p_large).astype(int)
        half = np.array([BLOCK_SIZES[int(t)][:2] for t in types]) / 2 + cfg.min_separation / 2
        for _ in range(LAYOUT_ATTEMPTS):
            positions = self._placed(types, half)
            if positions is not None:
                return types, positions
        raise UserError(f"could not place {n} blocks ({int(types.sum())} bars) in the workspace without overlap in "
                        f"{LAYOUT_ATTEMPTS} layouts: ask for fewer blocks or fewer bars (WorldConfig.p_large)")

    def _placed(self, types: np.ndarray, half: np.ndarray) -> np.ndarray | None:
        """(n, 3) positions of blocks with footprints `half` (n, 2) placed in turn, or None if one finds no place."""
        cfg, positions = self.config, np.zeros((len(types), 3))
        for i in range(len(types)):
            for _ in range(10_000):
                xy = np.array([self.rng.uniform(*cfg.workspace_x), self.rng.uniform(*cfg.workspace_y)])
                if all(np.any(np.abs(xy - positions[j, :2]) >= half[i] + half[j]) for j in range(i)):
                    break
            else:
                return None
            positions[i] = [xy[0], xy[1], BLOCK_SIZES[int(types[i])][2] / 2]
        return positions

    def _layout(self, types: np.ndarray) -> tuple[MotionPlanner, BlockPhysics]:
        key = tuple(int(t) for t in types)
        if key not in self._layouts:
            cfg = self.config
            planner = MotionPlanner(build_motion_scene(types, cfg.padding), cfg.joint_step, cfg.padding)
            physics = BlockPhysics(build_physics_scene(types, cfg.time_step), cfg.settle_speed,
                                   cfg.settle_angular_speed, cfg.settle_window, cfg.settle_max_time)
            self._layouts[key] = (planner, physics)
        return self._layouts[key]

    def motion_planner(self, types: np.ndarray) -> MotionPlanner:
        """The cached motion planner (collision checker) of a scene layout (block types)."""
        return self._layout(types)[0]

    def actions(self) -> list[PickPlace]:
        """All 9 n^2 pick-place actions of the current scene."""
        n = self._require_scene().n
        return [PickPlace(i, gi, j, rj) for i in range(n) for gi in OFFSETS for j in range(n) for rj in OFFSETS]

    def graspable_actions(self) -> list[PickPlace]:
        """The actions whose grasp point closes the jaws on a block in the current scene: the others end
        with nothing grasped whatever the arm does (a geometric test, no motion planned)."""
        scene = self._require_scene()
        grasps = {(i, gi) for i in range(scene.n) for gi in OFFSETS  # the grasp pose ignores the place
                  if held_block(scene, grasp_pose(scene, PickPlace(i, gi, i, 0), self.config)) >= 0}
        return [a for a in self.actions() if (a.pick, a.grasp_offset) in grasps]

    @property
    def X(self) -> np.ndarray:
        return self._require_scene().X()

    def _require_scene(self) -> Scene:
        if self.scene is None:
            raise RuntimeError("call World.reset() before using the scene")
        return self.scene

    # --- the skill ---------------------------------------------------------------------------
    def step(self, action: PickPlace | Iterable[int], settle: bool = True,
             seen: Scene | None = None) -> tuple[np.ndarray, StepInfo]:
        """Plan and execute one pick-place; returns the next state X and what happened.

        `settle=False` (the fast world only) plans the same motions but simulates no physics: the
        released blocks stay where the gripper let them go, and the retreat is planned from there.
        The planners' refinement uses it, so that what happens after a release stays the Dynamics
        Model's prediction. `seen`: the blocks as a camera saw them (the same blocks, in the same order):
        the skill aims its gripper poses at those, and the world does what the true blocks do with them
        (what the jaws close on, what is carried and where it lands, what the motions may not hit)."""
        scene = self._require_scene()
        action = validate_action(action, scene.n)
        if seen is not None and seen.n != scene.n:
            raise ValueError(f"the scene seen has {seen.n} blocks, the world {scene.n}")
        if self._predictor is not None:
            if not settle:
                raise ValueError("settle=False plans without physics; it needs the fast world")
            return self._step_full(action, seen)
        aim = scene if seen is None else seen
        self.motion_seeds.step += 1
        info = StepInfo(action)
        t_start = time.perf_counter()
        planner, physics = self._layout(scene.types)
        planner.detach()
        planner.set_block_poses(scene.X_WB)

        # Approach: jaws open over the grasp point, then down to it.
        approach = approach_poses(aim, action, self.config)
        X_WGrasp = dict(approach)["grasp"]
        qs = self._solve_ik(approach, info)
        if qs is None:
            return self._unchanged(info, t_start)
        t_motion = time.perf_counter()
        paths: dict[str, np.ndarray] = {}
        segments = [("approach", self.q, qs["pregrasp"]), ("descend", qs["pregrasp"], qs["grasp"])]
        if not self._plan(planner, segments, info, paths):
            return self._unchanged(info, t_start, t_motion)
        info.timings["motion"] = time.perf_counter() - t_motion

        held = held_block(scene, X_WGrasp)
        info.grasped = held
        if held < 0:
            info.status, info.reason = StepStatus.NOTHING_GRASPED, "the jaws closed on nothing at the grasp point"
            return self._unchanged(info, t_start)

        wp = pick_place_waypoints(aim, action, held, self.config)
        if aim is not scene:  # aimed at the blocks seen; the true blocks are what the jaws carry
            carried = [held] + scene.resting_on(held)
            wp = dataclasses.replace(wp, carried=carried, X_GC=[wp.grasp.inverse() @ scene.X_WB[c] for c in carried])
        info.carried = list(wp.carried)
        qs = self._solve_ik(wp.named(), info, q_start=qs["grasp"], skip=("pregrasp", "grasp"), known=qs)
        if qs is None:
            return self._unchanged(info, t_start)
        t_motion = time.perf_counter()
        # Lift-off: straight up by a centimetre, the carried blocks leaving their support (the
        # gripper alone is checked); from there on they are attached to the gripper.
        planner.set_block_poses(scene.X_WB, parked=tuple(wp.carried))
        ok = self._plan(planner, [("liftoff", qs["grasp"], qs["liftoff"])], info, paths)
        planner.attach(carried_shapes(scene, wp, self.config))
        carry = [("lift", qs["liftoff"], qs["lift"]), ("transfer", qs["lift"], qs["preplace"]),
                 ("lower", qs["preplace"], qs["place"])]
        ok = ok and self._plan(planner, carry, info, paths)
        planner.detach()
        info.timings["motion"] += time.perf_counter() - t_motion
        if not ok:
            return self._unchanged(info, t_start)

        self._release(scene, wp, qs, paths, physics, info, settle)
        self._retreat(scene, wp, qs, paths, planner, info)
        info.paths = paths
        info.q_waypoints = qs
        info.X_GC = list(wp.X_GC)
        info.timings["total"] = time.perf_counter() - t_start
        return self._require_scene().X(), info

    def _release(self, scene: Scene, wp, qs: dict[str, np.ndarray], paths: dict[str, np.ndarray], physics,
                 info: StepInfo, settle: bool) -> None:
        """Carry the blocks kinematically to the place pose, release them and, with `settle`, let physics
        decide where they rest (self.scene)."""
        # Execute: carry kinematically, release, let physics decide.
        X_WB_release = list(scene.X_WB)
        for c, X_GC in zip(wp.carried, wp.X_GC):
            X_WB_release[c] = wp.place @ X_GC
        info.X_release = Scene(scene.types, X_WB_release).X()
        self.observer.action_started()
        self.observer.motions_executed([paths[m] for m in ("approach", "descend")], scene.X_WB, None)
        self.observer.motions_executed([paths[m] for m in ("liftoff", "lift", "transfer", "lower")], scene.X_WB,
                                       Carried(wp.carried, wp.X_GC))
        if settle:
            t_physics = time.perf_counter()
            record: list[tuple[float, list[RigidTransform]]] = []
            settled = physics.settle(X_WB_release, record)
            info.timings["physics"] = time.perf_counter() - t_physics
            info.settle_time, info.settled = settled.time, settled.settled
            self.observer.physics_frames([PhysicsFrame(t, qs["place"], X_WB) for t, X_WB in record])
            self.scene = Scene(scene.types, settled.X_WB)
        else:
            self.scene = Scene(scene.types, X_WB_release)

    def _retreat(self, scene: Scene, wp, qs: dict[str, np.ndarray], paths: dict[str, np.ndarray], planner,
                 info: StepInfo) -> None:
        """Lift the open jaws straight up from the released blocks (self.q); home when that is blocked."""
        released = self._require_scene()
        # Retreat straight up with open jaws. The jaws opened around the released blocks, and any
        # block that moved while settling may lean on them: those are not obstacles to lifting away.
        t_motion = time.perf_counter()
        moved = [k for k in range(scene.n) if k in wp.carried
                 or np.linalg.norm(released.X_WB[k].translation()  # type: ignore[misc]  # pydrake stubs
                                   - scene.X_WB[k].translation()) > 1e-3]
        planner.set_block_poses(released.X_WB, parked=tuple(moved))
        seed = self.motion_seeds.of("retreat")
        retreat = planner.plan(qs["place"], qs["retreat"], self.config.planning_time,
                               direct=self.config.direct_motions, simplify=self.config.simplify_paths, seed=seed,
                               max_checks=self.config.planning_checks)
        info.motion_seconds["retreat"] = time.perf_counter() - t_motion
        info.motion_planner["retreat"] = retreat.planner
        info.motion_success["retreat"] = retreat.path is not None
        if retreat.path is not None:
            paths["retreat"] = retreat.path
            self.q = qs["retreat"]
            self.observer.motions_executed([paths["retreat"]], released.X_WB, None)
        else:
            # The blocks have moved; the arm cannot leave without disturbing them. It is taken
            # home (a reset of the arm alone) so that the next action starts collision-free.
            self.q = Q_HOME.copy()
            info.reason = f"released, but the retreat was blocked ({retreat.reason}); the arm was reset home"
        info.timings["motion"] += time.perf_counter() - t_motion

    def _step_full(self, action: PickPlace, seen: Scene | None = None) -> tuple[np.ndarray, StepInfo]:
        """Plan and predict with the fast world (which takes the step's motion seeds from the shared
        `motion_seeds`; aimed at `seen`, if given), then execute the timed trajectory under physics."""
        assert self._predictor is not None  # the full fidelity builds its predictor in __init__
        scene, q = self._require_scene(), self.q.copy()
        self._predictor.set_scene(scene, q)
        X_predicted, info = self._predictor.step(action, seen=seen)
        info.X_predicted = X_predicted
        if info.status == StepStatus.OK and not info.motion_success.get("retreat", False):
            info.status = StepStatus.MOTION_FAILURE  # no trajectory without a way out: nothing is executed
        if info.status != StepStatus.OK:
            return scene.X(), info
        t0 = time.perf_counter()
        step = refined_action(action, info, scene.X(), X_predicted, q)
        plan = RefinedPlan(scene.X(), [action], scene_init=scene, q_init=q, steps=[step])
        result = self._executor(scene.types).run(plan, self.observer)
        self.scene, self.q = result.scene, step.q["retreat"].copy()
        info.execution = result.log[0]
        info.timings["execute"] = time.perf_counter() - t0
        info.timings["total"] += info.timings["execute"]
        return self.scene.X(), info

    def _executor(self, types: np.ndarray) -> Executor:
        """The full fidelity's executor (Drake diagram) of a block layout, built once."""
        key = tuple(int(t) for t in types)
        if key not in self._executors:
            self._executors[key] = Executor(types, self.config)
        return self._executors[key]

    def _solve_ik(self, waypoints, info: StepInfo, q_start=None, skip=(), known=None) -> dict | None:
        t0 = time.perf_counter()
        planner, _ = self._layout(self._require_scene().types)
        todo = [(name, X_WG) for name, X_WG in waypoints if name not in skip]
        found, failed = solve_chain(todo, self.q if q_start is None else q_start,
                                    lambda X_WG, q_ref: self._numerical_ik(planner, X_WG, q_ref), info.ik_solver)
        qs = {**(known or {}), **found}
        for name in found:
            info.ik_success[name] = True
        if failed is not None:
            info.ik_success[failed] = False
            p = dict(todo)[failed].translation()
            info.status = StepStatus.IK_FAILURE
            info.reason = f"no IK solution for the {failed} pose at ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m"
        info.timings["ik"] = info.timings.get("ik", 0.0) + time.perf_counter() - t0
        return qs if failed is None else None

    @staticmethod
    def _numerical_ik(planner: MotionPlanner, X_WTcp: RigidTransform, q_seed: np.ndarray):
        plant = planner.scene.plant
        q_full = planner.full_configuration(q_seed)
        return drake_ik(plant, planner.arm_position_indices, X_WTcp, q_full, plant.GetFrameByName("tcp"))

    def _plan(self, planner: MotionPlanner, motions, info: StepInfo, paths: dict) -> bool:
        for name, q_a, q_b in motions:
            t = time.perf_counter()
            result = planner.plan(q_a, q_b, self.config.planning_time, direct=self.config.direct_motions,
                                  simplify=self.config.simplify_paths, seed=self.motion_seeds.of(name),
                                  max_checks=self.config.planning_checks)
            info.motion_seconds[name] = time.perf_counter() - t
            info.motion_planner[name] = result.planner
            info.motion_success[name] = result.path is not None
            if result.path is None:
                info.status = StepStatus.MOTION_FAILURE
                info.reason = f"{name} motion: {result.reason}"
                return False
            paths[name] = result.path
        return True

    def _unchanged(self, info: StepInfo, t_start: float, t_motion: float | None = None) -> tuple[np.ndarray, StepInfo]:
        if t_motion is not None:
            info.timings["motion"] = info.timings.get("motion", 0.0) + time.perf_counter() - t_motion
        info.timings["total"] = time.perf_counter() - t_start
        return self.X, info


def validate_action(action, n: int) -> PickPlace:
    """A PickPlace from a 4-sequence of integers, or a ValueError naming what is wrong."""
    try:
        values = [int(v) for v in action]
        if any(float(v) != int(v) for v in action):
            raise TypeError
    except (TypeError, ValueError):
        raise UserError(f"an action is 4 integers (pick, grasp_offset, place, release_offset), "
                        f"got {action!r}") from None
    if len(values) != 4:
        raise UserError(f"an action is 4 integers (pick, grasp_offset, place, release_offset), got {action!r}")
    pick, grasp_offset, place, release_offset = values
    for name, index in (("pick", pick), ("place", place)):
        if not 0 <= index < n:
            raise UserError(f"{name} object index {index} is out of range for a scene of {n} objects")
    for name, offset in (("grasp_offset", grasp_offset), ("release_offset", release_offset)):
        if offset not in OFFSETS:
            raise UserError(f"{name} must be -1, 0 or +1, got {offset}")
    return PickPlace(pick, grasp_offset, place, release_offset)


def _parse_X(X) -> tuple[np.ndarray, np.ndarray]:
    X = np.asarray(X, dtype=float) if not isinstance(X, np.ndarray) else X.astype(float)
    if X.ndim != 2 or X.shape[1] != 5:
        raise UserError(f"X must have shape (n, 5) (x, y, z, one-hot type), got shape {X.shape}")
    if not 1 <= X.shape[0] <= MAX_OBJECTS:
        raise UserError(f"X must describe 1..{MAX_OBJECTS} objects, got {X.shape[0]}")
    if not np.all(np.isfinite(X)):
        raise UserError("X contains NaN or infinite values")
    onehot = X[:, 3:]
    if not np.all((onehot == 0) | (onehot == 1)) or not np.all(onehot.sum(axis=1) == 1):
        raise UserError(f"X[:, 3:5] must be a one-hot type (small, large) per object, got {onehot.tolist()}")
    check_scene(X, where="X", upright=True, within_reach=False)  # placed upright, axis-aligned
    types = onehot.argmax(axis=1).astype(int)
    positions = X[:, :3].copy()
    return types, positions


__all__ = ["World", "validate_action", "SMALL", "LARGE", "topdown", "Waypoints"]
