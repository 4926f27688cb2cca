"""The Dynamics Model corrected by a closed loop's misses (`tamp.planning.experience`), and the loop that uses it."""
from __future__ import annotations

import numpy as np

from tamp.planning.closed_loop import plan_closed_loop
from tamp.planning.config import LoopConfig, PlanConfig
from tamp.planning.experience import Experienced, Miss, experienced
from tamp.planning.models import Models
from tests.planning_stubs import StubModel, two_block_domain, world_step

X = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])  # A on the table, B beside it
A_ON_B = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
A_BESIDE_B = np.array([[0.76, 0.1, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])  # where A falls when released on B
ON = (0, 0, 1, 0)  # A picked at its centre, released on B's centre


def test_a_miss_corrects_the_same_action_wherever_the_picked_block_starts():
    stub = StubModel()
    miss = Miss.of(stub, X, ON, A_BESIDE_B)
    assert np.isclose(miss.distance, 0.05 * np.sqrt(1 + 1.2 ** 2))  # A landed 6 cm along x and 5 cm lower
    model = Experienced(stub, [miss], within=0.02)
    elsewhere = X.copy()
    elsewhere[0, :2] = (0.4, -0.2)  # A starts elsewhere, B where it was: A ends beside B again
    for start in (X, elsewhere):
        e = model.predict_effect(start, [ON, (0, 0, 1, 1)])
        assert np.allclose(start[:, :3] + e[0], A_BESIDE_B[:, :3])
        assert np.allclose(e[1], stub.predict_effect(start, [(0, 0, 1, 1)])[0])  # another action: the model's
    assert np.allclose(model.predict_effects(np.stack([X, elsewhere]), np.array([ON, ON])),
                       np.stack([model.predict_effect(X, [ON])[0], model.predict_effect(elsewhere, [ON])[0]]))


def test_a_miss_does_not_correct_a_scene_whose_other_blocks_moved():
    stub = StubModel()
    model = Experienced(stub, [Miss.of(stub, X, ON, A_BESIDE_B)], within=0.02)
    moved = X.copy()
    moved[1, 0] += 0.03  # B 3 cm from where it was
    assert np.allclose(model.predict_effect(moved, [ON]), stub.predict_effect(moved, [ON]))
    assert experienced(stub, [], 0.02) is stub


def test_the_latest_miss_of_an_action_decides():
    stub = StubModel()
    first, then = A_BESIDE_B.copy(), A_BESIDE_B.copy()
    then[0, 0] = 0.64  # the second time A fell to B's other side
    model = Experienced(stub, [Miss.of(stub, X, ON, first), Miss.of(stub, X, ON, then)], within=0.02)
    assert np.allclose(X[:, :3] + model.predict_effect(X, [ON])[0], then[:, :3])


def tipping_world():
    """The stub world in which A released on B's centre falls beside it, wherever A came from."""
    def step(action):
        step.X = A_BESIDE_B if tuple(action) == ON else world_step(step.X, action)
        return step.X
    step.X = X
    return step


def test_the_loop_does_not_plan_a_step_it_saw_miss_again():
    """Released on B, A falls beside it: the loop that learns from the miss reaches A on B another way (offset
    onto B, then shifted back); the loop with the model as trained sends the same action until its budget."""
    stub = StubModel()
    models = Models(dynamics=stub, symbolic=stub, domain=two_block_domain())
    runs = {learn: plan_closed_loop("bilevel", models, X, A_ON_B, tipping_world(), rounds=None,
                                    cfg=PlanConfig(loop=LoopConfig(learn_misses=learn, max_actions=6)))
            for learn in (LoopConfig.learn_misses, None)}
    learned, trained = runs[LoopConfig.learn_misses], runs[None]
    assert learned.success and [tuple(int(v) for v in a) for a in learned.executed].count(ON) == 1
    assert not trained.success and trained.stop == "budget"
    assert all(tuple(int(v) for v in a) == ON for a in trained.executed)
