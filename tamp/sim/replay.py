"""Self-contained Meshcat HTML replays of the arm and the blocks.

A `Timeline` collects frames (time, arm joints, block poses) while the world steps; `write_html`
plays them through a MeshcatVisualizer recording and saves Meshcat's static HTML, which works
offline in any browser.

A timeline also shows what a camera rig saw (`observed`): at every observation, the fused point cloud and the
perceived blocks (translucent purple boxes, in their estimated poses) beside the true blocks, until the next one.

A timeline can also carry *ghosts*: translucent copies of the blocks at positions that were not
executed, drawn beside the executed blocks (the paper's Fig. 3): the goal, shown throughout, and
the Dynamics Model's prediction after each action, shown from the start of that action until the
next action's prediction replaces it. A timeline is a `WorldObserver`: the world and the executor
report each action's start (`action_started`), which is what ties predictions to the replay's clock.
"""
from __future__ import annotations

import html
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
from pydrake.math import RigidTransform

from tamp.planning.vocabulary import BLOCK_SIZES
from tamp.records import atomic_write_text
from tamp.sim.kinematics import V_MAX, tcp_pose
from tamp.sim.observer import Carried, PhysicsFrame, WorldObserver

REPLAY_FPS = 30.0
_REPLAY_SPEED = 0.5  # fraction of the joint velocity limits used to time kinematic motions
GOAL_RGBA = (0.1, 0.8, 0.2, 0.35)  # translucent green
PREDICTED_RGBA = (1.0, 0.55, 0.0, 0.35)  # translucent orange
PERCEIVED_RGBA = (0.55, 0.2, 0.9, 0.4)  # translucent purple: the blocks a camera rig perceived
CLOUD_RGBA = (0.1, 0.1, 0.1, 1.0)  # the fused point cloud's points
CLOUD_POINT_M = 0.003  # metres: a drawn point's size
GHOST_SCALE = 1.04  # ghosts are slightly larger than the blocks, so that one on a block stays visible
CAMERA_FOV = np.radians(75.0)  # Meshcat's vertical field of view
VIEW_ASPECT = 1.6  # width / height the opening view is framed for (1280 x 800)
VIEW_MARGIN = 0.9  # the framed points fill at most this fraction of the view
# From the blocks toward the camera: beyond the table's far side (+x), to the right and above, so
# that the arm (base at the origin) stands behind the blocks, facing the viewer, without hiding them.
VIEW_DIRECTION = np.array([1.0, -0.5, 0.35]) / np.linalg.norm([1.0, -0.5, 0.35])


def _pose7(X_AB: RigidTransform) -> np.ndarray:
    return np.r_[X_AB.rotation().ToQuaternion().wxyz(), X_AB.translation()]


@dataclass
class Ghosts:
    """Translucent blocks at states that were not executed (goal, predictions), under /ghosts/<name>/.

    `states[i]` (n, 5: x, y, z in metres and the one-hot type; blocks upright and axis-aligned) is
    shown from `times[i]` (seconds of the replay) until `times[i + 1]`, the last one to the end;
    before `times[0]` the ghosts are hidden.
    """

    name: str
    states: np.ndarray  # (m, n, 5)
    times: list[float]
    rgba: tuple[float, float, float, float]
    label: str = ""  # legend text

    def __post_init__(self) -> None:
        self.states = np.asarray(self.states, dtype=float)
        if self.states.ndim != 3 or self.states.shape[2] != 5 or len(self.states) != len(self.times):
            raise ValueError(f"ghosts {self.name!r}: need one (n, 5) state per time, got states of shape "
                             f"{self.states.shape} and {len(self.times)} time(s)")

    def paths(self) -> list[str]:
        return [f"/ghosts/{self.name}/block_{j}" for j in range(self.states.shape[1])]


@dataclass
class Seen:
    """What a camera rig saw at replay time `t` (seconds): the fused cloud and the perceived blocks."""

    t: float
    cloud: np.ndarray  # (k, 3) points in the world, metres
    boxes: list[tuple[int, np.ndarray]]  # each perceived block's type and pose (4, 4) in the world


@dataclass
class Timeline(WorldObserver):
    """Frames of a replay: times (s), arm joints (6,), block poses (n, 7) as quaternion wxyz + xyz.

    Attach it to a world (`world.observer = timeline`) or pass it to an execution to record them."""

    types: np.ndarray | None = None
    times: list[float] = field(default_factory=list)
    q_arm: list[np.ndarray] = field(default_factory=list)
    blocks: list[np.ndarray] = field(default_factory=list)
    action_starts: list[float] = field(default_factory=list)  # seconds: when each executed action began
    ghosts: list[Ghosts] = field(default_factory=list)
    caption: list[str] = field(default_factory=list)  # lines shown over the replay, above the legend
    # a side panel following the timeline: (replay seconds from which it shows, HTML), in time order
    panel: list[tuple[float, str]] = field(default_factory=list)
    seen: list[Seen] = field(default_factory=list)  # what the cameras saw, in time order

    @property
    def t_end(self) -> float:
        return self.times[-1] if self.times else 0.0

    def action_started(self) -> None:
        """Note that an action starts now (its frames follow)."""
        self.action_starts.append(self.t_end)

    def observed(self, cloud: np.ndarray, boxes: list[tuple[int, np.ndarray]]) -> None:
        """A camera rig's observation now: its fused cloud (k, 3) and perceived blocks (type, pose 4x4), shown until
        the next observation (a later one at the same time, a look again, replaces it)."""
        if self.seen and self.seen[-1].t == self.t_end:
            self.seen.pop()
        self.seen.append(Seen(self.t_end, np.asarray(cloud, dtype=float), list(boxes)))

    def show_goal(self, X_goal: np.ndarray) -> None:
        """The goal as translucent green blocks, throughout the replay."""
        self.ghosts.append(Ghosts("goal", np.asarray(X_goal)[None], [0.0], GOAL_RGBA, "goal"))

    def show_predictions(self, predicted: np.ndarray, first_action: int = 0) -> None:
        """The Dynamics Model's rollout of the plan, `predicted` (len + 1, n, 5) with predicted[0] the
        initial state, as translucent orange blocks: predicted[i + 1] from the start of the timeline's
        action `first_action + i`. Call after the actions ran; predictions of actions that never
        started (refinement stopped before them) are not shown."""
        predicted = np.asarray(predicted, dtype=float)
        starts = self.action_starts[first_action:first_action + len(predicted) - 1]
        if starts:
            self.ghosts.append(Ghosts("predicted", predicted[1:len(starts) + 1], list(starts), PREDICTED_RGBA,
                                      "Dynamics Model's prediction after the current action"))

    def show_panel(self, entries: Sequence[tuple[float, str]]) -> None:
        """A side panel that follows the timeline: entry i's HTML is shown from its time (seconds) until
        the next entry's. The page's ``#step=N`` opens the replay at entry N (counted from 0)."""
        self.panel = sorted(entries, key=lambda e: e[0])

    def scene_started(self, scene, q: np.ndarray) -> None:
        """Begin a new scene (a reset); earlier frames are kept and the replay continues."""
        self.types = np.array(scene.types)
        self._add(self.t_end, q, [_pose7(X_WB) for X_WB in scene.X_WB])

    def _add(self, t: float, q: np.ndarray, poses) -> None:
        self.times.append(float(t))
        self.q_arm.append(np.array(q, dtype=float))
        self.blocks.append(np.array(poses, dtype=float))

    def motions_executed(self, paths: Sequence[np.ndarray], X_WB: Sequence[RigidTransform],
                         carried: Carried | None) -> None:
        """Kinematic joint paths, timed at half the joint velocity limits; the carried blocks move
        with the gripper."""
        poses = [_pose7(X_WBi) for X_WBi in X_WB]
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

    def physics_frames(self, frames: Sequence[PhysicsFrame]) -> None:
        """Simulated frames, timed from the end of the replay so far."""
        t0 = self.t_end
        for frame in frames:
            self._add(t0 + frame.t, frame.q, [_pose7(X_WB) for X_WB in frame.X_WB])

    def write_html(self, path: str | Path) -> Path:
        """Render the frames (and ghosts) to a self-contained Meshcat HTML file, written atomically."""
        if not self.times or self.types is None:
            raise ValueError("the timeline is empty: reset and step the world with a timeline attached")
        from pydrake.geometry import Meshcat, MeshcatVisualizer, MeshcatVisualizerParams, Role

        from tamp.sim.plants import build_motion_scene

        scene = build_motion_scene(self.types, padding=0.0)
        plant = scene.plant
        meshcat = Meshcat()
        camera, target = self.camera()
        # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
        meshcat.SetCameraPose(camera_in_world=camera, target_in_world=target)  # type: ignore[arg-type]
        from pydrake.systems.framework import DiagramBuilder

        # A visualizer on the motion scene's scene graph, driven by hand.
        builder = DiagramBuilder()
        builder.AddSystem(scene.diagram)
        params = MeshcatVisualizerParams(role=Role.kIllustration)
        visualizer = MeshcatVisualizer.AddToBuilder(builder, scene.diagram.GetOutputPort("scene_graph_query"),
                                                    meshcat, params)
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
            # (pydrake's stubs type arrays as ndarray[float64[...]], which no array matches)
            plant.SetPositions(plant_ctx, q)  # type: ignore[arg-type]
            visualizer.ForcedPublish(vis_ctx)
        for ghosts in self.ghosts:
            _draw_ghosts(meshcat, recording, ghosts)
        _draw_seen(meshcat, recording, self.seen)
        del robot_ctx, recording
        visualizer.StopRecording()
        visualizer.PublishRecording()
        page = meshcat.StaticHtml()
        if self.ghosts or self.caption or self.seen:
            page = page.replace("</body>", self._overlay() + "</body>", 1)
        if self.panel:
            page = page.replace("</body>", _panel(self.panel) + "</body>", 1)
        return atomic_write_text(path, page)

    def camera(self) -> tuple[np.ndarray, np.ndarray]:
        """The replay's opening view, (camera position, target) in the world, framed on what the
        replay shows: the target is the centre of the box that holds every block (executed, carried
        and ghosts) throughout the replay, and the camera, looking from VIEW_DIRECTION, is as near
        as it can be with that box and the gripper's whole path inside the view."""
        centres = np.concatenate([poses[:, 4:] for poses in self.blocks]
                                 + [g.states[:, :, :3].reshape(-1, 3) for g in self.ghosts])
        assert self.types is not None, "the timeline is empty"
        reach = max(max(BLOCK_SIZES[int(t)]) for t in self.types) / 2  # of a block from its centre
        lo, hi = centres.min(axis=0) - reach, centres.max(axis=0) + reach
        target = (lo + hi) / 2
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        gripper = np.array([tcp_pose(q).translation() for q in self.q_arm])
        d = np.r_[box, gripper] - target
        # In camera coordinates (forward -VIEW_DIRECTION, right, up), a point at depth
        # distance - d.v fits when its offsets stay within tan(fov / 2) of that depth.
        right = np.cross(-VIEW_DIRECTION, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, -VIEW_DIRECTION)
        tan_half = np.tan(CAMERA_FOV / 2) * VIEW_MARGIN
        distance = float(np.max(d @ VIEW_DIRECTION + np.maximum(np.abs(d @ up), np.abs(d @ right) / VIEW_ASPECT)
                                / tan_half))
        return target + distance * VIEW_DIRECTION, target

    def _overlay(self) -> str:
        """A caption and a colour legend in the page's top-left corner."""
        def swatch(rgba) -> str:
            r, g, b, a = rgba
            return (f'<span style="display:inline-block;width:0.9em;height:0.9em;margin-right:0.4em;'
                    f'background:rgba({r * 255:.0f},{g * 255:.0f},{b * 255:.0f},{max(a, 0.6)})"></span>')
        lines = [html.escape(line) for line in self.caption]
        lines.append(swatch((0.85, 0.25, 0.25, 1)) + swatch((0.25, 0.45, 0.85, 1)) + "executed blocks (small, large)")
        seen = set()
        for g in self.ghosts:
            if g.name not in seen:
                seen.add(g.name)
                lines.append(swatch(g.rgba) + html.escape(g.label or g.name) + " (translucent)")
        if self.seen:
            lines.append(swatch(PERCEIVED_RGBA) + swatch(CLOUD_RGBA) + "what the cameras saw: the perceived blocks "
                         "(translucent) and the fused point cloud")
        return ('<div id="tamp-legend" style="position:fixed;left:8px;top:8px;padding:6px 10px;'
                'background:rgba(255,255,255,0.85);font:13px sans-serif;line-height:1.5;border-radius:4px;'
                'pointer-events:none">' + "<br>".join(lines) + "</div>\n")


PANEL_ID = "tamp-steps"
_PANEL_STYLE = ("position:fixed;left:8px;bottom:8px;width:460px;max-width:calc(100vw - 16px);max-height:62vh;"
                "overflow:auto;padding:8px 10px;background:rgba(255,255,255,0.94);font:12px/1.45 sans-serif;"
                "border-radius:4px;box-shadow:0 1px 4px rgba(0,0,0,0.3)")


def _panel(entries: Sequence[tuple[float, str]]) -> str:
    """The panel's element and the script that keeps it on the entry of Meshcat's animation time
    (`viewer.animator.time`, seconds), polled 10 times a second; ``#step=N`` pauses the animation at
    entry N once it is loaded (without WebGL, the page still shows entry N); press play to go on."""
    times = json.dumps([round(float(t), 4) for t, _ in entries])
    pages = json.dumps([text for _, text in entries]).replace("</", "<\\/")
    return (f'<div id="{PANEL_ID}" style="{_PANEL_STYLE}"></div>\n<script>\n(function () {{\n'
            f"const times = {times}, pages = {pages};\n"
            f'const panel = document.getElementById("{PANEL_ID}");\n'
            """const wanted = /[#&]step=(\\d+)/.exec(location.hash);
let pinned = wanted ? Math.min(parseInt(wanted[1], 10), pages.length - 1) : null;
let shown = -1, seeked = false, seekTime = null;
function animator() {
  return (typeof viewer !== "undefined" && viewer.animator && viewer.animator.duration > 0) ? viewer.animator : null;
}
function entryAt(t) {
  let k = 0;
  for (let i = 0; i < times.length; i++) if (times[i] <= t + 1e-6) k = i;
  return k;
}
function tick() {
  const a = animator();
  if (a !== null && pinned !== null && !seeked) {
    a.pause(); a.seek(times[pinned] + 0.01); a.display_progress(times[pinned] + 0.01);
    seeked = true; seekTime = a.time;
  }
  let k = pinned === null ? 0 : pinned;
  if (a !== null && (pinned === null || a.time !== seekTime)) { pinned = null; k = entryAt(a.time); }
  if (k !== shown) { shown = k; panel.innerHTML = pages[k]; panel.dataset.entry = String(k); }
}
tick();
setInterval(tick, 100);
})();
</script>
""")


def _draw_ghosts(meshcat, recording, ghosts: Ghosts) -> None:
    """Translucent boxes for `ghosts`, their poses (and visibility) keyed into the recording."""
    from pydrake.geometry import Box, Rgba

    frames = [recording.frame(t) for t in ghosts.times]
    for j, path in enumerate(ghosts.paths()):
        kind = int(np.argmax(ghosts.states[0, j, 3:]))
        meshcat.SetObject(path, Box(*(GHOST_SCALE * np.array(BLOCK_SIZES[kind]))), Rgba(*ghosts.rgba))
        poses = [RigidTransform(state[j, :3]) for state in ghosts.states]
        meshcat.SetTransform(path, poses[0])
        if frames[0] > 0:
            recording.SetProperty(0, path, "visible", False)
            recording.SetProperty(frames[0] - 1, path, "visible", False)
        recording.SetProperty(frames[0], path, "visible", True)
        for i, (frame, X_WGhost) in enumerate(zip(frames, poses)):
            if i > 0 and frame > frames[i - 1]:
                recording.SetTransform(frame - 1, path, poses[i - 1])  # hold, then jump (no sliding)
            recording.SetTransform(frame, path, X_WGhost)


def _draw_seen(meshcat, recording, seen: Sequence[Seen]) -> None:
    """Each observation's cloud and boxes under /perception/<k>/, visible from its time until the next one's."""
    from pydrake.geometry import Box, Rgba
    from pydrake.perception import PointCloud

    frames = [recording.frame(s.t) for s in seen]
    for k, (s, frame) in enumerate(zip(seen, frames)):
        until = frames[k + 1] if k + 1 < len(seen) else None
        cloud = PointCloud(len(s.cloud))
        cloud.mutable_xyzs()[:] = s.cloud.T
        paths = [f"/perception/{k}/cloud"]
        meshcat.SetObject(paths[0], cloud, CLOUD_POINT_M, Rgba(*CLOUD_RGBA))
        for j, (block_type, X_WB) in enumerate(s.boxes):
            path = f"/perception/{k}/block_{j}"
            meshcat.SetObject(path, Box(*BLOCK_SIZES[int(block_type)]), Rgba(*PERCEIVED_RGBA))
            meshcat.SetTransform(path, RigidTransform(np.asarray(X_WB)))  # type: ignore[arg-type]  # pydrake stubs
            paths.append(path)
        for path in paths:
            meshcat.SetProperty(path, "visible", frame == 0)
            if frame > 0:
                recording.SetProperty(0, path, "visible", False)
                recording.SetProperty(frame - 1, path, "visible", False)
            recording.SetProperty(frame, path, "visible", True)
            if until is not None and until > frame:
                recording.SetProperty(until, path, "visible", False)


def _position_layout(scene):
    plant = scene.plant
    arm_idx = np.array([plant.get_joint(j).position_start() for j in plant.GetJointIndices(scene.arm)
                        if plant.get_joint(j).num_positions() == 1])
    block_starts = [plant.get_body(plant.GetBodyIndices(b)[0]).floating_positions_start() for b in scene.blocks]
    return arm_idx, block_starts

