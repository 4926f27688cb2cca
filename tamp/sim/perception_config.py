"""Plain data of the camera rig and its depth sensors: the `[perception]` section of the configuration file.

A camera is described as Drake's `CameraConfig` describes one (name, pose, image size, field of view, depth
range), its pose given as a position and a point it looks at. The rig's four slots are the cameras of a real
cell: one above the table, one in front (opposite the arm) and one on each side; a slot can be switched off.
Lengths are metres, angles degrees where the name says so. Importing this module loads no Drake, so that
`tamp config show` stays fast.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from tamp.errors import UserError

RIG_SLOTS = ("above", "front", "left", "right")  # PerceptionConfig's cameras, in the order they are rendered
OBSERVE = ("truth", "cameras")  # PerceptionConfig.observe: what the closed loops observe


@dataclass(frozen=True)
class CameraConfig:
    """One fixed RGB-D camera (Drake's `CameraConfig` fields that matter here)."""

    on: bool = True  # rendered and used by perception
    position: tuple[float, float, float] = (0.65, 0.0, 1.1)  # metres: the camera's optical centre in the world
    target: tuple[float, float, float] = (0.65, 0.0, 0.0)  # metres: the point it looks at (sets X_WC)
    width: int = 640  # pixels
    height: int = 480  # pixels
    fov_y_deg: float = 45.0  # vertical field of view, as a D415-like sensor's depth stream
    depth_m: tuple[float, float] = (0.2, 2.5)  # metres: nearer or farther returns no depth (a real sensor's range)

    def __post_init__(self) -> None:
        if not (16 <= self.width <= 4096 and 16 <= self.height <= 4096):
            raise UserError(f"a camera image must be 16..4096 pixels wide and high, got {self.width}x{self.height}")
        if not 5.0 <= self.fov_y_deg <= 150.0:
            raise UserError(f"a camera's fov_y_deg must be in [5, 150] degrees, got {self.fov_y_deg}")
        if not 0.01 <= self.depth_m[0] < self.depth_m[1] <= 20.0:
            raise UserError(f"a camera's depth_m must be (near, far) with 0.01 <= near < far <= 20, got {self.depth_m}")
        gaze = [t - p for t, p in zip(self.target, self.position)]
        if sum(g * g for g in gaze) < 1e-6:
            raise UserError(f"a camera's target must differ from its position, got {self.position} for both")


@dataclass(frozen=True)
class DepthNoise:
    """A stereo depth sensor's errors (see tamp/sim/cameras.py `noisy_depth`)."""

    on: bool = True  # off: the rendered depth as it is (tests)
    sigma_at_1m: float = 0.0015  # metres of depth noise at 1 m; it grows as z^2 (a D415's RMS at 1 m)
    grazing_deg: float = 75.0  # surfaces seen more obliquely than this return nothing more and more often
    edge_m: float = 0.01  # a pixel whose neighbours' depth differs by more than this is a depth edge
    edge_dropout: float = 0.5  # probability that a depth-edge pixel returns nothing (stereo fails at edges)

    def __post_init__(self) -> None:
        if not 0.0 <= self.sigma_at_1m <= 0.05:
            raise UserError(f"perception.noise.sigma_at_1m must be in [0, 0.05] m, got {self.sigma_at_1m}")
        if not 0.0 < self.grazing_deg <= 90.0 or not 0.0 <= self.edge_dropout <= 1.0 or self.edge_m <= 0:
            raise UserError("perception.noise: grazing_deg must be in (0, 90], edge_dropout in [0, 1], edge_m > 0")


@dataclass(frozen=True)
class PerceptionConfig:
    """What the closed loops observe; the camera rig, its sensors' noise and the point cloud's resolution."""

    observe: str = "truth"  # what the closed loops observe: "truth" (the simulator's poses) or "cameras" (this rig)
    voxel_m: float = 0.004  # metres: the fused cloud is averaged in cubes of this size (bounds the pipeline's time)
    noise: DepthNoise = DepthNoise()  # every camera's sensor errors
    above: CameraConfig = CameraConfig()  # 1.1 m over the middle of the workspace, looking straight down
    front: CameraConfig = CameraConfig(position=(1.45, 0.0, 0.75))  # opposite the arm, looking down at 43 degrees
    left: CameraConfig = CameraConfig(position=(0.65, 0.85, 0.75))  # beside the workspace, looking down at 41 degrees
    right: CameraConfig = CameraConfig(position=(0.65, -0.85, 0.75))  # the other side

    def __post_init__(self) -> None:
        if self.observe not in OBSERVE:
            raise UserError(f"perception.observe must be one of {', '.join(OBSERVE)}, got {self.observe!r}")
        if not 0.001 <= self.voxel_m <= 0.01:
            raise UserError(f"perception.voxel_m must be in [0.001, 0.01] m, got {self.voxel_m}")
        if not self.cameras():
            raise UserError("perception: at least one camera of the rig must be on")

    def cameras(self) -> list[tuple[str, CameraConfig]]:
        """The rig's cameras that are on, by slot name."""
        return [(slot, camera) for slot in RIG_SLOTS if (camera := getattr(self, slot)).on]

    def with_cameras(self, *slots: str) -> PerceptionConfig:
        """This configuration with only the cameras of `slots` on."""
        return dataclasses.replace(self, **{slot: dataclasses.replace(getattr(self, slot), on=slot in slots)
                                            for slot in RIG_SLOTS})

    @property
    def cameras_on(self) -> bool:
        """Whether the closed loops observe through the cameras (`observe`)."""
        return self.observe == "cameras"

    def without_noise(self) -> PerceptionConfig:
        return dataclasses.replace(self, noise=dataclasses.replace(self.noise, on=False))


__all__ = ["CameraConfig", "DepthNoise", "OBSERVE", "PerceptionConfig", "RIG_SLOTS"]
