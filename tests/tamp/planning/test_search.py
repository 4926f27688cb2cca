"""Continuous forward search: pruning, batched vs unbatched successor prediction, limits."""
from __future__ import annotations

import numpy as np
import pytest

from tamp.errors import UserError
from tamp.planning import search
from tamp.planning.config import PlanConfig
from tamp.planning.pruning import goal_oriented_actions
from tamp.planning.search import SearchConfig, continuous_search
from tamp.planning.verify import VerifyConfig, goal_error, rollout
from tests.planning_stubs import StubModel, world_step

# three blocks: a large bar 0 and small cubes 1, 2
X = np.array([[0.55, -0.15, 0.025, 0, 1], [0.7, 0.1, 0.025, 1, 0], [0.8, -0.2, 0.025, 1, 0]])


def goal_after(actions):
    G = X
    for a in actions:
        G = world_step(G, a)
    return G


def test_goal_oriented_pruning_follows_the_paper():
    G = goal_after([(1, 0, 2, 0)])  # cube 1 onto cube 2: only object 1 is misplaced
    acts = goal_oriented_actions(X, G, release_targets=False)
    assert np.array_equal(acts, goal_oriented_actions(X, G))  # the closest object has the closest release point
    assert len(acts) == 18
    assert set(map(tuple, acts[:9])) == {(1, g, 2, r) for g in (-1, 0, 1) for r in (-1, 0, 1)}  # closest to its goal
    assert set(map(tuple, acts[9:])) == {(1, g, 1, r) for g in (-1, 0, 1) for r in (-1, 0, 1)}  # itself
    # only heights differ (2-D positions right): the 3-D misplaced objects get actions
    H = X.copy()
    H[1, 2] = 0.125
    assert set(goal_oriented_actions(X, H)[:, 0]) == {1}
    assert len(goal_oriented_actions(X, X)) == 0


def test_release_point_targets_reach_a_goal_beside_another_block():
    # cube 1's goal is on bar 0 at release offset +1 (7.5 cm along +y of its centre), but cube 2 is
    # closer to it (6.9 cm): the paper's rule offers only cube 2 and cube 1 itself as targets
    Y = np.array([[0.55, -0.15, 0.025, 0, 1], [0.8, 0.1, 0.025, 1, 0], [0.61, -0.04, 0.025, 1, 0]])
    G = world_step(Y, (1, 0, 0, 1))
    paper = goal_oriented_actions(Y, G, release_targets=False)
    assert set(paper[:, 2]) == {2, 1}
    ours = goal_oriented_actions(Y, G)
    assert len(ours) == 27 and set(ours[:, 2]) == {2, 0, 1}
    # so the search finds the one-action plan that the paper's pruning cannot
    assert continuous_search(StubModel(), Y, G).plan == [(1, 0, 0, 1)]
    assert continuous_search(StubModel(), Y, G, SearchConfig(release_targets=False, max_depth=1)).plan is None


def test_a_goal_on_a_stack_offers_the_top_of_the_stack():
    # cube 1 stands on cube 2, 5 mm off its centre; cube 0's goal is on top of them, above cube 2's centre: the
    # object closest in 2-D is the bottom of the stack, the one a placed block rests on is its top
    Y = np.array([[0.55, -0.15, 0.025, 1, 0], [0.705, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
    G = Y.copy()
    G[0, :3] = (0.7, 0.1, 0.125)
    assert set(goal_oriented_actions(Y, G, release_targets=False)[:, 2]) == {2, 0}  # the paper's rule
    ours = goal_oriented_actions(Y, G)
    assert len(ours) == 27 and set(ours[:, 2]) == {2, 1, 0}
    # a goal on the table offers what it did: the closest object and itself
    G[0, :3] = (0.7, 0.16, 0.025)
    assert set(goal_oriented_actions(Y, G)[:, 2]) == {2, 0}


def test_a_goal_on_the_end_of_a_raised_bar_offers_that_bar():
    # bar 2 lies on bar 1, 7.5 cm along it; bar 0's goal is on bar 2's end, right above bar 1's centre: the object
    # closest in 2-D and the one closest to the place below the goal is bar 1, 5 cm lower, which the goal does not
    # rest on; the bar at the level below the goal, whose release point +1 is the goal, is offered too
    Y = np.array([[0.61, -0.12, 0.025, 0, 1], [0.776, 0.189, 0.025, 0, 1], [0.776, 0.114, 0.075, 0, 1]])
    G = Y.copy()
    G[0, :3] = (0.776, 0.189, 0.125)
    ours = goal_oriented_actions(Y, G)
    assert set(ours[:, 2]) == {1, 2, 0}
    assert (0, 0, 2, 1) in {tuple(a) for a in ours.tolist()}


@pytest.mark.parametrize("plan", [[(1, 0, 2, 0)], [(1, 0, 2, 0), (0, -1, 0, 1)],
                                  [(2, 0, 0, 1), (1, 0, 2, 0), (0, 1, 0, -1)]])
def test_search_finds_plans_that_reach_the_goal(plan):
    G = goal_after(plan)
    result = continuous_search(StubModel(), X, G)
    assert result.solved, result.reason
    assert len(result.plan) <= len(plan)
    assert goal_error(goal_after(result.plan), G) < 0.05
    assert np.allclose(result.trajectory, rollout(StubModel(), X, result.plan))


def test_batched_and_unbatched_prediction_give_the_same_search():
    G = goal_after([(2, 0, 0, 1), (1, 0, 2, 0), (0, 1, 0, -1)])
    stubs = {True: StubModel(), False: StubModel()}
    out = {b: continuous_search(stubs[b], X, G, batched=b) for b in (True, False)}
    assert out[True].solved
    for f in ("plan", "status", "expanded", "generated", "duplicates"):
        assert getattr(out[True], f) == getattr(out[False], f), f
    assert np.array_equal(out[True].trajectory, out[False].trajectory)
    # one call per expansion vs one per successor
    assert out[True].predict_calls == stubs[True].calls == out[True].expanded
    assert out[False].predict_calls == stubs[False].calls == out[True].generated > out[True].expanded


def test_batched_equals_unbatched_with_a_real_effect_model():
    torch = pytest.importorskip("torch")
    from learned import EffectModel, ModelConfig

    torch.manual_seed(0)
    model = EffectModel(ModelConfig(n_max=4)).eval()
    G = rollout(model, X, [(1, 0, 2, 0), (0, 0, 0, 1)])[-1]  # reachable under this model
    cfg = SearchConfig(max_expansions=200)
    a, b = (continuous_search(model, X, G, cfg, batched=m) for m in (True, False))
    assert a.solved and a.plan == b.plan and a.expanded == b.expanded and a.generated == b.generated
    assert np.allclose(a.trajectory, b.trajectory, atol=1e-6)


def test_depth_limit_and_exhaustion_are_reported():
    G = goal_after([(2, 0, 0, 1), (1, 0, 2, 0)])
    out = continuous_search(StubModel(), X, G, SearchConfig(max_depth=1))
    assert not out.solved and out.status == "exhausted" and "within 1 actions" in out.reason
    assert continuous_search(StubModel(), X, X).plan == []
    with pytest.raises(ValueError, match="must both be"):
        continuous_search(StubModel(), X, X[:2])


def test_a_search_on_a_plateau_stops_after_stall_expansions_and_keeps_its_closest_state():
    X4 = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0], [0.8, -0.2, 0.025, 1, 0], [0.5, 0.3, 0.025, 0, 1]])
    G = X4.copy()
    G[0, :2] = (1.0, 0.5)  # on the table within reach, but no pick-place of the stub world puts the cube there
    budget = continuous_search(StubModel(), X4, G, SearchConfig(max_expansions=300, stall=None))
    assert budget.status == "node_limit" and budget.expanded == 300
    stalled = continuous_search(StubModel(), X4, G, SearchConfig(max_expansions=300, stall=25))
    assert stalled.status == "stalled" and stalled.expanded < 300 and "no state closer" in stalled.reason
    # the cut comes `stall` expansions after the closest state was expanded (the same search up to there),
    # and a closed loop may still step toward that state
    assert stalled.closest_plan
    first = continuous_search(StubModel(), X4, G, SearchConfig(max_expansions=stalled.expanded - 25, stall=None))
    assert first.closest_plan == stalled.closest_plan
    with pytest.raises(UserError, match="stall"):
        SearchConfig(stall=0)
    with pytest.raises(UserError, match="greedy_stall"):
        SearchConfig(greedy_stall=0)


def test_from_greedy_from_blocks_on_greedy_stall_is_the_stall_cut():
    """Below greedy_from blocks `stall` decides (off by default), from greedy_from on `greedy_stall` does."""
    X4 = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0], [0.8, -0.2, 0.025, 1, 0], [0.5, 0.3, 0.025, 0, 1]])
    G = X4.copy()
    G[0, :2] = (1.0, 0.5)  # unreachable by the stub world's actions: every search plateaus
    below = continuous_search(StubModel(), X4, G, SearchConfig(max_expansions=120, greedy_from=5, greedy_stall=25))
    assert below.status == "node_limit" and below.expanded == 120
    greedy = continuous_search(StubModel(), X4, G, SearchConfig(max_expansions=120, greedy_from=4, greedy_stall=25))
    assert greedy.status == "stalled" and greedy.expanded < 120 and "in 25 expansions" in greedy.reason
    assert continuous_search(StubModel(), X4, G, SearchConfig(max_expansions=120, greedy_from=4, greedy_stall=None,
                                                              stall=25)).status == "node_limit"


def test_a_search_that_must_avoid_an_infeasible_action_finds_another_plan():
    G = goal_after([(1, 0, 2, 0)])  # cube 1 onto cube 2: one action away
    assert continuous_search(StubModel(), X, G).plan == [(1, 0, 2, 0)]

    def feasible(X_pred, action):  # the kinematic check says the direct action is infeasible
        return "collision" if tuple(action) == (1, 0, 2, 0) else None

    out = continuous_search(StubModel(), X, G, feasible=feasible)
    assert out.solved and (1, 0, 2, 0) not in out.plan
    assert out.rejected["collision"] >= 1
    assert goal_error(rollout(StubModel(), X, out.plan)[-1], G) < out_eps()
    # a (state, action) pair known to fail refinement is never generated
    from tamp.planning.search import state_key

    pruned = {(state_key(X, SearchConfig().resolution), (1, 0, 2, 0))}
    again = continuous_search(StubModel(), X, G, pruned=pruned)
    assert again.solved and again.plan[0] != (1, 0, 2, 0) and again.pruned >= 1


def test_goal_states_reached_only_by_rejected_actions_are_counted_and_said():
    """A goal the model reaches only by actions the kinematic check rejects is not a search that came close: the
    result counts those goal states, its closest state is one the check let through, and the reason says both."""
    G = goal_after([(1, 0, 2, 0)])
    from tamp.planning.verify import goal_errors

    def feasible(X_pred, action):  # every action into a goal state is blocked
        after = world_step(X_pred, action)
        return "collision" if goal_errors(after, G).max() < out_eps() else None

    out = continuous_search(StubModel(), X, G, SearchConfig(max_expansions=40), feasible=feasible)
    assert not out.solved and out.plan is None
    assert out.goals_rejected >= 1 and out.rejected_goal_error < 0.01  # the direct action lands on the goal
    assert out.best_error >= out_eps()
    assert f"{out.goals_rejected} goal state" in out.reason and "kinematic check rejects" in out.reason
    free = continuous_search(StubModel(), X, G, SearchConfig(max_expansions=40))
    assert free.solved and free.goals_rejected == 0


def out_eps() -> float:
    return VerifyConfig().eps


class BiasedModel(StubModel):
    """The stub dynamics, but picking object 0 in the scene X with one of `biased` is predicted to
    leave it 4 cm off along x: a goal state within eps (5 cm), not within `confident` (3 cm)."""

    def __init__(self, biased):
        super().__init__()
        self.biased = {tuple(a) for a in biased}

    def predict_effect(self, X_, actions):
        e = super().predict_effect(X_, actions)
        if np.allclose(X_, X):
            for b, a in enumerate(np.asarray(actions).reshape(-1, 4).tolist()):
                if tuple(a) in self.biased:
                    e[b, 0, 0] += 0.04
        return e


def test_a_goal_state_predicted_4_cm_off_waits_for_a_closer_one_of_the_same_length():
    G = goal_after([(0, 0, 0, 1)])  # the bar shifted 7.5 cm along y on itself
    assert goal_error(goal_after([(0, -1, 0, 0)]), G) < 1e-9  # picked at -1, released at 0: the same shift
    model = BiasedModel([(0, -1, 0, 0)])  # generated first, predicted 4 cm off
    first = continuous_search(model, X, G, SearchConfig(look_on=0))
    assert first.plan == [(0, -1, 0, 0)]
    closer = continuous_search(model, X, G)
    assert closer.solved and closer.plan == [(0, 0, 0, 1)]
    assert goal_error(closer.trajectory[-1], G) < VerifyConfig().confident


def test_a_shorter_plan_predicted_4_cm_off_beats_longer_exact_ones():
    G = goal_after([(0, 0, 0, 1)])
    every_first_move_of_the_bar = [(0, g, j, r) for g in (-1, 0, 1) for j in range(3) for r in (-1, 0, 1)]
    out = continuous_search(BiasedModel(every_first_move_of_the_bar), X, G)
    assert out.solved and len(out.plan) == 1
    assert 0.03 < goal_error(out.trajectory[-1], G) < 0.05
    with pytest.raises(ValueError, match="confident"):
        VerifyConfig(confident=0.06)


def test_the_papers_pruning_rule_is_a_setting():
    from guarded.config import parse_toml
    from tamp.planning.config import overlay

    assert PlanConfig().search.release_targets
    assert not overlay(PlanConfig(), parse_toml("[search]\nrelease_targets = false", "c"), "c").search.release_targets


class DoubtfulModel(StubModel):
    """The stub dynamics as an ensemble that doubts `doubtful` actions: there its predicted variance is
    (5 cm)^2 per axis (`learned.ensemble.distribution_of` reads `predict_gaussian`)."""

    def __init__(self, doubtful):
        super().__init__()
        self.doubtful = {tuple(a) for a in doubtful}

    def predict_gaussian(self, Xs, actions):
        actions = np.asarray(actions, dtype=np.int64).reshape(-1, 4)
        mean = np.stack([self.predict_effect(X, a[None])[0] for X, a in zip(Xs, actions)])
        var = np.zeros_like(mean)
        for b, a in enumerate(actions.tolist()):
            if tuple(a) in self.doubtful:
                var[b] = 0.05 ** 2
        return mean, var


def test_a_goal_state_the_model_doubts_waits_for_one_it_does_not():
    from tamp.planning.verify import doubt

    G = goal_after([(0, 0, 0, 1)])
    model = DoubtfulModel([(0, -1, 0, 0)])  # generated first, exact, but the model doubts it
    states = rollout(model, X, [(0, -1, 0, 0)])
    assert doubt(model, states, [(0, -1, 0, 0)]) > 0.1 and doubt(model, states, [(0, 0, 0, 1)]) == 0.0
    assert doubt(StubModel(), states, [(0, -1, 0, 0)]) == 0.0  # a model without spread doubts nothing
    blind = continuous_search(model, X, G, SearchConfig())
    assert blind.plan == [(0, -1, 0, 0)]
    sure = continuous_search(model, X, G, SearchConfig(max_doubt=0.03))
    assert sure.solved and sure.plan == [(0, 0, 0, 1)]
    # when the model doubts every goal state, the search still returns the best of them after looking on
    every = DoubtfulModel([(0, g, j, r) for g in (-1, 0, 1) for j in range(3) for r in (-1, 0, 1)])
    only = continuous_search(every, X, G, SearchConfig(max_depth=1, max_doubt=0.03))
    assert only.solved and len(only.plan) == 1 and "95 % bound" in only.reason
    with pytest.raises(ValueError, match="max_doubt"):
        SearchConfig(max_doubt=0.0)


def test_actions_whose_grasp_cannot_hold_the_block_are_never_predicted():
    G = goal_after([(1, 0, 2, 0)])  # cube 1 onto cube 2
    seen = []

    class Recording(StubModel):
        def predict_effect(self, X_, actions):
            seen.extend(map(tuple, np.asarray(actions)))
            return super().predict_effect(X_, actions)

    graspable = np.ones((3, 3), dtype=bool)
    graspable[1:, [0, 2]] = False  # the cubes only at their centre, as the kinematic check says
    out = continuous_search(Recording(), X, G, graspable=graspable)
    assert out.plan == [(1, 0, 2, 0)]
    assert seen and all(a[1] == 0 for a in seen if a[0] in (1, 2))
    assert out.ungraspable == 12  # of cube 1's 18 actions (onto cube 2 and itself), 6 grasp its centre
    # a plan that needs a grasp the mask forbids is not found
    assert continuous_search(StubModel(), X, G, SearchConfig(max_depth=1),
                             graspable=np.zeros((3, 3), dtype=bool)).plan is None


def test_from_greedy_from_blocks_on_h_counts_in_its_own_unit(monkeypatch):
    """With many blocks a search in the paper's units (h in metres) is nearly breadth-first: counting h in
    half metres from `greedy_from` blocks on reaches a deep goal after fewer expansions; below it, nothing changes."""
    X5 = np.array([[0.5, -0.2, 0.025, 1, 0], [0.6, 0.1, 0.025, 1, 0], [0.7, -0.1, 0.025, 1, 0],
                   [0.8, 0.2, 0.025, 1, 0], [0.55, 0.3, 0.025, 0, 1]])
    G = X5
    for action in [(0, 0, 1, 0), (2, 0, 3, 0), (4, 0, 4, 1)]:
        G = world_step(G, action)
    paper = continuous_search(StubModel(), X5, G, SearchConfig(greedy_from=None))
    below = continuous_search(StubModel(), X5, G, SearchConfig(greedy_from=6))
    greedy = continuous_search(StubModel(), X5, G, SearchConfig(greedy_from=5))
    assert paper.solved and greedy.solved
    assert (below.plan, below.expanded) == (paper.plan, paper.expanded)
    assert greedy.expanded < paper.expanded
    # counting the blocks still off their goal too: at most as many expansions as the distance alone
    monkeypatch.setattr(search, "GREEDY_PER_MISPLACED", 0.0)
    alone = continuous_search(StubModel(), X5, G, SearchConfig(greedy_from=5))
    assert greedy.expanded <= alone.expanded
    with pytest.raises(UserError, match="greedy_from"):
        SearchConfig(greedy_from=0)
