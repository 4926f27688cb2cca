"""Faults of a real cell, injected into a closed loop to measure how it recovers.

- Observation noise: every horizontal position the planner observes carries Gaussian noise of
  `noise_m` (metres, per coordinate), as a camera's block poses would. Heights are observed exactly: a
  perception pipeline places a block on what supports it, and a block observed half inside the table
  or floating is not a scene the planner accepts. For the same reason two blocks the noise put into each
  other are moved apart until they touch (`keep_apart`). The world itself is not moved, and the
  kinematic checker takes the orientations from the true scene (they are not in X; a real system would
  estimate them).
- A push: once per run, after the first action, one free block (on the table, nothing on it) is
  moved `push_m` (metres, uniform in the range) in a random horizontal direction, as a person or a
  slipping block would, to a place where it touches no other block. The planner observes it there.

Both draw from one generator seeded per run, so a run is the same for any number of workers. The loop
that runs until the goal is told the noise (`Faults.known_to`), as a cell's calibration would tell it.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from tamp.app.args import metres_below
from tamp.errors import UserError
from tamp.planning.config import LoopConfig
from tamp.planning.vocabulary import BLOCK_SIZES, ON_TABLE

if TYPE_CHECKING:  # the configuration loads no Drake: `tamp evaluate --help` stays fast
    from tamp.sim.skill import Scene

_CLEARANCE = 0.005  # metres: a pushed block's footprint keeps this gap to every other block's
STOP_MARGIN_SIGMAS = 1.0  # the stop margin in sigmas of the observation noise, where the configuration leaves it
LOOKS_UNDER_NOISE = 2  # observations again after a round without a plan, where the configuration leaves them


@dataclass(frozen=True)
class Faults:
    """Disturbances of the world during a closed loop (see the module docstring)."""

    noise_m: float = 0.0  # std of the noise on every observed x and y (0: exact observations)
    push_m: tuple[float, float] | None = None  # (min, max) distance of the one push (None: no push)

    def __post_init__(self) -> None:
        if not 0 <= self.noise_m < 0.05:
            raise UserError(f"the observation noise must be between 0 and 5 cm, got {self.noise_m} m")
        if self.push_m is not None and not 0 < self.push_m[0] <= self.push_m[1] < 0.3:
            raise UserError(f"a push needs 0 < min <= max < 0.3 m, got {self.push_m}")

    @property
    def any(self) -> bool:
        return self.noise_m > 0 or self.push_m is not None

    @property
    def noise_words(self) -> str:
        return f"observations with {self.noise_m * 1000:g} mm noise"

    def describe(self) -> str:
        """The faults in words, as a run will inject them."""
        said = [] if self.noise_m == 0 else [self.noise_words]
        if self.push_m is not None:
            low, high = (f"{v * 100:g}" for v in self.push_m)
            said.append(f"one free block pushed {low if low == high else low + '-' + high} cm after the first action")
        return "; ".join(said) or "none"

    def known_to(self, loop: LoopConfig, cameras: bool = False) -> LoopConfig:
        """`loop` as a closed loop that knows this noise, in the fields the configuration leaves to it (None): it
        stops `STOP_MARGIN_SIGMAS` sigma inside eps (a block's observed distance to its goal scatters by about one
        sigma around the true one), and after a round without a plan it looks again `LOOKS_UNDER_NOISE` times (the
        noise may have put neighbours into each other, so that the kinematic check rejects every action). Without
        noise they are 0: exact observations, where a second look sees the same. With `cameras` (the loop observes
        through the camera rig, `perception.observe`) the noise is the cameras' own: the stop margin stays None,
        for the loop to learn from what it measures (`tamp.app.observation`), and it looks again as under noise."""
        if cameras:
            if self.noise_m > 0:
                raise UserError("--noise adds noise to the truth's observations; with perception.observe = "
                                "\"cameras\" the loop observes through the camera rig, whose noise is its own")
            return loop if loop.looks is not None else replace(loop, looks=LOOKS_UNDER_NOISE)
        noisy = self.noise_m > 0
        if loop.stop_margin is None:
            loop = replace(loop, stop_margin=STOP_MARGIN_SIGMAS * self.noise_m if noisy else 0.0)
        return loop if loop.looks is not None else replace(loop, looks=LOOKS_UNDER_NOISE if noisy else 0)

    def observe(self, X: np.ndarray, rng: np.random.Generator, scene: Scene | None = None) -> np.ndarray:
        """X as the planner observes it: horizontal positions with noise. With the world's `scene`, blocks
        the noise put into each other are moved apart (`keep_apart`)."""
        if self.noise_m <= 0:
            return X
        seen = np.array(X, dtype=float)
        seen[:, :2] += rng.normal(0.0, self.noise_m, size=(len(X), 2))
        return seen if scene is None else keep_apart(seen, scene)


def _push_range(text: str) -> tuple[float, float]:
    """MIN,MAX metres of `--push` (a single value: exactly that far)."""
    parts = text.split(",")
    try:
        low, high = (float(parts[0]), float(parts[-1])) if len(parts) <= 2 else (None, None)
    except ValueError:
        low = high = None
    if low is None or high is None or not 0 < low <= high < 0.3:
        raise argparse.ArgumentTypeError(f"expected MIN,MAX metres with 0 < MIN <= MAX < 0.3, got {text!r}")
    return low, high


def add_fault_arguments(p: argparse.ArgumentParser, which: str) -> None:
    """`--noise` and `--push` (`tamp evaluate`, `tamp plan --replan`); `which`: the loops they disturb, in words."""
    p.add_argument("--noise", type=metres_below(0.05), default=0.0, metavar="METRES",
                   help=f"{which}: Gaussian noise of this standard deviation on every x and y the planner "
                   "observes, as a camera's would (default 0; the world itself is not moved; the loop that runs "
                   "until the goal stops 1 sigma inside eps and looks again twice after a round without a plan, "
                   "unless the configuration sets loop.stop_margin and loop.looks)")
    p.add_argument("--push", type=_push_range, default=None, metavar="MIN,MAX",
                   help=f"{which}: once per problem, after the first action, push one free block MIN-MAX "
                   "metres in a random horizontal direction (e.g. 0.03,0.05), as a person or a slip would; both "
                   "faults are drawn from the problem's seed, so a run is repeatable")


def faults_of(args: argparse.Namespace) -> Faults:
    """The Faults of `add_fault_arguments`' flags."""
    return Faults(noise_m=args.noise, push_m=args.push)


def keep_apart(seen: np.ndarray, scene: Scene, passes: int = 10) -> np.ndarray:
    """The noisy observation `seen` (n, 5) with every two blocks at the same height whose footprints the
    noise made overlap, though they do not overlap in `scene`, moved apart until they touch: half the
    overlap each, along the axis that separates them with the least motion. A perception pipeline knows
    that two blocks cannot share space, as it knows that a block rests on its support."""
    seen = np.array(seen, dtype=float)
    n = scene.n
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n)
             if abs(seen[i, 2] - seen[j, 2]) < 0.04 and _apart(footprint(scene, i), footprint(scene, j), -0.001)]
    for _ in range(passes):
        moved = False
        for i, j in pairs:
            a, b = footprint(scene, i, seen[i, :2]), footprint(scene, j, seen[j, :2])
            axis, overlap = _least_overlap(a, b)
            if overlap > 1e-6:
                seen[i, :2] -= axis * overlap / 2
                seen[j, :2] += axis * overlap / 2
                moved = True
        if not moved:
            break
    return seen


def _least_overlap(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, float]:
    """(unit axis, depth): the edge normal of two convex footprints along which they overlap least, pointing
    from a to b, and that overlap in metres (0 when they are apart)."""
    best: tuple[np.ndarray, float] = (np.zeros(2), np.inf)
    for normal in _edge_normals(a, b):
        pa, pb = a @ normal, b @ normal
        forward, backward = pa.max() - pb.min(), pb.max() - pa.min()  # b beyond a, a beyond b
        depth, axis = (forward, normal) if forward <= backward else (backward, -normal)
        if depth <= 0:
            return np.zeros(2), 0.0
        if depth < best[1]:
            best = (axis, float(depth))
    return best


def footprint(scene: Scene, i: int, at: np.ndarray | None = None) -> np.ndarray:
    """The four (x, y) corners of block i's footprint (metres), in order around it (so that consecutive
    corners make its edges), centred at `at` if given."""
    X_WB = scene.X_WB[i]
    half = np.asarray(BLOCK_SIZES[int(scene.types[i])][:2]) / 2
    R = X_WB.rotation().matrix()[:2, :2]
    centre = X_WB.translation()[:2] if at is None else at
    corners = np.array([[-half[0], -half[1]], [half[0], -half[1]], [half[0], half[1]], [-half[0], half[1]]])
    return centre + corners @ R.T


def _apart(a: np.ndarray, b: np.ndarray, gap: float) -> bool:
    """Whether two convex footprints (corner arrays) are at least `gap` apart along a separating axis."""
    for normal in _edge_normals(a, b):
        pa, pb = a @ normal, b @ normal
        if pa.max() + gap <= pb.min() or pb.max() + gap <= pa.min():
            return True
    return False


def _edge_normals(a: np.ndarray, b: np.ndarray):
    """The unit normals of the edges of two convex footprints: the candidate separating axes."""
    for poly in (a, b):
        for k in range(len(poly)):
            edge = poly[(k + 1) % len(poly)] - poly[k]
            norm = np.linalg.norm(edge)
            if norm > 0:
                yield np.array([-edge[1], edge[0]]) / norm


def push(scene: Scene, faults: Faults, rng: np.random.Generator, tries: int = 32) -> tuple[Scene, str]:
    """The scene after one push (see the module docstring) and what was pushed; the scene unchanged (and
    why) when no free block has room to move."""
    from pydrake.math import RigidTransform

    from tamp.sim.skill import Scene

    assert faults.push_m is not None  # a push was asked for
    n = scene.n
    positions = np.array([p.translation() for p in scene.X_WB])
    free = [i for i in range(n) if positions[i, 2] < ON_TABLE and not any(
        positions[j, 2] > positions[i, 2] + 0.02 and not _apart(footprint(scene, i), footprint(scene, j), 0.0)
        for j in range(n) if j != i)]
    for _ in range(tries):
        if not free:
            break
        i = int(rng.choice(free))
        distance = float(rng.uniform(*faults.push_m))
        angle = float(rng.uniform(0, 2 * np.pi))
        shift = distance * np.array([np.cos(angle), np.sin(angle)])
        moved = footprint(scene, i, positions[i, :2] + shift)
        if all(_apart(moved, footprint(scene, j), _CLEARANCE) for j in range(n) if j != i):
            poses = list(scene.X_WB)
            poses[i] = RigidTransform(poses[i].rotation(), positions[i] + np.array([*shift, 0.0]))
            return Scene(np.array(scene.types), poses), f"block {i} pushed {distance * 100:.1f} cm"
    return scene, "no free block had room to be pushed"


__all__ = ["Faults", "footprint", "keep_apart", "push"]
