"""Replays: the frames a watched world records, and the written page."""
import numpy as np
import pytest

from tamp.planning.structs import PickPlace
from tamp.sim import World, WorldConfig
from tamp.sim.replay import Timeline

SMALL, LARGE = [1.0, 0.0], [0.0, 1.0]
X_TWO = np.array([[0.6, 0.15, 0.025] + SMALL, [0.7, -0.1, 0.025] + LARGE])
PLAN = [PickPlace(0, 0, 1, 0), PickPlace(1, 1, 1, -1)]  # the cube onto the bar, then the bar with it on


def watched_run(fidelity: str) -> Timeline:
    world = World(WorldConfig(fidelity=fidelity), seed=0)
    timeline = Timeline()
    world.timeline = timeline
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
