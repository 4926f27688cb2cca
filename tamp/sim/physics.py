"""Physics of released blocks: simulate table + blocks until every block is at rest."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydrake.math import RigidTransform
from pydrake.systems.analysis import Simulator

from tamp.sim.plants import PhysicsScene


@dataclass
class SettleResult:
    X_WB: list[RigidTransform]  # block poses at rest
    time: float  # simulated seconds
    settled: bool  # False when the time cap was hit


class BlockPhysics:
    """Hydroelastic table-and-blocks simulation that runs until the scene is at rest."""

    def __init__(self, scene: PhysicsScene, settle_speed: float, settle_angular_speed: float,
                 settle_window: float, max_time: float) -> None:
        self.scene = scene
        self._simulator = Simulator(scene.diagram)
        self._plant_context = scene.plant.GetMyMutableContextFromRoot(self._simulator.get_mutable_context())
        self._bodies = [scene.plant.get_body(scene.plant.GetBodyIndices(b)[0]) for b in scene.blocks]
        self._speed = settle_speed
        self._angular_speed = settle_angular_speed
        self._window = settle_window
        self._max_time = max_time
        self._check_every = max(scene.plant.time_step(), 0.01)

    def settle(self, X_WB: list[RigidTransform], record: list | None = None) -> SettleResult:
        """Start the blocks at rest at X_WB and simulate until all are still for the settle window.

        If `record` is a list, (time, poses) samples are appended to it every check interval.
        """
        plant, ctx = self.scene.plant, self._plant_context
        root = self._simulator.get_mutable_context()
        root.SetTime(0.0)
        for body, X_WBi in zip(self._bodies, X_WB):
            plant.SetFreeBodyPose(ctx, body, X_WBi)
            plant.SetFreeBodySpatialVelocity(ctx, body, _zero_velocity())
        self._simulator.Initialize()
        still_since = 0.0
        t = 0.0
        while t < self._max_time:
            t = min(t + self._check_every, self._max_time)
            self._simulator.AdvanceTo(t)
            poses = [plant.EvalBodyPoseInWorld(ctx, b) for b in self._bodies]
            if record is not None:
                record.append((t, poses))
            if self._at_rest():
                if t - still_since >= self._window - 1e-9:
                    return SettleResult(poses, t, True)
            else:
                still_since = t
        return SettleResult([plant.EvalBodyPoseInWorld(ctx, b) for b in self._bodies], t, False)

    def _at_rest(self) -> bool:
        return blocks_at_rest(self.scene.plant, self._plant_context, self._bodies, self._speed, self._angular_speed)


def blocks_at_rest(plant, context, bodies, speed: float, angular_speed: float) -> bool:
    """True when every body moves slower than `speed` (m/s) and turns slower than `angular_speed` (rad/s)."""
    for body in bodies:
        V = plant.EvalBodySpatialVelocityInWorld(context, body)
        if np.linalg.norm(V.translational()) > speed or np.linalg.norm(V.rotational()) > angular_speed:
            return False
    return True


def _zero_velocity():
    from pydrake.multibody.math import SpatialVelocity

    # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
    return SpatialVelocity(np.zeros(3), np.zeros(3))  # type: ignore[arg-type]
