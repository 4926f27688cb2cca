"""The camera rig: fixed RGB-D cameras rendered by Drake (`RgbdSensor`, `RenderEngineVtk`) and their depth noise.

    rig = CameraRig(PerceptionConfig())
    views = rig.observe(scene, rng)          # one noisy DepthView per camera that is on
    seen = perceive(views, rig.config)       # tamp.sim.perception: the blocks from the depth images

The rig's diagram (table, a pool of MAX_OBJECTS cubes and MAX_OBJECTS bars, one sensor per camera) is built
once and kept warm: a scene is rendered by setting its blocks' poses in the one context (the pool's unused
blocks parked under the table, where no camera sees them). The first frame costs about 0.5 s (VTK's start),
each later observation of four 640x480 depth images about 25 ms. The arm is not in the rig's world yet.
"""
from __future__ import annotations

import numpy as np
from pydrake.geometry import (
    ClippingRange,
    DepthRange,
    DepthRenderCamera,
    MakeRenderEngineVtk,
    RenderCameraCore,
    RenderEngineVtkParams,
)
from pydrake.math import RigidTransform, RotationMatrix
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.sensors import CameraInfo, RgbdSensor

from tamp.planning.validate import MAX_OBJECTS
from tamp.planning.vocabulary import LARGE, SMALL
from tamp.sim.perception_config import CameraConfig, DepthNoise, PerceptionConfig
from tamp.sim.plants import TABLE_FILE, add_blocks
from tamp.sim.point_cloud import DepthView
from tamp.sim.skill import Scene

RENDERER = "vtk"
_PARKED_Z = -1.0  # metres: unused pool blocks rest this far under the table top, hidden from every camera


def X_WC_looking_at(position, target) -> RigidTransform:
    """The pose of a Drake camera frame (+z forward, +x right, +y down in the image) at `position` looking at
    `target` (metres), its image upright (+x horizontal)."""
    p, t = np.asarray(position, float), np.asarray(target, float)
    z = (t - p) / np.linalg.norm(t - p)
    up = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.99 else np.array([1.0, 0.0, 0.0])  # looking straight down
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    R = RotationMatrix(np.column_stack([x, np.cross(z, x), z]))
    return RigidTransform(R, p)  # type: ignore[arg-type]  # pydrake's stubs type vectors as ndarray[float64[3, 1]]


def depth_camera(camera: CameraConfig) -> DepthRenderCamera:
    """The Drake depth camera of a CameraConfig (clipping a little inside the depth range)."""
    info = CameraInfo(camera.width, camera.height, np.deg2rad(camera.fov_y_deg))
    near, far = camera.depth_m
    core = RenderCameraCore(RENDERER, info, ClippingRange(near * 0.5, far * 1.2), RigidTransform())
    return DepthRenderCamera(core, DepthRange(near, far))


def noisy_depth(depth: np.ndarray, intrinsics: tuple[float, float, float, float], noise: DepthNoise,
                rng: np.random.Generator) -> np.ndarray:
    """`depth` (H, W metres, inf where nothing returns) as a stereo sensor measures it: Gaussian noise of
    sigma_at_1m * z^2, no return where a surface is seen more obliquely than grazing_deg (with a probability
    rising from 0 at grazing_deg - 15 degrees to 1 at grazing_deg), and none, with probability edge_dropout,
    at a depth edge (a 4-neighbour more than edge_m away)."""
    fx, fy, cx, cy = intrinsics
    h, w = depth.shape
    depth = depth.astype(np.float32)
    finite = np.isfinite(depth) & (depth > 0)  # Drake: 0 too near, inf too far
    z = np.where(finite, depth, np.float32(0.0))
    x_ray = ((np.arange(w) - cx) / fx).astype(np.float32)[None, :]
    y_ray = ((np.arange(h) - cy) / fy).astype(np.float32)[:, None]
    # the surface's tangents along the image (forward differences of p = z * ray) and the angle of its normal
    # to the ray
    z_u, z_v = np.zeros_like(z), np.zeros_like(z)
    z_u[:, :-1], z_v[:-1] = np.diff(z, axis=1), np.diff(z, axis=0)
    t_u = (z_u * x_ray + z / fx, z_u * y_ray, z_u)
    t_v = (z_v * x_ray, z_v * y_ray + z / fy, z_v)
    normal = (t_u[1] * t_v[2] - t_u[2] * t_v[1], t_u[2] * t_v[0] - t_u[0] * t_v[2], t_u[0] * t_v[1] - t_u[1] * t_v[0])
    along = np.abs(normal[0] * x_ray + normal[1] * y_ray + normal[2])
    norms = np.sqrt(normal[0] ** 2 + normal[1] ** 2 + normal[2] ** 2) * np.sqrt(x_ray ** 2 + y_ray ** 2 + 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        angle = np.degrees(np.arccos(np.clip(along / norms, 0.0, 1.0)))
    p_drop = np.clip((np.nan_to_num(angle, nan=90.0) - (noise.grazing_deg - 15.0)) / 15.0, 0.0, 1.0)
    padded = np.pad(np.where(finite, depth, np.float32(np.inf)), 1, mode="edge")
    jump = np.zeros(depth.shape, dtype=bool)
    for dv, du in ((0, 1), (2, 1), (1, 0), (1, 2)):  # the 4-neighbours
        with np.errstate(invalid="ignore"):
            jump |= ~(np.abs(padded[dv:dv + h, du:du + w] - depth) <= noise.edge_m)  # inf beside a return: an edge
    p_drop = np.where(jump, np.maximum(p_drop, noise.edge_dropout), p_drop)
    sigma = np.float32(noise.sigma_at_1m) * z * z
    measured = depth + rng.standard_normal(depth.shape, dtype=np.float32) * sigma
    return np.where(finite & (rng.random(depth.shape, dtype=np.float32) >= p_drop), measured, np.float32(np.inf))


class CameraRig:
    """The cameras of `config` around the table, rendering block scenes (see the module docstring)."""

    def __init__(self, config: PerceptionConfig | None = None) -> None:
        self.config = config or PerceptionConfig()
        builder = DiagramBuilder()
        self.plant, self.scene_graph = AddMultibodyPlantSceneGraph(builder, 0.0)
        parser = Parser(self.plant)
        (table,) = parser.AddModels(TABLE_FILE)
        self.plant.WeldFrames(self.plant.world_frame(), self.plant.GetFrameByName("table_top", table))
        pool = add_blocks(parser, np.array([SMALL] * MAX_OBJECTS + [LARGE] * MAX_OBJECTS))
        self.plant.Finalize()
        self._pool = {SMALL: [self._body(b) for b in pool[:MAX_OBJECTS]],
                      LARGE: [self._body(b) for b in pool[MAX_OBJECTS:]]}
        self.scene_graph.AddRenderer(RENDERER, MakeRenderEngineVtk(RenderEngineVtkParams()))
        self.sensors: list[tuple[str, RgbdSensor, np.ndarray, tuple[float, float, float, float]]] = []
        for name, camera in self.config.cameras():
            X_WC = X_WC_looking_at(camera.position, camera.target)
            render_camera = depth_camera(camera)
            sensor = RgbdSensor(self.scene_graph.world_frame_id(), X_WC, render_camera)
            builder.AddSystem(sensor)
            builder.Connect(self.scene_graph.get_query_output_port(), sensor.query_object_input_port())
            info = render_camera.core().intrinsics()
            intrinsics = (info.focal_x(), info.focal_y(), info.center_x() - 0.5, info.center_y() - 0.5)
            self.sensors.append((name, sensor, np.asarray(X_WC.GetAsMatrix4()), intrinsics))
        self.diagram: Diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self._plant_context = self.plant.GetMyMutableContextFromRoot(self.context)

    def _body(self, instance):
        return self.plant.get_body(self.plant.GetBodyIndices(instance)[0])

    def set_scene(self, scene: Scene) -> None:
        """Pose the pool's blocks as `scene`'s (types and poses); the rest go under the table."""
        used = {SMALL: 0, LARGE: 0}
        for t, X_WB in zip(scene.types, scene.X_WB):
            self.plant.SetFreeBodyPose(self._plant_context, self._pool[int(t)][used[int(t)]], X_WB)
            used[int(t)] += 1
        for t, bodies in self._pool.items():
            for k, body in enumerate(bodies[used[t]:], start=used[t]):
                parked = RigidTransform([0.3 * k - 1.5, 0.3 * t, _PARKED_Z])  # type: ignore[call-overload]
                self.plant.SetFreeBodyPose(self._plant_context, body, parked)

    def render(self, scene: Scene) -> list[DepthView]:
        """Each camera's depth image of `scene`, as rendered (no noise)."""
        self.set_scene(scene)
        views = []
        for name, sensor, X_WC, intrinsics in self.sensors:
            image = sensor.depth_image_32F_output_port().Eval(sensor.GetMyContextFromRoot(self.context))
            depth = np.array(image.data, dtype=np.float32)[:, :, 0]  # type: ignore[attr-defined]  # an ImageDepth32F
            views.append(DepthView(name, depth, intrinsics, X_WC))
        return views

    def observe(self, scene: Scene, rng: np.random.Generator) -> list[DepthView]:
        """Each camera's depth image of `scene` as the sensor measures it (`noisy_depth`, unless noise is off)."""
        return self.measured(self.render(scene), rng)

    def measured(self, views: list[DepthView], rng: np.random.Generator) -> list[DepthView]:
        """Rendered `views` with the sensor's noise (`noisy_depth`), or as they are when the noise is off."""
        noise = self.config.noise
        if not noise.on:
            return views
        return [DepthView(v.name, noisy_depth(v.depth, v.intrinsics, noise, rng), v.intrinsics, v.X_WC)
                for v in views]


__all__ = ["CameraRig", "X_WC_looking_at", "depth_camera", "noisy_depth"]
