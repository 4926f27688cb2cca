"""The loop's experience: an executed action the Dynamics Model missed is predicted as the world did it."""
from __future__ import annotations

import numpy as np

from tamp.planning import closed_loop
from tamp.planning.closed_loop import plan_closed_loop
from tamp.planning.experience import Experience, Experienced, remembers
from tamp.planning.models import Models
from tests.planning_stubs import StubModel, world_step
from tests.tamp.planning.test_closed_loop import AcceptAll

A_ON_MIDDLE = (0, 0, 1, 0)  # cube A released on the middle of bar B
X0 = np.array([[0.6, -0.1, 0.025, 1, 0], [0.7, 0.1, 0.025, 0, 1]])  # A a cube, B a bar along y
GOAL = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 0, 1]])  # A on the middle of B
SLID = np.array([0.78, 0.1, 0.025])  # where A lands when released on B's middle in the world below


def sliding_world():
    """The stub world, except that A released on the middle of B slides off B's side to SLID."""
    def step(action):
        X = world_step(step.X, action)
        if tuple(action) == A_ON_MIDDLE:
            X = step.X.copy()
            X[0, :3] = SLID
        step.X = X
        return X
    step.X = X0
    return step


def slid(X: np.ndarray) -> np.ndarray:
    X = X.copy()
    X[0, :3] = SLID
    return X


def test_a_miss_is_predicted_as_the_world_did_it_from_wherever_the_picked_block_starts():
    stub = StubModel()
    experience = Experience(within=0.02, alike=1)
    assert experience.over(stub) is stub  # nothing missed: the plain model
    assert experience.remember(stub, X0, A_ON_MIDDLE, slid(X0)) is not None
    model = experience.over(stub)
    elsewhere = X0.copy()
    elsewhere[0, :2] = (0.5, -0.3)  # A starts 22 cm away: it is carried, its start decides nothing
    for X in (X0, elsewhere):
        landed = X[:, :3] + model.predict_effect(X, [A_ON_MIDDLE])[0]
        np.testing.assert_allclose(landed, slid(X)[:, :3], atol=1e-9)
    # another action, or B 3 cm from where it was: the plain model's prediction
    other = (0, 0, 1, 1)
    np.testing.assert_allclose(model.predict_effect(X0, [other]), stub.predict_effect(X0, [other]))
    moved = X0.copy()
    moved[1, 0] += 0.03
    np.testing.assert_allclose(model.predict_effect(moved, [A_ON_MIDDLE]), stub.predict_effect(moved, [A_ON_MIDDLE]))
    # batched queries agree with single ones
    both = np.stack([X0, moved])
    actions = np.array([A_ON_MIDDLE, A_ON_MIDDLE])
    np.testing.assert_allclose(model.predict_effects(both, actions)[0], model.predict_effect(X0, [A_ON_MIDDLE])[0])
    np.testing.assert_allclose(model.predict_effects(both, actions)[1], stub.predict_effect(moved, [A_ON_MIDDLE])[0])
    dist = model.distribution(both, actions)
    np.testing.assert_allclose(dist.mean, model.predict_effects(both, actions))


def test_only_misses_are_remembered_and_a_shift_depends_on_where_the_block_is():
    stub = StubModel()
    experience = Experience(within=0.02, alike=1)
    shift = (0, 0, 0, 1)  # A placed 7.5 cm along y from where it is
    as_predicted = world_step(X0, shift)
    nearly = as_predicted.copy()
    nearly[0, 0] += 0.015
    assert experience.remember(stub, X0, shift, nearly) is None and not experience.misses  # 1.5 cm: no miss
    off = as_predicted.copy()
    off[0, 0] += 0.04
    assert experience.remember(stub, X0, shift, off) is not None
    model = experience.over(stub)
    np.testing.assert_allclose(X0[:, :3] + model.predict_effect(X0, [shift])[0], off[:, :3], atol=1e-9)
    elsewhere = X0.copy()
    elsewhere[0, 1] -= 0.1  # placed relative to itself: where A is decides, so the miss does not speak here
    np.testing.assert_allclose(model.predict_effect(elsewhere, [shift]), stub.predict_effect(elsewhere, [shift]))
    # the same action missed again, as the corrected model predicts it: nothing new to remember
    assert experience.remember(stub, X0, shift, off) is None and len(experience.misses) == 1


def test_a_miss_is_trusted_once_the_world_repeats_it_and_until_it_does_otherwise():
    stub = StubModel()
    experience = Experience(within=0.02)  # alike = 2, the loop's default
    elsewhere = X0.copy()
    elsewhere[0, :2] = (0.5, -0.3)
    first = experience.remember(stub, X0, A_ON_MIDDLE, slid(X0))
    assert first is not None and not experience.trusts(first) and experience.over(stub) is stub  # once: scatter?
    again = experience.remember(stub, elsewhere, A_ON_MIDDLE, slid(elsewhere))  # the same landing from elsewhere
    assert experience.trusts(again)
    model = experience.over(stub)
    np.testing.assert_allclose(X0[:, :3] + model.predict_effect(X0, [A_ON_MIDDLE])[0], slid(X0)[:, :3], atol=1e-9)
    # the world does otherwise there (A stays on B as the model said): the miss is scatter, no longer trusted
    stayed = world_step(X0, A_ON_MIDDLE)
    assert experience.remember(stub, X0, A_ON_MIDDLE, stayed) is not None
    assert not experience.trusted and experience.over(stub) is stub
    # two different misses are not alike: neither is trusted
    other = Experience(within=0.02)
    far = slid(X0)
    far[0, 1] += 0.1
    other.remember(stub, X0, A_ON_MIDDLE, slid(X0))
    other.remember(stub, elsewhere, A_ON_MIDDLE, far)
    assert len(other.misses) == 2 and not other.trusted


def test_a_plan_on_course_is_no_longer_kept_by_its_own_prediction_through_a_remembered_miss():
    stub = StubModel()
    experience = Experience(within=0.02, alike=1)
    experience.remember(stub, X0, A_ON_MIDDLE, slid(X0))
    trajectory = np.stack([X0, world_step(X0, A_ON_MIDDLE)])
    assert remembers(Experienced(stub, experience), trajectory, [A_ON_MIDDLE])
    assert not remembers(Experienced(stub, experience), trajectory, [(0, 0, 1, 1)])
    assert not remembers(stub, trajectory, [A_ON_MIDDLE])  # a model without experience


def test_the_loop_does_not_try_a_missed_action_again_while_another_way_reaches_the_goal(monkeypatch):
    models = Models(dynamics=StubModel())
    with monkeypatch.context() as m:
        m.setattr(closed_loop, "REMEMBER_ALIKE", 10**6)  # no miss trusted
        forgetful = plan_closed_loop("cfs", models, X0, GOAL, sliding_world(), rounds=None, kinematics=AcceptAll())
    # without experience: back on the middle from each new place of A, until the actions run out
    assert not forgetful.success and [tuple(a) for a in forgetful.executed].count(A_ON_MIDDLE) >= 4
    out = plan_closed_loop("cfs", models, X0, GOAL, sliding_world(), rounds=None, kinematics=AcceptAll())
    assert out.success and [tuple(a) for a in out.executed].count(A_ON_MIDDLE) == 2  # the second landed alike
    assert out.experience is not None and [m.action for m in out.experience.trusted] == [A_ON_MIDDLE]
    assert len(out.executed) == 4  # the middle twice, then onto B's end and shifted along B to its middle
    said = "remembered: pick 0 at +0, place on 1 at +0 landed"
    assert any(reason.startswith(said) for reason in out.rounds[2].reasons)
    # what the loop expected of each step: A on B's middle twice (it slid), then each step as expected
    landed = [np.linalg.norm(X[:, :3] - e, axis=1).max() for X, e in zip(out.states[1:], out.expected)]
    assert len(out.expected) == 4 and min(landed[:2]) > 0.05 and max(landed[2:]) < 1e-9
