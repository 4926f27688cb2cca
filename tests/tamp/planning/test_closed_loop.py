"""The closed loop that does not know k: it goes on until the goal, plans again when a plan ends
short, widens its search when a round finds nothing, and stops at its action budget. Stub models and
the stub world (no Drake, no torch model)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from tamp.errors import UserError
from tamp.planning import closed_loop, config
from tamp.planning.closed_loop import plan_closed_loop
from tamp.planning.config import LoopConfig, PlanConfig
from tamp.planning.models import Models
from tamp.planning.planners import plan
from tamp.planning.results import PlanResult
from tamp.planning.verify import goal_error
from tamp.planning.vocabulary import Infeasible
from tests.planning_stubs import StubModel, two_block_domain, world_step

X_INIT = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
A_ON_B = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])


@pytest.fixture(scope="module")
def models() -> Models:
    stub = StubModel()
    return Models(dynamics=stub, symbolic=stub, domain=two_block_domain())


def slipping_world(slips: int):
    """The stub world whose first `slips` actions grasp nothing (the blocks stay where they are)."""
    sent: list = []

    def step(action):
        sent.append(tuple(action))
        X = step.X
        step.X = X if len(sent) <= slips else world_step(X, action)
        return step.X
    step.X = X_INIT
    return step


def forget(monkeypatch) -> None:
    """The loop trusts no miss it remembers (closed_loop.REMEMBER_ALIKE out of reach)."""
    monkeypatch.setattr(closed_loop, "REMEMBER_ALIKE", 10**6)


def test_the_loop_goes_on_after_the_rounds_the_paper_would_give(models, monkeypatch):
    # a goal of k = 1 action: the paper's loop has k - 1 = 0 rounds, one plan executed to its end
    paper = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(2), rounds=0)
    assert not paper.success and paper.stop == "rounds" and len(paper.executed) == 1
    # (the two slips alike would be trusted as what the world does: `test_experience` has that; here the world
    #   does as predicted the third time)
    forget(monkeypatch)
    goal = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(2), rounds=None)
    assert goal.success and goal.stop == "goal" and len(goal.executed) == 3
    assert len(goal.rounds) == 3  # one action per round: a plan that ended short is followed by a round


def test_the_loop_stops_at_its_action_budget(models):
    cfg = PlanConfig(loop=LoopConfig(max_actions=4))
    out = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(100), rounds=None, cfg=cfg)
    assert not out.success and out.stop == "budget" and len(out.executed) == 4
    assert "4 actions sent" in out.reason


def test_the_action_budget_does_not_steer_the_loop_before_it_is_reached(models, monkeypatch):
    # --max-actions is a user's bound: a loop that reaches the goal within it acts and reasons as with any larger one
    forget(monkeypatch)
    forgetful = LoopConfig()
    runs = {cap: plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(2), rounds=None,
                                  cfg=PlanConfig(loop=replace(forgetful, max_actions=cap))) for cap in (3, 4, 30)}
    assert all(r.success and r.stop == "goal" for r in runs.values())
    assert runs[3].executed == runs[4].executed == runs[30].executed and len(runs[3].executed) == 3
    assert [r.reasons for r in runs[3].rounds] == [r.reasons for r in runs[30].rounds]
    short = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(2), rounds=None,
                             cfg=PlanConfig(loop=replace(forgetful, max_actions=2)))
    assert short.stop == "budget" and short.executed == runs[30].executed[:2]


def test_the_loop_stops_when_its_rounds_have_spent_its_search_budget(models, monkeypatch):
    cfg = PlanConfig(loop=LoopConfig(search_budget=3))
    out = plan_closed_loop("cfs", models, X_INIT, A_ON_B, slipping_world(100), rounds=None, cfg=cfg)
    spent = sum(r.search.expanded for r in out.rounds)
    assert out.stop == "budget" and "search budget" in out.reason and spent >= 3 and len(out.executed) < 12
    assert all(r.search.expanded <= 3 for r in out.rounds)  # no round searches past what the budget had left
    # from the search's greedy_from blocks on, GREEDY_SEARCH_BUDGET is the budget instead (if smaller)
    assert LoopConfig().search_budget_for(5, 5) == config.GREEDY_SEARCH_BUDGET < LoopConfig().search_budget
    monkeypatch.setattr(config, "GREEDY_SEARCH_BUDGET", 3)
    greedy = PlanConfig(search=replace(PlanConfig().search, greedy_from=len(X_INIT)),
                        loop=LoopConfig(search_budget=1000))
    out = plan_closed_loop("cfs", models, X_INIT, A_ON_B, slipping_world(100), rounds=None, cfg=greedy)
    assert out.stop == "budget" and all(r.search.expanded <= 3 for r in out.rounds)
    assert LoopConfig().search_budget_for(len(X_INIT), len(X_INIT) + 1) == 3000


def test_a_round_without_a_plan_widens_the_search_to_every_action(models):
    def planner_without_plans(method, models_, X, X_goal, cfg, **kwargs):
        result = PlanResult(method, None)
        result.reasons.append("level 2: exhausted (a stub that never plans)")
        result.timings["total"] = 0.001
        return result

    out = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=None,
                           planner=planner_without_plans)
    assert out.success and out.rounds[0].widened and out.rounds[0].origin == "widened search"
    assert out.rounds[0].search is not None and out.rounds[0].timings["planned"] == pytest.approx(0.001)
    assert out.rounds[0].reasons[0] == "level 2: exhausted (a stub that never plans)"
    narrow = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=None,
                              planner=planner_without_plans, cfg=PlanConfig(loop=LoopConfig(widen=False)))
    assert not narrow.success and narrow.stop == "no_plan" and not narrow.executed
    # the paper's loop never widens
    paper = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=3,
                             planner=planner_without_plans)
    assert paper.stop == "no_plan" and not paper.rounds[0].widened


def test_an_empty_plan_while_a_block_is_off_its_goal_widens_the_search(models):
    def planner_empty(method, models_, X, X_goal, cfg, **kwargs):
        result = PlanResult(method, [], level=1, predicted=np.asarray(X)[None])
        result.timings["total"] = 0.0
        return result

    out = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=None, planner=planner_empty)
    assert out.success and out.rounds[0].widened
    assert out.rounds[0].reasons[0] == "the planner returned an empty plan with a block off its goal"


class RejectGoalMoves:
    """A kinematic check that rejects every action onto the other block: no plan can put A on B, and the
    widened search finds none either; only shifts of a block on itself are left."""

    def graspable(self, X):
        return np.ones((len(X), 3), dtype=bool)

    def check(self, X, actions):
        return [Infeasible.COLLISION if a[0] != a[2] else None for a in np.asarray(actions)]

    def refine(self, actions, trajectory, grid_m):
        raise AssertionError("nothing to refine: no plan passes the check")


def test_the_loop_says_why_it_stopped_when_no_action_is_left(models):
    out = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=None,
                           kinematics=RejectGoalMoves())
    assert not out.success and out.stop == "no_plan" and out.rounds[-1].widened
    assert "no plan over every action either" in out.reason


class RejectInNoisyScene:
    """A kinematic check that rejects every action in scenes where block A is observed 3 mm off its place (as
    observation noise may put neighbours into each other) and none elsewhere."""

    def graspable(self, X):
        return np.ones((len(X), 3), dtype=bool)

    def check(self, X, actions):
        noisy = abs(float(X[0, 0]) - NOISY[0, 0]) < 1e-9
        return [Infeasible.COLLISION if noisy else None for _ in np.asarray(actions)]

    def refine(self, actions, trajectory, grid_m):
        from tamp.planning.vocabulary import RefinementOutcome

        return RefinementOutcome()


NOISY = X_INIT + np.array([[0.003, 0.0, 0.0, 0, 0], [0.0, 0.0, 0.0, 0, 0]])


def test_a_round_without_a_plan_under_noise_looks_again_before_the_loop_stops(models):
    """Noise may put neighbours into each other so that the check rejects every action; the loop with looks left
    observes the scene again (without acting) and plans from that, and says so; without looks it stops."""
    looked = []

    def look():
        looked.append(1)
        return X_INIT.copy()

    def run(looks: int):
        looked.clear()
        return plan_closed_loop("bilevel", models, NOISY, A_ON_B, slipping_world(0), rounds=None, look=look,
                                kinematics=RejectInNoisyScene(), cfg=PlanConfig(loop=LoopConfig(looks=looks)))

    once = run(1)
    assert once.success and once.stop == "goal" and len(looked) == 1 and len(once.executed) == 1
    assert not once.rounds[0].solved and "observed again (1 of 1)" in once.rounds[1].reasons[0]
    assert np.allclose(once.states[0], X_INIT)  # the action started from the state seen again
    never = run(0)
    assert never.stop == "no_plan" and not looked and not never.executed
    with pytest.raises(UserError, match="looks"):
        LoopConfig(looks=-1)


def test_with_a_stop_margin_the_loop_does_not_stop_on_an_observation_just_inside_eps(models):
    # the first placement lands A 4.5 cm off along x: within eps (5 cm), not within eps less a 1 cm margin
    def near_miss(action):
        X = world_step(near_miss.X, action)
        if not near_miss.sent:
            X[0, 0] += 0.045
        near_miss.sent.append(tuple(action))
        near_miss.X = X
        return X

    def run(margin: float, planner=None):
        near_miss.X, near_miss.sent = X_INIT, []
        return plan_closed_loop("bilevel", models, X_INIT, A_ON_B, near_miss, rounds=None, planner=planner,
                                cfg=PlanConfig(loop=LoopConfig(stop_margin=margin)))

    exact = run(0.0)
    assert exact.stop == "goal" and len(exact.executed) == 1 and 0.04 < goal_error(exact.X_final, A_ON_B) < 0.05
    careful = run(0.01)
    assert careful.stop == "goal" and len(careful.executed) == 2 and goal_error(careful.X_final, A_ON_B) < 0.04
    assert "1 cm inside eps" in careful.reason and careful.eps == 0.05  # the outcome is judged at the user's eps

    def doubtful(*args, **kwargs):  # every plan predicted to end 4 cm from the goal: not clearly closer
        result = plan(*args, **kwargs)
        return replace(result, predicted_error=0.04) if result.plan else result

    risky = run(0.01, doubtful)
    assert risky.stop == "goal" and len(risky.executed) == 1
    assert "no plan is predicted closer than 3.5 cm" in risky.reason
    with pytest.raises(UserError, match="stop margin"):
        PlanConfig(loop=LoopConfig(stop_margin=0.05))
    with pytest.raises(UserError, match="stop_margin"):
        LoopConfig(stop_margin=-0.01)


def test_loop_config_is_checked():
    with pytest.raises(UserError, match="at least 1 action"):
        LoopConfig(max_actions=0)


def test_the_loop_is_deterministic(models):
    a = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(1), rounds=None)
    b = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(1), rounds=None)
    assert a.executed == b.executed and a.stop == b.stop == "goal"
    assert plan("bilevel", models, X_INIT, A_ON_B).solved


class AcceptAll:
    """A kinematic check that accepts every action, and a refinement that always succeeds."""

    def graspable(self, X):
        return np.ones((len(X), 3), dtype=bool)

    def check(self, X, actions):
        return [None] * len(np.asarray(actions))

    def refine(self, actions, trajectory, grid_m):
        from tamp.planning.vocabulary import RefinementOutcome

        return RefinementOutcome()


def test_back_at_an_earlier_state_the_loop_leaves_out_the_action_it_took_from_there(models):
    from tamp.planning.search import state_key

    away, back = (1, 0, 1, 1), (1, 0, 1, -1)  # B shifted 7.5 cm along y, then shifted back
    seen: list[frozenset] = []

    def cycling_planner(method, models_, X, X_goal, cfg, avoid=frozenset(), **kwargs):
        seen.append(avoid)
        if any(action == away for _, action in avoid):
            return plan(method, models_, X, X_goal, cfg, avoid=avoid, **kwargs)
        at_start = np.allclose(X, X_INIT)
        result = PlanResult(method, [away if at_start else back], level=2,
                            predicted=np.stack([X, world_step(X, away if at_start else back)]))
        result.timings["total"] = 0.0
        return result

    cfg = PlanConfig(loop=LoopConfig(keep_plan=False))
    out = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=None, cfg=cfg,
                           planner=cycling_planner, kinematics=AcceptAll())
    assert out.executed[:2] == [away, back] and out.success and len(out.executed) == 3
    assert seen[:2] == [frozenset(), frozenset()]
    assert seen[2] == frozenset({(state_key(X_INIT, cfg.search.resolution), away)})  # back at X_INIT
    # the planners leave such a pair out: their first choice from X_INIT, avoided, gives another plan
    for method in ("cfs", "bilevel"):
        first = tuple(plan(method, models, X_INIT, A_ON_B, cfg, kinematics=AcceptAll()).plan[0])
        avoid = frozenset({(state_key(X_INIT, cfg.search.resolution), first)})
        other = plan(method, models, X_INIT, A_ON_B, cfg, kinematics=AcceptAll(), avoid=avoid)
        assert other.solved and tuple(other.plan[0]) != first


def test_without_a_plan_the_loop_steps_toward_the_closest_state_while_that_makes_progress(models, monkeypatch):
    goal = A_ON_B.copy()
    out = plan_closed_loop("bilevel", models, X_INIT, goal, slipping_world(0), rounds=None,
                           kinematics=RejectGoalMoves())
    toward = [r for r in out.rounds if r.toward]
    assert toward and all(r.origin == "toward the closest state" and r.widened and r.level == 2 for r in toward)
    assert all(a[0] == a[2] for a in out.executed)  # only shifts were possible
    distances = [np.linalg.norm(X[:, :3] - goal[:, :3], axis=1).sum() for X in out.states]
    assert all(b <= a - 0.02 + 1e-9 for a, b in zip(distances, distances[1:]))  # every step made progress
    assert not out.success and out.stop == "no_plan"  # A cannot get onto B: it stops when no step helps
    assert "toward the closest state" in toward[0].reasons[-1]
    import tamp.planning.closed_loop as closed_loop

    monkeypatch.setattr(closed_loop, "PROGRESS_M", 1.0)  # no step is that much closer
    still = plan_closed_loop("bilevel", models, X_INIT, goal, slipping_world(0), rounds=None,
                             kinematics=RejectGoalMoves())
    assert not still.executed and still.stop == "no_plan"


def test_with_no_budget_left_to_widen_the_loop_steps_toward_what_its_search_found(models):
    # the round's own search spends the whole budget: no widened search, yet its closest state is a step closer
    cfg = PlanConfig(search=replace(PlanConfig().search, max_expansions=3), loop=LoopConfig(search_budget=3))
    out = plan_closed_loop("bilevel", models, X_INIT, A_ON_B, slipping_world(0), rounds=None,
                           kinematics=RejectGoalMoves(), cfg=cfg)
    first = out.rounds[0]
    assert first.toward and not first.widened and first.origin == "toward the closest state"
    assert len(out.executed) == 1 and out.stop == "budget"
    before, after = (np.linalg.norm(X[:, :3] - A_ON_B[:, :3], axis=1).sum() for X in out.states)
    assert after <= before - 0.02 + 1e-9


def test_a_plan_kept_near_the_tolerance_gives_way_to_one_aimed_closer(models):
    goal = world_step(world_step(X_INIT, (1, 0, 1, 1)), (0, 0, 1, 0))  # B shifted 7.5 cm, then A on B
    calls: list[int] = []

    def planner(off_m):
        """`plan`, whose first plan predicts an end 4 cm off the goal (within eps, over verify.confident), and
        whose later plans end `off_m` off."""
        def call(method, models, X, X_goal, cfg, **kwargs):
            result = plan(method, models, X, X_goal, cfg, **kwargs)
            shift = 0.04 if not calls else off_m
            calls.append(len(result.plan))
            predicted = result.predicted.copy()
            predicted[-1, :, 0] += shift
            return replace(result, predicted=predicted,
                           predicted_error=float(np.abs(predicted[-1, :, :3] - X_goal[:, :3]).max()) + shift)
        return call

    calls.clear()
    out = plan_closed_loop("bilevel", models, X_INIT, goal, slipping_world(0), rounds=None, planner=planner(0.0))
    assert len(calls) == 2 and out.success
    assert not out.rounds[1].kept and out.rounds[1].reasons[0].startswith("keep: the rest of the last plan ends 4.0 cm")
    calls.clear()
    worse = plan_closed_loop("bilevel", models, X_INIT, goal, slipping_world(0), rounds=None, planner=planner(0.045))
    assert len(calls) == 2 and worse.rounds[1].kept and "planned" in worse.rounds[1].timings
    assert worse.executed == worse.rounds[0].plan  # the first plan, followed to its end


def test_a_plan_kept_near_the_tolerance_gives_way_only_to_one_within_confident(models):
    """A new plan a few millimetres closer but still over verify.confident does not replace the kept plan on
    course (`LoopConfig.commit`): trading it let the loop wander between near-equal plans."""
    goal = world_step(world_step(X_INIT, (1, 0, 1, 1)), (0, 0, 1, 0))
    calls: list[int] = []

    def planner(method, models, X, X_goal, cfg, **kwargs):  # the first plan ends 4.0 cm off, later ones 3.8 cm
        result = plan(method, models, X, X_goal, cfg, **kwargs)
        calls.append(len(result.plan))
        predicted = result.predicted.copy()
        predicted[-1, :, 0] = X_goal[:, 0] + (0.04 if len(calls) == 1 else 0.038)
        return replace(result, predicted=predicted, predicted_error=goal_error(predicted[-1], X_goal))

    kept = plan_closed_loop("bilevel", models, X_INIT, goal, slipping_world(0), rounds=None, planner=planner)
    assert len(calls) == 2 and kept.rounds[1].kept and kept.executed == kept.rounds[0].plan
    calls.clear()
    wander = PlanConfig(loop=LoopConfig(commit=False))
    traded = plan_closed_loop("bilevel", models, X_INIT, goal, slipping_world(0), rounds=None, planner=planner,
                              cfg=wander)
    assert not traded.rounds[1].kept
    assert traded.rounds[1].reasons[0].startswith("keep: the rest of the last plan ends 4.0 cm")
