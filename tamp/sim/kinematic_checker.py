"""Kinematic feasibility of pick-place actions in a predicted scene, for the planners.

A predicted state X (n, 5) holds positions only; the check rebuilds a scene from them with each
block's orientation carried over from the last observed scene (the state has no yaw), and then asks,
with the skill's own geometry (`tamp.sim.skill`) and IK (`tamp.sim.kinematics.solve_chain`, closed form on the
skill's branch, no numerical fallback):

1. grasp contact: does the grasp point lie on the picked block (`skill.held_block`)?
2. IK: does every waypoint (pre-grasp ... retreat) have a solution on the branch?
3. collision: is every waypoint configuration free of the other blocks and the table (Drake's
   collision checker of the `fast` world, one per scene layout, block poses set per query), with the
   carried blocks attached while they are carried?

No physics is simulated and no motion is planned: what happens after release stays the Dynamics
Model's prediction. `FeasibilityChecker.refine` is the full refinement (IK, OMPL motions, grasps) of a
plan, which the planners run before returning it: each action's motions are planned in the scene the
Dynamics Model predicts before it, again without physics.
The planners see this class only through `tamp.planning.vocabulary.KinematicFeasibility`.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from pydrake.math import RigidTransform

from tamp.planning.search import SearchConfig, state_key
from tamp.planning.vocabulary import OFFSETS, Infeasible, PickPlace, RefinementOutcome
from tamp.sim.kinematics import BRANCH, Q_HOME, solve_chain
from tamp.sim.motion import MotionPlanner
from tamp.sim.plants import build_motion_scene
from tamp.sim.refine import step_failure
from tamp.sim.skill import (
    Box,
    PickWaypoints,
    Scene,
    Waypoints,
    approach_poses,
    boxes_overlap,
    can_hold,
    carried_shapes,
    carried_size,
    held_block,
    pick_place_waypoints,
    pick_waypoints,
)
from tamp.sim.world import World
from tamp.sim.world_types import StepInfo, WorldConfig

# Collision set-up of each waypoint configuration, as `World.step` plans the motions through it.
WITH_ALL_BLOCKS = ("pregrasp", "grasp")  # jaws open around the picked block
CARRYING = ("liftoff", "lift", "preplace", "place")  # carried blocks attached to the gripper (lift-off: the pick half)
AFTER_RELEASE = ("retreat",)  # carried blocks released below the jaws: not obstacles
REFINE_REASONS = {"ik": Infeasible.REFINE_IK, "motion": Infeasible.REFINE_MOTION, "grasp": Infeasible.REFINE_GRASP}


# metres: a predicted block this close to resting on the table or a block is checked resting on it (the
#   Dynamics Model predicts released blocks a few mm off their support; docs/beyond-the-paper.md)
REST_WITHIN_M = 0.01
_MAX_PICKS = 100_000  # remembered pick halves before the memo starts again (each a few kB)
_MAX_SCENES = 1_000  # remembered predicted scenes (each a few kB)


@dataclass(frozen=True)
class _Pick:
    """A feasible pick half: its waypoints, the arm at the lift-off, the carried blocks' boxes."""

    waypoints: PickWaypoints
    q_liftoff: np.ndarray
    shapes: list[Box]


def _grid_key(scene: Scene, grid_m: float) -> bytes:
    """The blocks' types and positions on a `grid_m` grid (the search's duplicate-detection grid), as bytes."""
    positions = np.array([X_WB.translation() for X_WB in scene.X_WB])
    return np.asarray(scene.types, dtype=np.int64).tobytes() + state_key(positions, grid_m)


def _remember(memo: dict, key, value, limit: int) -> None:
    """memo[key] = value, the memo emptied first when it holds `limit` entries (it starts again)."""
    if len(memo) >= limit:
        memo.clear()
    memo[key] = value


class FeasibilityChecker:
    """Cheap per-action check on predicted scenes, and full refinement, for one observed scene at a time.

    Call `reset(X_init)` (blocks upright, settled, as `tamp.sim.refine.refine(plan, X_init)` starts) or
    `observe(scene, q)` (an exact simulator state, e.g. in closed loop) before planning from it.
    """

    def __init__(self, world: World | None = None, config: WorldConfig | None = None, shortcuts: bool = True,
                 rest_within: float | None = REST_WITHIN_M) -> None:
        """`world`: a `fast` World whose Drake plants are reused (ideally with simplify_paths=True,
        the world refinement uses); by default one is made from `config`. `shortcuts`: keep the pick half
        of each check for the other places of the same grasp, pose the carried boxes as stand-ins in a
        collision checker of their own, reject a place whose box overlaps a standing block before IK, and
        tell the search which grasps can never hold a block (`graspable`) (False: every check from scratch
        on the world's checker, the benchmark's baseline; the verdicts are the same). `rest_within` (metres):
        a predicted block this close to resting on the table or a block is checked resting on it
        (`predicted_scene`; None: where X puts it)."""
        if world is None:
            world = World(dataclasses.replace(config or WorldConfig(), fidelity="fast", simplify_paths=True))
        if world.config.fidelity != "fast":
            raise ValueError("FeasibilityChecker needs a fast World")
        self.world = world
        self.config = world.config
        self.scene: Scene | None = None
        self.q = Q_HOME.copy()
        self.num_checks = 0
        self.check_time_s = 0.0
        self.shortcuts = shortcuts
        self.rest_within = rest_within
        self._carrying: dict[tuple[int, ...], MotionPlanner] = {}  # per layout (`_carrying_planner`)
        self._picks: dict[tuple[bytes, int, int], _Pick | Infeasible] = {}
        self._scenes: dict[bytes, Scene] = {}  # predicted scenes by X's positions, with their corners (`check`)
        # actions whose refinement failed, by (scene on the search's grid, action, its place in the plan: the
        #   motion seed); kept across `observe`, since a closed loop's rounds and their widened searches ask again
        self._failed_refinements: dict[tuple[bytes, tuple[int, ...], int], tuple[Infeasible | None, str]] = {}

    # --- the observed scene ----------------------------------------------------------------------
    def reset(self, X_init: np.ndarray) -> Scene:
        """Observe the scene X_init places upright, as `tamp.sim.refine.refine(plan, X_init)` starts."""
        self.world.rng = np.random.default_rng(0)
        self.world.reset(X=X_init)
        scene = self.world.scene
        assert scene is not None  # reset placed the blocks
        self.scene, self.q = scene, self.world.q.copy()
        self._picks.clear()
        self._scenes.clear()
        self._failed_refinements.clear()
        return scene

    def observe(self, scene: Scene, q: np.ndarray | None = None) -> None:
        """Plan from an exact simulator state (block poses with orientation, arm joints)."""
        self.scene = Scene(np.array(scene.types), list(scene.X_WB))
        self.q = Q_HOME.copy() if q is None else np.array(q, dtype=float)
        self._picks.clear()
        self._scenes.clear()

    def predicted_scene(self, X: np.ndarray) -> Scene:
        """Positions from X, orientations carried over from the observed scene, each block within
        `rest_within` of its support set down on it (`Scene.settled`)."""
        if self.scene is None:
            raise RuntimeError("call FeasibilityChecker.reset() or observe() before checking actions")
        X = np.asarray(X, dtype=float)
        if len(X) != self.scene.n:
            raise ValueError(f"X has {len(X)} objects, the observed scene {self.scene.n}")
        scene = Scene(self.scene.types,
                      [RigidTransform(X_WB.rotation(), p) for X_WB, p in zip(self.scene.X_WB, X[:, :3])])
        return scene if self.rest_within is None else scene.settled(self.rest_within)

    # --- the cheap check ---------------------------------------------------------------------------
    def graspable(self, X: np.ndarray) -> np.ndarray:
        """(n, 3) bool: False where no pose of block i lets the jaws hold it at grasp offset -1, 0, +1
        (`skill.can_hold`: a cube grasped off its centre), so that every check of such an action says NO_GRASP.
        Without shortcuts every grasp is left to the check."""
        types = np.argmax(np.asarray(X, dtype=float)[:, 3:], axis=1)
        if not self.shortcuts:
            return np.ones((len(types), len(OFFSETS)), dtype=bool)
        return np.array([[can_hold(int(t), g) for g in OFFSETS] for t in types], dtype=bool)

    def check(self, X: np.ndarray, actions) -> list[Infeasible | None]:
        """Per action (B, 4) in the predicted scene X (n, 5): None if feasible, else the first reason.

        The pick half of a check (`_pick`) is remembered per (X, pick, grasp offset) until the next
        `reset`/`observe`: the search checks the successors of one state one at a time, up to nine of
        them with the same grasp, and most rejections are the grasp's (nothing held, the jaws or the
        lifted block hitting a neighbour)."""
        t0 = time.perf_counter()
        X = np.asarray(X, dtype=float)
        state = X[:, :3].tobytes()
        scene = self._scenes.get(state) if self.shortcuts else None
        if scene is None:  # the successors of one state are checked one after another: one scene for them all
            scene = self.predicted_scene(X)
            if self.shortcuts:
                _remember(self._scenes, state, scene, _MAX_SCENES)
        out = [self.check_scene(scene, PickPlace(*(int(v) for v in a)), state)
               for a in np.asarray(actions).reshape(-1, 4)]
        self.num_checks += len(out)
        self.check_time_s += time.perf_counter() - t0
        return out

    def check_scene(self, scene: Scene, action: PickPlace, state: bytes | None = None) -> Infeasible | None:
        """The check of one action in an exact scene, pick half first (`state`: a key of the scene, to
        remember the pick half under)."""
        pick = self._pick(scene, action, state)
        if isinstance(pick, Infeasible):
            return pick
        wp = pick_place_waypoints(scene, action, action.pick, self.config, pick.waypoints)
        if self.shortcuts and self._place_occupied(scene, wp, pick.shapes):
            return Infeasible.COLLISION
        qs, failed = solve_chain(wp.named()[3:], pick.q_liftoff)
        if failed is not None:
            return Infeasible.IK
        planner = self.world.motion_planner(scene.types)
        planner.detach()
        planner.set_block_poses(scene.X_WB, parked=tuple(wp.carried))
        if not all(planner.is_valid(qs[name]) for name in AFTER_RELEASE):
            return Infeasible.COLLISION
        carrying = self._carrying_planner(scene, wp.carried, pick.shapes)
        return None if all(carrying.is_valid(qs[name]) for name in CARRYING[1:]) else Infeasible.COLLISION

    @staticmethod
    def _place_occupied(scene: Scene, wp: Waypoints, shapes: list[Box]) -> bool:
        """Whether a carried box at the place pose interpenetrates a block left standing (`boxes_overlap`): the
        collision check of the place waypoint would say so, after IK and the attached boxes that cost ten
        times more. Most rejections in cluttered scenes are of this kind (a neighbour where the block goes)."""
        others = [k for k in range(scene.n) if k not in wp.carried]
        for (size, _), X_GC in zip(shapes, wp.X_GC):
            X_WC = wp.place @ X_GC
            if any(boxes_overlap(X_WC, size, scene.X_WB[k], scene.size(k)) for k in others):
                return True
        return False

    def _carrying_planner(self, scene: Scene, carried: Sequence[int], shapes: list[Box]) -> MotionPlanner:
        """The collision model of the carrying waypoints: the carried blocks parked and their boxes attached to
        the gripper. A checker of its own per layout, with a stand-in box for every block (`plants.StandIn`):
        attaching is setting joint positions, not adding shapes to the checker (0.35 ms each); the world's
        checker stays bare."""
        key = tuple(int(t) for t in scene.types)
        if not self.shortcuts:
            planner = self.world.motion_planner(scene.types)
        else:
            if key not in self._carrying:
                cfg = self.config
                stand_ins = [carried_size(t, cfg) for t in scene.types]  # enough for any stack
                self._carrying[key] = MotionPlanner(build_motion_scene(scene.types, cfg.padding, stand_ins=stand_ins),
                                                    cfg.joint_step, cfg.padding)
            planner = self._carrying[key]
        planner.set_block_poses(scene.X_WB, parked=tuple(carried))
        planner.attach(shapes)
        return planner

    def _pick(self, scene: Scene, action: PickPlace, state: bytes | None) -> _Pick | Infeasible:
        """The pick half of the check (grasp contact, IK up to the lift-off, its collisions), remembered
        under (state, pick, grasp offset) when `state` is given."""
        key = None if state is None or not self.shortcuts else (state, action.pick, action.grasp_offset)
        if key in self._picks:
            return self._picks[key]
        pick = self._check_pick(scene, action)
        if key is not None:
            _remember(self._picks, key, pick, _MAX_PICKS)
        return pick

    def _check_pick(self, scene: Scene, action: PickPlace) -> _Pick | Infeasible:
        cfg = self.config
        approach = approach_poses(scene, action, cfg)
        if held_block(scene, dict(approach)["grasp"]) != action.pick:
            return Infeasible.NO_GRASP
        wp = pick_waypoints(scene, action, action.pick, cfg)
        qs, failed = solve_chain(wp.named(), Q_HOME)
        if failed is not None:
            return Infeasible.IK
        planner = self.world.motion_planner(scene.types)
        planner.detach()
        planner.set_block_poses(scene.X_WB)
        if not all(planner.is_valid(qs[name]) for name in WITH_ALL_BLOCKS):
            return Infeasible.COLLISION
        # From the lift-off on, the carried blocks are attached to the gripper and parked out of the scene.
        shapes = carried_shapes(scene, wp, cfg)
        if not self._carrying_planner(scene, wp.carried, shapes).is_valid(qs["liftoff"]):
            return Infeasible.COLLISION
        return _Pick(wp, qs["liftoff"], shapes)

    # --- full refinement ---------------------------------------------------------------------------
    def refine(self, actions: Sequence[Sequence[int]], trajectory: np.ndarray | None = None,
               grid_m: float = SearchConfig.resolution) -> RefinementOutcome:
        """Full refinement of a plan: IK, OMPL motions (the skill's, with the carried blocks attached)
        and grasps, action by action, without physics.

        With `trajectory` ((len(actions) + 1, n, 5), the Dynamics Model's predicted states along the
        plan), action k's motions are planned in the scene predicted before it (orientations carried
        over from the observation; action 0 in the observed scene), from the arm configuration the
        previous action's retreat ends in: what happens after a release stays the prediction.
        Without it, each action is planned in the scene the previous one leaves with its released
        blocks where the gripper let them go. The simulator decides what really happens only when
        the plan is executed. An action that failed to refine fails again at once in the same scene (to
        the `grid_m` grid, metres: the continuous search's) at the same place of a plan, until the next `reset`: a
        failed motion has spent RRTConnect's whole budget (about a second), and a closed loop's rounds
        offer the same first actions again."""
        if self.scene is None:
            raise RuntimeError("call FeasibilityChecker.reset() or observe() before refining a plan")
        plan = [PickPlace(*(int(v) for v in a)) for a in actions]
        if trajectory is not None and len(trajectory) < len(plan):
            raise ValueError(f"a trajectory of {len(trajectory)} states for {len(plan)} actions")
        scene, q = self.scene, self.q
        steps: list[dict] = []
        for k, action in enumerate(plan):
            if k > 0 and trajectory is not None:
                scene = self.predicted_scene(trajectory[k])
            known = (_grid_key(scene, grid_m), tuple(action), k)
            if known in self._failed_refinements:
                reason, message = self._failed_refinements[known]
                steps.append({"ik_branch": None, "planner": None, "time_s": None, "failure": message + " (known)"})
                return RefinementOutcome(k, reason, message, tuple(steps))
            self.world.set_scene(scene, q, motion_seed=k)
            _, info = self.world.step(action, settle=False)
            failure = step_failure(info)
            steps.append(refined_step(info, None if failure is None else f"{failure[0]} [{failure[1]}]: {failure[2]}"))
            if failure is not None:
                stage, where, why = failure
                outcome = RefinementOutcome(k, REFINE_REASONS[stage], f"{stage} [{where}]: {why}", tuple(steps))
                _remember(self._failed_refinements, known, (outcome.reason, outcome.message), _MAX_SCENES)
                return outcome
            assert self.world.scene is not None  # set_scene above
            scene, q = self.world.scene, self.world.q
        return RefinementOutcome(steps=tuple(steps))


def refined_step(info: StepInfo, failure: str | None) -> dict:
    """One action's refinement as the search record has it: IK branch, planner per motion, seconds, failure."""
    planners = ", ".join(f"{name} {planner}" for name, planner in info.motion_planner.items())
    return {"ik_branch": BRANCH, "planner": planners or None,
            "time_s": round(sum(info.motion_seconds.values()), 4), "failure": failure}


__all__ = ["FeasibilityChecker"]

