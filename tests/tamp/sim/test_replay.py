"""Replays: the frames a watched world records, and the written page."""
import numpy as np
import pytest

from tamp.planning.vocabulary import PickPlace
from tamp.sim import World, WorldConfig
from tamp.sim.observer import WorldObserver
from tamp.sim.replay import Timeline

pytestmark = pytest.mark.sim  # every test here builds Drake plants

SMALL, LARGE = [1.0, 0.0], [0.0, 1.0]
X_TWO = np.array([[0.6, 0.15, 0.025] + SMALL, [0.7, -0.1, 0.025] + LARGE])
PLAN = [PickPlace(0, 0, 1, 0), PickPlace(1, 1, 1, -1)]  # the cube onto the bar, then the bar with it on


def watched_run(fidelity: str) -> Timeline:
    world = World(WorldConfig(fidelity=fidelity), seed=0)
    timeline = Timeline()
    world.observer = timeline
    world.reset(X=X_TWO)
    for action in PLAN:
        assert world.step(action)[1].status == "ok"
    return timeline


# Recorded on the code before the world reported to observers (commit ba65fe6; the full fidelity's
# again when the arm came to dwell 0.25 s at each place pose before releasing): the frames of a
# replay must not change when the way they reach the timeline does.
@pytest.mark.parametrize("fidelity, frames, t_end, starts, sum_t", [
    ("fast", 106, 3.294273, [0.0, 2.213091], 184.3453),
    ("full", 290, 9.503462, [0.0, 5.486486], 1374.6615),
])
def test_a_watched_world_records_the_same_frames(fidelity, frames, t_end, starts, sum_t):
    timeline = watched_run(fidelity)
    assert len(timeline.times) == len(timeline.q_arm) == len(timeline.blocks) == frames
    assert timeline.t_end == pytest.approx(t_end, abs=1e-6)
    assert timeline.action_starts == pytest.approx(starts, abs=1e-6)
    assert sum(timeline.times) == pytest.approx(sum_t, abs=1e-3)
    assert np.all(np.diff(timeline.times) >= 0)  # (each full-fidelity action restarts at the last frame's time)
    assert timeline.blocks[0].shape == (2, 7)


class EventLog(WorldObserver):
    """The names of the events a world reports, in order."""

    def __init__(self):
        self.events = []

    def scene_started(self, scene, q):
        self.events.append("scene")

    def action_started(self):
        self.events.append("action")

    def motions_executed(self, paths, X_WB, carried):
        self.events.append("carry" if carried is not None else "move")

    def physics_frames(self, frames):
        assert frames and all(b.t > a.t for a, b in zip(frames, frames[1:]))
        self.events.append("physics")


def test_the_world_reports_scenes_actions_motions_and_physics_to_its_observer():
    log = EventLog()
    world = World(WorldConfig(), seed=0, observer=log)
    world.reset(X=X_TWO)
    assert world.step(PickPlace(0, 0, 1, 0))[1].status == "ok"
    assert log.events == ["scene", "action", "move", "carry", "physics", "move"]
    log.events.clear()
    world.reset(X=np.r_[X_TWO, [[1.6, 0.0, 0.025] + SMALL]])
    assert world.step(PickPlace(2, 0, 0, 0))[1].status == "ik_failure"  # out of reach: changes nothing
    assert log.events == ["scene"]
    world.observer = None  # nobody watches
    world.reset(X=X_TWO)
    world.step(PickPlace(0, 0, 1, 0))
    assert log.events == ["scene"]


def test_the_world_knows_observers_not_replays():
    import ast

    import tamp.sim.world as world_module

    tree = ast.parse(open(world_module.__file__).read())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    assert "tamp.sim.observer" in imported and "tamp.sim.replay" not in imported


def _camera_in_page(html: str) -> tuple[np.ndarray, np.ndarray]:
    """(camera position, target) in the world from a static Meshcat page's commands (msgpack,
    three.js y-up coordinates: x, z, -y)."""
    import base64
    import re
    import struct

    raw = b"".join(base64.b64decode(b) for b in re.findall(r'base64,([A-Za-z0-9+/=]+)"', html))
    xyz = rb"\x93\xcb(.{8})\xcb(.{8})\xcb(.{8})"
    position = re.findall(rb"/Cameras/default/rotated/<object>\xa8property\xa8position\xa5value" + xyz, raw, re.S)
    target = re.findall(rb"set_target\xa5value" + xyz, raw, re.S)
    assert len(position) == len(target) == 1
    p, t = ([struct.unpack(">d", v)[0] for v in found[0]] for found in (position, target))
    return np.array([p[0], -p[2], p[1]]), np.array([t[0], -t[2], t[1]])


def _pixels(camera, target, points, width=1280, height=800):
    """Pinhole projection of world points into a width x height view of Meshcat's 75-degree camera."""
    forward = (target - camera) / np.linalg.norm(target - camera)
    right = np.cross(forward, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = np.asarray(points) - camera
    scale = height / 2 / np.tan(np.radians(75.0) / 2)
    return np.c_[width / 2 + scale * (d @ right) / (d @ forward), height / 2 - scale * (d @ up) / (d @ forward)]


def test_the_replay_opens_framed_on_the_blocks_and_the_arm(tmp_path):
    from tamp.sim.kinematics import tcp_pose

    timeline = watched_run("fast")
    camera, target = _camera_in_page(timeline.write_html(tmp_path / "replay.html").read_text())
    np.testing.assert_allclose(np.c_[camera, target], np.c_[timeline.camera()], atol=1e-9)
    centres = np.concatenate([poses[:, 4:] for poses in timeline.blocks])
    reach = 0.125  # half a bar
    np.testing.assert_allclose(target, (centres.min(axis=0) + centres.max(axis=0)) / 2, atol=1e-9)
    assert np.linalg.norm(camera - target) < 1.0
    # Everything the replay shows is in view: the blocks, the gripper's path, the arm's base...
    gripper = [tcp_pose(q).translation() for q in timeline.q_arm]
    px = _pixels(camera, target, np.r_[centres, gripper, [[0.0, 0.0, 0.0]]])
    assert np.all((px >= 0) & (px <= [1280, 800]))
    # ...and the blocks are large in it: a 5 cm cube is over 20 px wide (about 15 px from the fixed
    # camera 1.75 m away this replaced; here about 25 px, the arm's home pose keeping the camera
    # back), and the blocks' box spans a third of the view's width.
    cube = timeline.blocks[0][0, 4:]
    assert np.ptp(_pixels(camera, target, [cube - [0, 0.025, 0], cube + [0, 0.025, 0]])[:, 0]) > 20
    lo, hi = centres.min(axis=0) - reach, centres.max(axis=0) + reach
    box = [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
    assert np.ptp(_pixels(camera, target, box)[:, 0]) > 1280 / 3
