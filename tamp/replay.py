"""Self-contained Meshcat HTML replays of the arm and the blocks.

A `Timeline` collects frames (time, arm joints, block poses) while the world steps; `write_html`
plays them through a MeshcatVisualizer recording and saves Meshcat's static HTML, which works
offline in any browser.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform

from tamp.kinematics import V_MAX, tcp_pose

REPLAY_FPS = 30.0
_REPLAY_SPEED = 0.5  # fraction of the joint velocity limits used to time kinematic motions


def _pose7(X: RigidTransform) -> np.ndarray:
    return np.r_[X.rotation().ToQuaternion().wxyz(), X.translation()]


@dataclass
class Timeline:
    """Frames of a replay: times (s), arm joints (6,), block poses (n, 7) as quaternion wxyz + xyz."""

    types: np.ndarray | None = None
    times: list[float] = field(default_factory=list)
    q_arm: list[np.ndarray] = field(default_factory=list)
    blocks: list[np.ndarray] = field(default_factory=list)

    @property
    def t_end(self) -> float:
        return self.times[-1] if self.times else 0.0

    def start(self, scene, q: np.ndarray) -> None:
        """Begin a new scene (a reset); earlier frames are kept and the replay continues."""
        self.types = np.array(scene.types)
        self._add(self.t_end, q, [_pose7(X) for X in scene.X_WB])

    def _add(self, t: float, q: np.ndarray, poses) -> None:
        self.times.append(float(t))
        self.q_arm.append(np.array(q, dtype=float))
        self.blocks.append(np.array(poses, dtype=float))

    def add_motions(self, paths: list[np.ndarray], X_WB: list[RigidTransform], carried) -> None:
        """Kinematic joint paths, timed at half the joint velocity limits; `carried` is
        (block indices, their poses in the tcp frame) for blocks moving with the gripper."""
        poses = [_pose7(X) for X in X_WB]
        for path in paths:
            for a, b in zip(path[:-1], path[1:]):
                duration = max(float(np.max(np.abs(b - a) / (_REPLAY_SPEED * V_MAX))), 1.0 / REPLAY_FPS)
                t0 = self.t_end
                for s in np.linspace(0.0, 1.0, max(2, int(duration * REPLAY_FPS) + 1))[1:]:
                    q = a + s * (b - a)
                    frame = list(poses)
                    if carried is not None:
                        X_WG = tcp_pose(q)
                        for c, X_GC in zip(*carried):
                            frame[c] = _pose7(X_WG @ X_GC)
                    self._add(t0 + s * duration, q, frame)

    def add_physics(self, record: list, q_arm: np.ndarray) -> None:
        """Settling frames from BlockPhysics.settle(record=...), the arm still."""
        t0 = self.t_end
        for t, poses in record:
            self._add(t0 + t, q_arm, [_pose7(X) for X in poses])

    def write_html(self, path: str | Path) -> Path:
        """Render the frames to a self-contained Meshcat HTML file."""
        if not self.times or self.types is None:
            raise ValueError("the timeline is empty: reset and step the world with a timeline attached")
        from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role

        from tamp.plants import build_motion_scene

        scene = build_motion_scene(self.types, padding=0.0)
        plant = scene.plant
        meshcat = Meshcat()
        meshcat.SetCameraPose(camera_in_world=[1.7, -1.1, 0.9], target_in_world=[0.6, 0.0, 0.1])
        from pydrake.systems.framework import DiagramBuilder

        # A visualizer on the motion scene's scene graph, driven by hand.
        builder = DiagramBuilder()
        builder.AddSystem(scene.diagram)
        params = MeshcatVisualizerParams(role=Role.kIllustration)
        visualizer = MeshcatVisualizer.AddToBuilder(builder, scene.diagram.GetOutputPort("scene_graph_query"), meshcat, params)
        diagram = builder.Build()
        context = diagram.CreateDefaultContext()
        robot_ctx = scene.diagram.GetMyMutableContextFromRoot(context)
        plant_ctx = scene.plant.GetMyMutableContextFromRoot(context)
        vis_ctx = visualizer.GetMyContextFromRoot(context)
        planner_idx = _position_layout(scene)
        recording = visualizer.StartRecording(False)
        q = np.zeros(plant.num_positions())
        for t, q_arm, poses in zip(self.times, self.q_arm, self.blocks):
            context.SetTime(t)
            q[planner_idx[0]] = q_arm
            for i, s in enumerate(planner_idx[1]):
                q[s:s + 7] = poses[i]
            plant.SetPositions(plant_ctx, q)
            visualizer.ForcedPublish(vis_ctx)
        del robot_ctx, recording
        visualizer.StopRecording()
        visualizer.PublishRecording()
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(meshcat.StaticHtml())
        return path


def _position_layout(scene):
    plant = scene.plant
    arm_idx = np.array([plant.get_joint(j).position_start() for j in plant.GetJointIndices(scene.arm)
                        if plant.get_joint(j).num_positions() == 1])
    block_starts = [plant.get_body(plant.GetBodyIndices(b)[0]).floating_positions_start() for b in scene.blocks]
    return arm_idx, block_starts
