"""Perception against the simulator's truth: what class each true block is in, how far its estimate is, and the
time an observation takes. `tamp perceive` prints it for one scene, bench/perception.py sums it over many."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from tamp.sim.box_fit import orientation_error
from tamp.sim.cameras import CameraRig
from tamp.sim.perception import Perception, perceive
from tamp.sim.skill import Scene

CLASSES = ("table", "stack", "leaning")  # where a true block is: on the table, on another block, tilted
LEANING_RAD = np.radians(3.0)  # a block whose axis nearest the vertical is tilted more than this leans
ON_TABLE_M = 0.01  # metres: a block whose bottom is higher rests on another (or leans on one)


def block_class(scene: Scene, i: int) -> str:
    """CLASSES entry of block i of the true `scene`."""
    R = scene.X_WB[i].rotation().matrix()
    if np.arccos(np.clip(np.abs(R[2, :]).max(), 0.0, 1.0)) > LEANING_RAD:
        return "leaning"
    return "stack" if scene.bottom(i) > ON_TABLE_M else "table"


@dataclass(frozen=True)
class BlockCheck:
    """One true block and its estimate (the estimate perception gave its identity)."""

    block: int
    kind: str  # CLASSES entry
    type_true: int
    type_seen: int | None  # None: no estimate has this block's identity
    position_error_m: float | None
    orientation_error_rad: float | None  # the yaw error for a block resting flat; up to the box's symmetries

    @property
    def found(self) -> bool:
        return self.type_seen is not None

    @property
    def type_right(self) -> bool:
        return self.type_seen == self.type_true


def check(scene: Scene, seen: Perception) -> list[BlockCheck]:
    """Each true block of `scene` against the estimate with its identity (perceived with `previous` in the order
    of `scene`)."""
    by_identity = {i: b for b, i in zip(seen.blocks, seen.identity) if i >= 0}
    checks = []
    for i in range(scene.n):
        t, kind, block = int(scene.types[i]), block_class(scene, i), by_identity.get(i)
        if block is None:
            checks.append(BlockCheck(i, kind, t, None, None, None))
            continue
        X_WB = scene.X_WB[i]
        error = float(np.linalg.norm(block.position - X_WB.translation()))
        R_true = np.asarray(X_WB.rotation().matrix())
        checks.append(BlockCheck(i, kind, t, block.type, error, orientation_error(block.X_WB[:3, :3], R_true, t)))
    return checks


@dataclass
class Observation:
    """One observation of a true scene: what was perceived, checked against the truth, and its times."""

    seen: Perception
    checks: list[BlockCheck]
    render_s: float  # Drake's rendering of every camera
    noise_s: float  # the sensor model's noise (a simulator's cost, no real camera's)
    perceive_s: float  # depth images to blocks

    @property
    def count_right(self) -> bool:
        return len(self.seen.blocks) == len(self.checks) and all(c.found for c in self.checks)


def observe(rig: CameraRig, scene: Scene, rng: np.random.Generator, previous: np.ndarray | None = None) -> Observation:
    """Render `scene` with the rig, measure it with the sensors' noise and perceive it, identities from `previous`
    (the scene's own X when None: the truth names the blocks)."""
    t0 = time.perf_counter()
    views = rig.render(scene)
    t1 = time.perf_counter()
    views = rig.measured(views, rng)
    t2 = time.perf_counter()
    seen = perceive(views, rig.config, previous=scene.X() if previous is None else previous)
    t3 = time.perf_counter()
    return Observation(seen, check(scene, seen), t1 - t0, t2 - t1, t3 - t2)


__all__ = ["BlockCheck", "CLASSES", "Observation", "block_class", "check", "observe"]
