"""Replays: the frames a watched world records, and the written page."""
import numpy as np
import pytest

from tamp.planning.structs import PickPlace
from tamp.sim import World, WorldConfig
from tamp.sim.observer import WorldObserver
from tamp.sim.replay import Timeline

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


# Recorded on the code before the world reported to observers (commit ba65fe6): the frames of a
# replay must not change when the way they reach the timeline does.
@pytest.mark.parametrize("fidelity, frames, t_end, starts, sum_t", [
    ("fast", 106, 3.294273, [0.0, 2.213091], 184.3453),
    ("full", 276, 9.003462, [0.0, 5.236486], 1241.2748),
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
