"""What the simulated world reports while it runs, for whoever watches it (a replay's `Timeline`).

The world (`World.step`, `World.reset`, `World.set_scene`) and the full-fidelity executor
(`Executor.run`) call one `WorldObserver` at each event below, in the order things happen; they do
not know what the observer does with them. `WorldObserver` itself ignores every event: it is the
world's observer when nobody watches.
"""
from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
from pydrake.math import RigidTransform

from tamp.sim.skill import Scene


class Carried(NamedTuple):
    """Blocks moving with the gripper: their indices and their poses in the tcp frame G."""

    blocks: Sequence[int]
    X_GC: Sequence[RigidTransform]


class PhysicsFrame(NamedTuple):
    """One simulated instant: t (seconds since the simulated stretch began), arm joints, block poses."""

    t: float
    q: np.ndarray
    X_WB: Sequence[RigidTransform]


class WorldObserver:
    """The events of a running world, in order: a scene starts, then per action `action_started`
    followed by its motions (kinematic paths, untimed) and physics frames (simulated, timed)."""

    def scene_started(self, scene: Scene, q: np.ndarray) -> None:
        """A scene begins (a reset, a given state, the start of an execution): blocks and arm joints."""

    def action_started(self) -> None:
        """An action starts; its motions and frames follow. Actions that change nothing (IK,
        motion or grasp failures) report nothing, not even their start."""

    def motions_executed(self, paths: Sequence[np.ndarray], X_WB: Sequence[RigidTransform],
                         carried: Carried | None) -> None:
        """Joint paths (k, 6) the arm followed kinematically, the blocks at X_WB except `carried`."""

    def physics_frames(self, frames: Sequence[PhysicsFrame]) -> None:
        """A simulated stretch (blocks settling, or the arm executing under physics), its times
        counted from its own start, which is where the previous event left the world."""
