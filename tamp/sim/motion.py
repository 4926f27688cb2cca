"""Joint-space motion planning for the UR10e: OMPL RRTConnect over Drake's collision checker.

Every motion is first tried as the straight joint-space segment (OMPL's motion validator at the
configured resolution); RRTConnect runs only when that segment is blocked. A grasped block is
attached to the gripper (as an added collision shape, or as a stand-in box on a joint to the gripper
where the scene has one) and its free body is moved out of the scene, so carried motions are checked
with the block in the jaws.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from ompl import base as ob
from ompl import geometric as og
from ompl import util as ou
from pydrake.geometry import Box
from pydrake.math import RigidTransform

from tamp.sim.kinematics import Q_LOWER, Q_UPPER
from tamp.sim.plants import MotionScene

ou.setLogLevel(ou.LogLevel.LOG_WARN)

_PARKED = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -10.0])  # free-body pose far below the table
_CARRIED_GROUP = "carried"
_STAND_IN_PARKED = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 100.0])  # a stand-in 100 m from the gripper: touches nothing


def _positions(X: RigidTransform) -> np.ndarray:
    """The 7 positions of a floating joint at pose X: quaternion (w, x, y, z), then translation."""
    return np.concatenate((X.rotation().ToQuaternion().wxyz(), X.translation()))


def _seed_ompl(seed: int) -> None:
    """Reseed OMPL's generator so a motion's path depends on its seed only. OMPL logs an error
    when reseeding after its first use, yet the reseeding takes effect, so the log is muted."""
    level = ou.getLogLevel()
    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    ou.RNG.setSeed(int(seed) % (2**31 - 1) + 1)
    ou.setLogLevel(level)


@dataclass
class MotionResult:
    path: np.ndarray | None  # (m, 6) joint waypoints, start and goal included; None if no path
    reason: str = ""  # why there is no path
    planner: str = ""  # "direct" or "rrtconnect"


class MotionPlanner:
    """Plans collision-free arm motions in a scene whose block poses are set by the caller."""

    def __init__(self, scene: MotionScene, joint_step: float, padding: float) -> None:
        self.scene = scene
        plant = scene.plant
        self._n_q = plant.num_positions()
        self._arm_idx = np.array(
            [plant.get_joint(j).position_start() for j in plant.GetJointIndices(scene.arm)
             if plant.get_joint(j).num_positions() == 1]
        )
        self._block_idx = [
            plant.get_body(plant.GetBodyIndices(b)[0]).floating_positions_start() for b in scene.blocks
        ]
        self._q_full = np.zeros(self._n_q)
        for i in range(len(scene.blocks)):
            self._set_block(i, _PARKED)
        self._park_stand_ins()
        self._joint_step = joint_step
        self.num_checks = 0
        self._attached: tuple | None = None  # key of the boxes attached to the gripper (None: unknown)
        self._shapes_added = True  # whether boxes may have been added to the checker as shapes (unknown: yes)

        self._space = ob.RealVectorStateSpace(6)
        bounds = ob.RealVectorBounds(6)
        for i in range(6):
            bounds.setLow(i, float(Q_LOWER[i]))
            bounds.setHigh(i, float(Q_UPPER[i]))
        self._space.setBounds(bounds)

    @property
    def arm_position_indices(self) -> np.ndarray:
        """Where the six arm joints sit in the motion plant's position vector."""
        return self._arm_idx

    # --- scene -------------------------------------------------------------------------------
    def _set_block(self, i: int, q7: np.ndarray) -> None:
        s = self._block_idx[i]
        self._q_full[s : s + 7] = q7

    def _set_stand_in(self, k: int, q7: np.ndarray) -> None:
        s = self.scene.stand_ins[k].position_start
        self._q_full[s : s + 7] = q7

    def _park_stand_ins(self) -> None:
        for k in range(len(self.scene.stand_ins)):
            self._set_stand_in(k, _STAND_IN_PARKED)

    def set_block_poses(self, X_WB: list[RigidTransform], parked: tuple[int, ...] = ()) -> None:
        """Block poses for collision checking; blocks in `parked` are removed from the scene."""
        for i, X_WBi in enumerate(X_WB):
            if i in parked:
                self._set_block(i, _PARKED)
            else:
                self._set_block(i, _positions(X_WBi))

    def attach(self, shapes: list[tuple[tuple[float, float, float], RigidTransform]]) -> None:
        """Attach boxes (size, pose in the gripper body frame) to the gripper; nothing is done when these
        boxes are attached already, to a tenth of a micrometre. The scene's stand-ins of the same sizes take
        the boxes' poses when there are enough of them; otherwise the boxes are added to the collision
        checker as shapes (about 0.35 ms each)."""
        key = tuple((tuple(size), np.round(X_GB.GetAsMatrix34(), 7).tobytes()) for size, X_GB in shapes)
        if key == self._attached:
            return
        self.detach()
        free = list(range(len(self.scene.stand_ins)))
        posed = []
        for size, X_GB in shapes:
            k = next((k for k in free if self.scene.stand_ins[k].size == tuple(size)), None)
            if k is None:
                break
            free.remove(k)
            posed.append((k, X_GB))
        if len(posed) == len(shapes):
            for k, X_GB in posed:
                self._set_stand_in(k, _positions(X_GB))
        else:
            for size, X_GB in shapes:
                self.scene.checker.AddCollisionShapeToBody(
                    _CARRIED_GROUP, self.scene.gripper_body, Box(*size), X_GB
                )
            self._shapes_added = True
        self._attached = key

    def detach(self) -> None:
        if self._attached != ():
            self._park_stand_ins()
            if self._shapes_added:
                self.scene.checker.RemoveAllAddedCollisionShapes(_CARRIED_GROUP)
                self._shapes_added = False
            self._attached = ()

    def full_configuration(self, q_arm: np.ndarray) -> np.ndarray:
        q = self._q_full.copy()
        q[self._arm_idx] = q_arm
        return q

    # --- checks ------------------------------------------------------------------------------
    def is_valid(self, q_arm) -> bool:
        self.num_checks += 1
        q = self._q_full
        q[self._arm_idx] = [q_arm[i] for i in range(6)]
        # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
        return bool(self.scene.checker.CheckConfigCollisionFree(q))  # type: ignore[arg-type]

    def collisions(self, q_arm: np.ndarray) -> list[str]:
        """Names of the colliding body pairs at q_arm, e.g. 'gripper_base / object 2'."""
        checker, plant = self.scene.checker, self.scene.plant
        # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
        clearance = checker.CalcRobotClearance(self.full_configuration(q_arm), 0.01)  # type: ignore[arg-type]
        names = {plant.GetBodyIndices(b)[0]: f"object {i}" for i, b in enumerate(self.scene.blocks)}
        pairs = []
        for r, o, d in zip(clearance.robot_indices(), clearance.other_indices(), clearance.distances()):
            if d < checker.GetPaddingBetween(r, o):
                pairs.append(f"{names.get(r, plant.get_body(r).name())} / {names.get(o, plant.get_body(o).name())}")
        return sorted(set(pairs))

    def path_is_valid(self, path: np.ndarray, joint_step: float) -> bool:
        """Check a piecewise-linear path densely (independent of OMPL)."""
        for a, b in zip(path[:-1], path[1:]):
            m = max(2, int(np.ceil(np.linalg.norm(b - a) / joint_step)) + 1)
            for s in np.linspace(0.0, 1.0, m):
                if not self.is_valid(a + s * (b - a)):
                    return False
        return True

    # --- planning ----------------------------------------------------------------------------
    def plan(self, q_start: np.ndarray, q_goal: np.ndarray, time_limit: float, direct: bool = True,
             simplify: bool = False, seed: int = 0, max_checks: int = 20_000) -> MotionResult:
        """A collision-free joint path from q_start to q_goal within the joint limits; with `direct`
        the straight segment is returned when it is free."""
        for name, q in (("start", q_start), ("goal", q_goal)):
            if not self.is_valid(q):
                pairs = ", ".join(self.collisions(q)) or "carried block"
                return MotionResult(None, f"{name} configuration in collision ({pairs})")
        ss = og.SimpleSetup(self._space)
        ss.setStateValidityChecker(self.is_valid)
        si = ss.getSpaceInformation()
        si.setStateValidityCheckingResolution(self._joint_step / self._space.getMaximumExtent())
        start, goal = self._space.allocState(), self._space.allocState()
        for i in range(6):
            start[i] = float(q_start[i])
            goal[i] = float(q_goal[i])
        ss.setStartAndGoalStates(start, goal)
        ss.setPlanner(og.RRTConnect(si))
        ss.setup()
        if direct and si.checkMotion(start, goal):
            return MotionResult(np.array([q_start, q_goal], dtype=float), planner="direct")
        _seed_ompl(seed)
        # Stop after a budget of collision checks, so that the outcome does not depend on how busy
        # the machine is; the time limit only guards against a pathological case.
        first, deadline = self.num_checks, time.perf_counter() + time_limit
        stop = ob.PlannerTerminationCondition(
            lambda: self.num_checks - first > max_checks or time.perf_counter() > deadline)
        status = ss.solve(stop)
        if not ss.haveExactSolutionPath():
            return MotionResult(None, f"no collision-free path within {max_checks} collision checks ({status})")
        if simplify:
            ss.simplifySolution()  # one full shortcut-and-smooth pass
        path = ss.getSolutionPath()
        states = [[path.getState(k)[i] for i in range(6)] for k in range(path.getStateCount())]
        return MotionResult(np.array(states, dtype=float), planner="rrtconnect")
