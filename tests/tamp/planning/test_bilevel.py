"""Algorithm 1 with a hand-made domain and stub models: verification order, fall-through to the
continuous search, unsolvable problems, closed-loop replanning. No Drake, no torch model."""
from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from tamp.errors import UserError
from tamp.planning import closed_loop, level1
from tamp.planning.closed_loop import plan_closed_loop
from tamp.planning.config import KinematicsConfig, Level1Config, LoopConfig, PlanConfig, VerifyConfig
from tamp.planning.level1 import level1_scene
from tamp.planning.models import Models
from tamp.planning.planners import plan
from tamp.planning.search import SearchConfig, continuous_search
from tamp.planning.verify import goal_error, verify
from tests.planning_stubs import StubModel, two_block_domain, world_step

X_INIT = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
A_ON_B = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])


@pytest.fixture(scope="module")
def domain():
    return two_block_domain()


def models(domain) -> Models:
    stub = StubModel()
    return Models(dynamics=stub, symbolic=stub, domain=domain)


def execute(X, actions):
    for a in actions:
        X = world_step(X, a)
    return X


def test_verify_rolls_out_and_uses_the_per_object_max():
    stub = StubModel()
    v = verify(stub, X_INIT, A_ON_B, [(0, 0, 1, 1)])
    assert v.trajectory.shape == (2, 2, 5) and np.array_equal(v.trajectory[0], X_INIT)
    # released 7.5 cm beside the small block B: it lands on the table there
    assert np.allclose(v.X_final[0, :3], [0.7, 0.175, 0.025])
    assert v.error == pytest.approx(np.hypot(0.075, 0.05)) and not v.verified
    assert v.error_stacked == pytest.approx(v.error)  # B did not move
    good = verify(stub, X_INIT, A_ON_B, [(0, 0, 1, 0)])
    assert good.verified and good.error < 1e-9


def with_level1(**fields) -> PlanConfig:
    """The default configuration with these Level-1 settings."""
    return PlanConfig(level1=Level1Config(**fields))


def test_most_frequent_plan_fails_verification_and_the_next_verified_one_is_returned(domain):
    result = plan("bilevel", models(domain), X_INIT, A_ON_B, with_level1(n_domains=100, seed=0))
    first, second = result.candidates[:2]
    # the setting: the most frequent symbolic plan is the bad one
    assert first.actions == ((0, 0, 1, 1),) and first.count > second.count
    assert first.verified is False and first.error > 0.07
    assert second.actions == ((0, 0, 1, 0),) and second.verified is True
    assert result.level == 1 and result.plan == [(0, 0, 1, 0)]
    assert result.search is None and "search" not in result.timings
    assert goal_error(execute(X_INIT, result.plan), A_ON_B) < 0.05
    assert {"symbols", "symbolic", "verify", "total"} <= set(result.timings)
    # the unverified baselines take the most frequent plan and fail when executed
    for method in ("probabilistic", "deterministic"):
        base = plan(method, models(domain), X_INIT, A_ON_B, with_level1(n_domains=100, seed=0))
        assert base.plan == [(0, 0, 1, 1)] and base.candidates[0].verified is False
        assert goal_error(execute(X_INIT, base.plan), A_ON_B) > 0.05


def test_a_verified_plan_predicted_to_miss_the_goal_waits_for_the_continuous_search(domain):
    # the goal: A on B, with B 6 cm along +y. Level 1's plans put A on B where B is: verified (within
    # tau = 7 cm) but predicted 6 cm off, beyond the success tolerance; the continuous search shifts
    # B first and ends 1.5 cm off
    goal = A_ON_B.copy()
    goal[:, 1] += 0.06
    ours = plan("bilevel", models(domain), X_INIT, goal, with_level1(n_domains=100, seed=0))
    assert any(c.verified and 0.05 <= c.error < 0.07 for c in ours.candidates)
    assert ours.level == 2 and len(ours.plan) == 2 and ours.predicted_error < 0.02
    assert goal_error(execute(X_INIT, ours.plan), goal) < 0.05
    assert any("kept while level 2 searches" in r for r in ours.reasons)
    # the paper's rule takes the verified plan, which misses the goal; so does its Algorithm 1
    paper = plan("bilevel", models(domain), X_INIT, goal, with_level1(n_domains=100, seed=0, wait_beyond=None))
    assert paper.level == 1 and paper.search is None and goal_error(execute(X_INIT, paper.plan), goal) > 0.05
    alg1 = plan("bilevel_alg1", models(domain), X_INIT, goal, with_level1(n_domains=100, seed=0))
    assert alg1.level == 1 and alg1.search is None and goal_error(execute(X_INIT, alg1.plan), goal) > 0.05
    # when the continuous search finds nothing, the kept plan is returned
    shallow = PlanConfig(level1=Level1Config(n_domains=100, seed=0), search=SearchConfig(max_depth=1))
    kept = plan("bilevel", models(domain), X_INIT, goal, shallow)
    assert kept.level == 1 and kept.plan == paper.plan and kept.search is not None and not kept.search.solved
    with pytest.raises(UserError, match="Level1Config.wait_beyond"):
        with_level1(wait_beyond=0.0)


def test_same_symbols_but_goal_elsewhere_falls_through_to_the_continuous_search():
    # a large bar shifted 15 cm along y: the same symbols before and after. Level 1's plan is the empty
    # one, as in the paper's Algorithm 1; it cannot verify (X_init is 15 cm from the goal), so Level 2
    # finds the shift, a symbolic no-op.
    domain = two_block_domain(shift=True)
    X = np.array([[0.6, 0.0, 0.025, 0, 1], [0.75, -0.2, 0.025, 1, 0]])
    goal = X.copy()
    goal[0, 1] = 0.15
    ours = plan("bilevel", models(domain), X, goal, with_level1(n_domains=20))
    assert ours.candidates[0].actions == () and ours.candidates[0].verified is False
    assert ours.level == 2 and ours.plan == [(0, -1, 0, 1)]
    assert goal_error(execute(X, ours.plan), goal) < 0.05


def test_bilevel_alg1_verifies_the_ranked_plans_in_order_and_searches_as_the_paper(domain, monkeypatch):
    # the most frequent plan fails verification: Algorithm 1 takes the second ranked plan
    alg1 = plan("bilevel_alg1", models(domain), X_INIT, A_ON_B, with_level1(n_domains=100, seed=0))
    assert alg1.method == "bilevel_alg1"
    assert alg1.level == 1 and alg1.plan == [(0, 0, 1, 0)] and alg1.candidates[1].count < alg1.candidates[0].count
    # where the symbols do not change, Algorithm 1 tries the empty plan and falls through
    shift = two_block_domain(shift=True)
    X = np.array([[0.6, 0.0, 0.025, 0, 1], [0.75, -0.2, 0.025, 1, 0]])
    goal = X.copy()
    goal[0, 1] = 0.15
    alg1_shift = plan("bilevel_alg1", models(shift), X, goal, with_level1(n_domains=20))
    assert [c.actions for c in alg1_shift.candidates] == [()] and alg1_shift.level == 2
    # its Level 2 is the paper's search: the paper's pruning rule, the first goal state returned
    import tamp.planning.level2 as level2
    searched = []
    monkeypatch.setattr(level2, "continuous_search", lambda model, x, g, config, *rest, **kw:
                        searched.append(config) or continuous_search(model, x, g, config, *rest, **kw))
    plan("bilevel_alg1", models(shift), X, goal, with_level1(n_domains=20))
    assert searched and all(not c.release_targets and c.look_on == 0 for c in searched)
    assert alg1_shift.level == 2  # Level 1's plan was not kept: alg1's rules are the paper's


def test_symbolic_failure_falls_through_to_continuous_search(domain):
    # a large bar shifted 15 cm along y: the same symbols before and after, so the symbolic plan is
    # empty and fails verification; only the continuous search can find (0, -1, 0, +1)
    X = np.array([[0.6, 0.0, 0.025, 0, 1], [0.75, -0.2, 0.025, 1, 0]])
    goal = X.copy()
    goal[0, 1] = 0.15
    result = plan("bilevel", models(domain), X, goal, with_level1(n_domains=20))
    assert result.candidates and all(c.verified is False for c in result.candidates)
    assert result.level == 2 and result.search.solved
    assert any(r.startswith("level 1: none of the") for r in result.reasons)
    assert goal_error(execute(X, result.plan), goal) < 0.05
    assert result.predicted_error < 0.05 and result.predicted.shape == (len(result.plan) + 1, 2, 5)
    assert "search" in result.timings


def test_unsolvable_problem_ends_within_limits_with_reasons_from_both_levels(domain):
    goal = X_INIT.copy()
    goal[0, :2] = (1.0, 0.5)  # on the table within reach, but no pick-place of the stub world puts it there
    cfg = PlanConfig(level1=Level1Config(n_domains=20), search=SearchConfig(max_expansions=300, time_limit=10.0))
    t0 = time.perf_counter()
    result = plan("bilevel", models(domain), X_INIT, goal, cfg)
    assert time.perf_counter() - t0 < 10.0
    assert not result.solved and result.plan is None and result.level is None
    assert result.search.status == "node_limit" and result.search.expanded == 300
    assert len(result.reasons) == 2
    assert result.reasons[0].startswith("level 1:") and result.reasons[1].startswith("level 2: node limit")
    # a time limit ends it too (four blocks: a search space the stub world does not exhaust in 0.3 s)
    X4 = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0], [0.8, -0.2, 0.025, 1, 0], [0.5, 0.3, 0.025, 0, 1]])
    goal4 = X4.copy()
    goal4[0, :2] = (1.0, 0.5)
    cfg = PlanConfig(level1=Level1Config(n_domains=20), search=SearchConfig(max_expansions=10**9, time_limit=0.3))
    t0 = time.perf_counter()
    result = plan("cfs", models(domain), X4, goal4, cfg)
    assert time.perf_counter() - t0 < 2.0 and result.search.status == "time_limit"
    assert result.reasons == [f"level 2: {result.search.reason}"]


def test_closed_loop_replans_from_the_observed_state(domain):
    calls = []

    def flaky_world(action):  # the first action grasps nothing; then the world behaves
        calls.append(action)
        return X if len(calls) == 1 else world_step(X, action)

    X = X_INIT
    open_loop = plan_closed_loop("bilevel", models(domain), X_INIT, A_ON_B, flaky_world, rounds=0)
    assert not open_loop.success and len(open_loop.rounds) == 1
    calls.clear()
    closed = plan_closed_loop("bilevel", models(domain), X_INIT, A_ON_B, flaky_world, rounds=1)
    assert closed.success and len(closed.rounds) == 2 and closed.executed == [(0, 0, 1, 0)] * 2
    assert closed.error < 0.05 and len(closed.states) == 3


def test_the_closed_loop_keeps_a_plan_on_course_and_replans_one_off_course(domain):
    goal = execute(X_INIT, [(1, 0, 1, 1), (0, 0, 1, 0)])  # B shifted 7.5 cm along y, then A on B
    calls = []

    def planner(method, *args, **kwargs):
        calls.append(method)
        return plan(method, *args, **kwargs)

    def world(nudge_m=0.0):
        """The stub world; with `nudge_m`, the first action's moved blocks land that far off along x."""
        X = [X_INIT]

        def step(action):
            after = world_step(X[-1], action)
            if len(X) == 1:
                after[:, 0] += nudge_m * (np.linalg.norm(after[:, :3] - X[-1][:, :3], axis=1) > 1e-6)
            X.append(after)
            return after
        return step

    calls.clear()
    kept = plan_closed_loop("cfs", models(domain), X_INIT, goal, world(), rounds=1, planner=planner)
    assert kept.success and len(kept.rounds) == 2 and calls == ["cfs"]  # one planning call
    assert kept.executed == kept.rounds[0].plan and "kept the rest" in kept.rounds[1].reasons[-1]
    assert kept.rounds[1].level == kept.rounds[0].level and kept.rounds[1].kept and not kept.rounds[0].kept
    assert kept.rounds[1].to_dict()["kept"] is True and kept.rounds[1].kept_by == "on course"
    assert kept.rounds[0].kept_by is None  # planned
    calls.clear()
    fresh = plan_closed_loop("cfs", models(domain), X_INIT, goal, world(), rounds=1, planner=planner,
                             cfg=PlanConfig(loop=LoopConfig(keep_plan=False)))
    assert fresh.success and calls == ["cfs", "cfs"]  # the paper's replanning: a planning call per round
    # the first move lands 4 cm off: the rest of the plan no longer reaches the goal, so it plans again
    calls.clear()
    off = plan_closed_loop("cfs", models(domain), X_INIT, goal, world(0.04), rounds=1, planner=planner)
    assert calls == ["cfs", "cfs"] and "keep" in off.rounds[1].timings and not off.rounds[1].kept
    assert off.rounds[1].timings["total"] >= off.rounds[1].timings["keep"] > 0
    assert off.rounds[1].reasons[0].startswith("keep: the rest of the last plan is predicted")
    # the paper's Algorithm 1 replans in every round, as the paper does
    calls.clear()
    plan_closed_loop("bilevel_alg1", models(domain), X_INIT, goal, world(), rounds=1, planner=planner)
    assert calls == ["bilevel_alg1", "bilevel_alg1"]


def test_a_kept_level1_plan_follows_its_symbolic_path(domain):
    from tamp.planning.closed_loop import keep_rest
    from tamp.planning.results import Candidate, PlanResult
    from tamp.planning.vocabulary import PickPlace

    goal = execute(X_INIT, [(1, 0, 1, 1), (0, 0, 1, 0)])
    actions = ((1, 0, 1, 1), (0, 0, 1, 0))
    last = PlanResult("bilevel", [PickPlace(*a) for a in actions], level=1,
                      candidates=[Candidate(actions, 5, 0.5, 0.0, True, states=(10, 11, 12))])
    assert last.plan_states == (10, 11, 12)
    kept = keep_rest(models(domain), world_step(X_INIT, actions[0]), goal, last, PlanConfig())
    assert kept.kept and kept.level == 1 and kept.plan == [actions[1]] and kept.plan_states == (11, 12)
    assert kept.kept_by == "rollout"  # `last` holds no prediction to be on course with
    # off course (B not shifted): nothing kept, and the result says why
    missed = keep_rest(models(domain), X_INIT, goal, last, PlanConfig())
    assert not missed.solved and not missed.kept and missed.reasons[0].startswith("keep:")


def test_a_plan_on_course_is_kept_whatever_a_swinging_rollout_of_its_rest_says(domain, capsys, monkeypatch):
    """The world did what the plan predicted (within closed_loop.ON_COURSE_M): the rest is kept with the plan's
    own prediction, although the model, given the observed state, predicts the rest far off."""
    from tamp.planning.closed_loop import keep_rest, off_course
    from tamp.planning.results import PlanResult
    from tamp.planning.verify import goal_errors
    from tamp.planning.vocabulary import PickPlace

    class SwingingModel(StubModel):
        """The toy dynamics, but 20 cm off along x from any scene whose block A is off the 1 cm grid."""

        def predict_effect(self, X, actions):
            effect = super().predict_effect(X, actions)
            if abs(X[0, 0] * 100 - round(X[0, 0] * 100)) > 1e-3:
                effect[:, :, 0] += 0.2
            return effect

    actions = ((1, 0, 1, 1), (0, 0, 1, 0))
    goal = execute(X_INIT, actions)
    predicted = verify(StubModel(), X_INIT, goal, actions).trajectory
    last = PlanResult("cfs", [PickPlace(*a) for a in actions], level=2, predicted=predicted)
    swinging = Models(dynamics=SwingingModel(), symbolic=None, domain=None)

    def observed(nudge_m):
        X = world_step(X_INIT, actions[0])
        X[0, 0] += nudge_m
        return X

    assert off_course(observed(0.005), last) == pytest.approx(0.005)
    kept = keep_rest(swinging, observed(0.005), goal, last, PlanConfig())
    assert kept.kept and kept.kept_by == "on course" and kept.plan == [actions[1]] and "on course" in kept.reasons[-1]
    assert np.array_equal(kept.predicted[0], observed(0.005)) and np.array_equal(kept.predicted[1], predicted[2])
    assert kept.predicted_error == pytest.approx(goal_errors(predicted[-1], goal).max())
    # without on_course: the rollout from the observed state decides, and it ends 20 cm off
    with monkeypatch.context() as m:
        m.setattr(closed_loop, "ON_COURSE_M", 0.0)
        blind = keep_rest(swinging, observed(0.005), goal, last, PlanConfig())
    assert not blind.solved and blind.reasons[0].startswith("keep: the rest of the last plan is predicted 2")
    # 2.5 cm off the plan's prediction is off course: the rollout decides again
    off = keep_rest(swinging, observed(0.025), goal, last, PlanConfig())
    assert not off.solved and off.reasons[0].startswith("keep: the rest of the last plan is predicted")
    # on course, but the plan itself predicted its end beyond search.confident: the rollout decides
    doubtful = replace(last, predicted=predicted.copy())
    doubtful.predicted[-1, 1, 1] += 0.04  # block B 4 cm off its goal at the end of the plan
    assert not keep_rest(swinging, observed(0.005), goal, doubtful, PlanConfig()).solved
    # `tamp plan --replan` and `tamp demo` say why a round kept the plan
    from tamp.app.plan_command import print_result

    print_result(kept, 0.07)
    assert "kept the rest of the last plan: on course" in capsys.readouterr().out
    # a last plan without a prediction is never on course
    assert off_course(observed(0.0), PlanResult("cfs", last.plan, level=2)) == float("inf")


def test_unknown_method_is_a_clear_error(domain):
    with pytest.raises(ValueError, match="unknown planning method 'astar'"):
        plan("astar", models(domain), X_INIT, A_ON_B)


def test_verify_many_shares_prefixes_and_equals_verify_one_by_one():
    from tamp.planning.verify import verify_many

    plans = [[(0, 0, 1, 1), (1, 0, 0, 0)], [(0, 0, 1, 1), (1, 1, 0, 0)], [(0, 0, 1, 0)], []]
    stub = StubModel()
    many = verify_many(stub, X_INIT, A_ON_B, plans)
    assert stub.calls == 2  # one call for the first actions, one for the two second actions
    for p, v in zip(plans, many):
        one = verify(StubModel(), X_INIT, A_ON_B, p)
        assert v.actions == one.actions and np.allclose(v.trajectory, one.trajectory)
        assert v.error == pytest.approx(one.error) and v.verified == one.verified


def test_verify_many_predicts_all_prefixes_of_one_length_in_one_pass_when_the_model_can():
    from tamp.planning.verify import verify_many

    class BatchedStub(StubModel):
        """predict_effects: many scenes, one action each (the learned models' batched call)."""
        batched = 0

        def predict_effects(self, Xs, actions):
            self.batched += 1
            return np.stack([self.predict_effect(X, [a])[0] for X, a in zip(Xs, actions)])

    plans = [[(0, 0, 1, 1), (1, 0, 0, 0)], [(0, 0, 1, 0), (1, 1, 0, 0)], [(1, 0, 0, 0)], [(0, 0, 1, 1)]]
    stub = BatchedStub()
    many = verify_many(stub, X_INIT, A_ON_B, plans)
    assert stub.batched == 2  # three distinct first actions, then two second actions from two scenes
    for p, v in zip(plans, many):
        one = verify(StubModel(), X_INIT, A_ON_B, p)
        assert v.actions == one.actions and np.allclose(v.trajectory, one.trajectory)


def test_the_symbolic_search_returns_the_first_shortest_plan_in_ground_action_order():
    from symbolic import SymbolicPlanner, make_problem, steps_to_actions

    stub = StubModel()
    problem = make_problem(*stub.symbols(X_INIT), *stub.symbols(A_ON_B))
    # both releases usually stack, so both are in the deterministic domain; breadth-first search takes
    # the first one in ground-action order, (0, 0, 1, 0), whichever is more reliable (the ranking by
    # frequency over sampled domains and the verification choose among plans, not the search)
    for p_plus, p_zero in ((0.9, 0.6), (0.6, 0.9)):
        domain = two_block_domain(p_bad=p_plus, p_good=p_zero)
        out = SymbolicPlanner(domain).plan_deterministic(problem)
        assert steps_to_actions(domain, out.plan, 2) == [(0, 0, 1, 0)]


class StubKinematics:
    """The planner's view of kinematic feasibility (tamp.planning.vocabulary.KinematicFeasibility), scripted:
    `infeasible` actions fail the cheap check, plans starting with `unrefinable` fail refinement."""

    def __init__(self, infeasible=(), unrefinable=()):
        self.infeasible, self.unrefinable = set(infeasible), set(unrefinable)
        self.refined: list[list[tuple]] = []

    def graspable(self, X):
        return np.ones((len(X), 3), dtype=bool)

    def check(self, X, actions):
        from tamp.planning.vocabulary import Infeasible

        return [Infeasible.NO_GRASP if tuple(map(int, a)) in self.infeasible else None
                for a in np.asarray(actions).reshape(-1, 4)]

    def refine(self, actions, trajectory=None, grid_m=0.03):
        from tamp.planning.vocabulary import Infeasible, RefinementOutcome

        actions = [tuple(map(int, a)) for a in actions]
        self.refined.append(actions)
        if actions and actions[0] in self.unrefinable:
            return RefinementOutcome(0, Infeasible.REFINE_MOTION, "motion [lift]: blocked")
        return RefinementOutcome()


# both ranked plans verify (9 cm, 0 cm) and a verified plan is taken however close it is predicted
LOOSE = PlanConfig(level1=Level1Config(n_domains=100, seed=0, wait_beyond=None),
                   verify=VerifyConfig(tau_verify=0.1))


def test_a_refinement_failure_of_the_first_level1_candidate_returns_the_second(domain):
    from tamp.planning.vocabulary import Infeasible

    first = plan("bilevel", models(domain), X_INIT, A_ON_B, LOOSE)
    assert first.level == 1 and first.plan == [(0, 0, 1, 1)]  # without kinematics: the most frequent plan
    kin = StubKinematics(unrefinable={(0, 0, 1, 1)})
    result = plan("bilevel", models(domain), X_INIT, A_ON_B, LOOSE, kinematics=kin)
    assert result.level == 1 and result.plan == [(0, 0, 1, 0)]
    assert kin.refined == [[(0, 0, 1, 1)], [(0, 0, 1, 0)]]  # the second is refined before it is returned
    assert result.rejected[1][Infeasible.REFINE_MOTION] == 1
    assert [r["failed_action"] for r in result.refinements] == [0, None]
    assert result.to_dict()["rejected"] == {"level 1": {"refine_motion": 1}, "level 2": {}}
    # the switch: feasibility off, the kinematics are not consulted
    unchecked = replace(LOOSE, kinematics=KinematicsConfig(feasibility=False))
    off = plan("bilevel", models(domain), X_INIT, A_ON_B, unchecked, kinematics=kin)
    assert off.plan == [(0, 0, 1, 1)] and off.rejected is None and len(kin.refined) == 2


def test_a_waiting_level1_plan_is_refined_only_when_the_continuous_search_finds_none(domain):
    # as above: Level 1's verified plan ends 6 cm off and waits while Level 2 searches
    goal = A_ON_B.copy()
    goal[:, 1] += 0.06
    kin = StubKinematics()
    found = plan("bilevel", models(domain), X_INIT, goal, with_level1(n_domains=100, seed=0), kinematics=kin)
    assert found.level == 2 and kin.refined == [found.plan]  # Level 2's plan, refined; the waiting one never
    # Level 2 finds nothing: the waiting plan is refined then, and returned
    shallow = PlanConfig(level1=Level1Config(n_domains=100, seed=0), search=SearchConfig(max_depth=1))
    kin = StubKinematics()
    kept = plan("bilevel", models(domain), X_INIT, goal, shallow, kinematics=kin)
    assert kept.level == 1 and kin.refined == [kept.plan] and kept.refinements[0]["level"] == 1
    # ... unless it does not refine: no plan, and why
    kin = StubKinematics(unrefinable={tuple(kept.plan[0])})
    lost = plan("bilevel", models(domain), X_INIT, goal, shallow, kinematics=kin)
    assert lost.plan is None and any("its waiting plan did not refine" in r for r in lost.reasons)


def test_a_level1_candidate_failing_the_check_is_not_refined_and_the_next_is_returned(domain):
    from tamp.planning.vocabulary import Infeasible

    kin = StubKinematics(infeasible={(0, 0, 1, 1)})
    result = plan("bilevel", models(domain), X_INIT, A_ON_B, LOOSE, kinematics=kin)
    assert result.plan == [(0, 0, 1, 0)] and kin.refined == [[(0, 0, 1, 0)]]
    assert result.rejected[1] == {Infeasible.NO_GRASP: 1}


def test_refinement_failures_send_the_planner_to_level2_with_the_failing_pair_pruned(domain):
    # every plan starting with the direct action fails refinement: Level 1 has nothing left, Level 2
    # must find a plan that starts otherwise
    kin = StubKinematics(unrefinable={(0, 0, 1, 0), (0, 0, 1, 1)})
    result = plan("bilevel", models(domain), X_INIT, A_ON_B, PlanConfig(kinematics=KinematicsConfig(max_refinements=6)),
                  kinematics=kin)
    assert result.solved and result.level == 2 and result.plan[0] not in kin.unrefinable
    assert result.refinements[0]["level"] == 1 and result.refinements[0]["plan"] == [[0, 0, 1, 0]]
    assert result.refinements[-1]["failed_action"] is None and kin.refined[-1] == [tuple(a) for a in result.plan]
    assert goal_error(execute(X_INIT, result.plan), A_ON_B) < 0.05


def test_level1_that_runs_out_of_its_budget_leaves_the_plan_to_level2(domain):
    """`[level1] budget` bounds the symbolic search in generated states: every domain that has no plan by then
    ends as a timeout, and the continuous search plans; a budget that suffices leaves the problem to Level 1."""
    far = np.array([[0.45, -0.3 + 0.12 * i, 0.025, 1, 0] for i in range(3)])
    stacked = far.copy()
    stacked[0, :3] = far[1, :3] + [0, 0, 0.05]
    X5, G5 = np.vstack([X_INIT, far]), np.vstack([A_ON_B, stacked])  # two blocks to stack: two actions
    starved = plan("bilevel", models(domain), X5, G5, with_level1(n_domains=20, focus_from=5, serial=False, budget=1))
    assert starved.symbolic_stats["outcomes"] == {"timeout": 20} and not starved.candidates
    assert starved.level == 2 and goal_error(execute(X5, starved.plan), G5) < 0.05
    four = plan("bilevel", models(domain), X5[:4], G5[:4], with_level1(n_domains=20, focus_from=5, serial=False))
    assert four.level == 1 and four.symbolic_stats["generated"] > 1


def test_from_focus_from_blocks_on_level1_plans_in_the_scene_of_the_objects_the_goal_involves(domain, monkeypatch):
    """`level1_scene`: Level 1 reads the symbols of the misplaced block and its targets only, and its plan
    names the whole scene's objects; with more objects involved than the limit, Level 2 plans at once."""
    far = np.array([[0.45, -0.3 + 0.12 * i, 0.025, 1, 0] for i in range(3)])
    stacked = far.copy()
    stacked[0, :3] = far[1, :3] + [0, 0, 0.05]
    X5, G5 = np.vstack([X_INIT, far]), np.vstack([X_INIT, stacked])  # block 2 onto block 3, the rest stay
    cfg = with_level1(n_domains=20, focus_from=5)
    assert level1_scene(X5, G5, cfg.level1, cfg.verify) == (2, 3)
    assert level1_scene(X5[:4], G5[:4], cfg.level1, cfg.verify) is None
    sub = plan("bilevel", models(domain), X5, G5, cfg)
    assert sub.level == 1 and sub.symbolic_stats["objects"] == [2, 3]
    assert [tuple(a)[::2] for a in sub.plan] == [(2, 3)] and goal_error(execute(X5, sub.plan), G5) < 0.05
    assert all(c.objects == (2, 3) for c in sub.candidates)
    assert sub.plan_scene == (2, 3) and len(sub.plan_states) == 2  # the per-step view reads the sub-scene
    with monkeypatch.context() as m:
        m.setattr(level1, "level1_scene", lambda *args: None)  # Level 1 on the whole scene
        whole = plan("bilevel", models(domain), X5, G5, cfg)
    assert whole.level == 1 and whole.symbolic_stats["objects"] is None and whole.plan_scene is None
    assert whole.plan_states is not None and whole.plan_states != sub.plan_states
    both = np.vstack([A_ON_B, stacked])  # two stacks to build: four objects involved
    assert level1_scene(X5, both, cfg.level1, cfg.verify) == (0, 1, 2, 3)
    monkeypatch.setattr(level1, "SUBSCENE_OBJECTS", 3)
    over = plan("bilevel", models(domain), X5, both, replace(cfg, level1=replace(cfg.level1, serial=False)))
    assert over.level == 2 and not over.candidates and "involves 4 objects" in over.reasons[0]
    assert goal_error(execute(X5, over.plan), both) < 0.05


def test_level1_plans_one_block_at_a_time_when_the_whole_goal_gives_no_plan(domain, monkeypatch):
    """`level1_serial`: with more objects involved than Level 1's scenes hold, it places one misplaced
    block per stage (lowest goal first, each in its own sub-scene) and the joined plan, verified in the
    whole scene, is Level 1's; without it, or when a stage places no block, Level 2 plans."""
    far = np.array([[0.45, -0.3 + 0.12 * i, 0.025, 1, 0] for i in range(3)])
    stacked = far.copy()
    stacked[0, :3] = far[1, :3] + [0, 0, 0.05]
    X5, G5 = np.vstack([X_INIT, far]), np.vstack([A_ON_B, stacked])  # two stacks: four objects involved
    monkeypatch.setattr(level1, "SUBSCENE_OBJECTS", 3)
    cfg = with_level1(n_domains=20, focus_from=5)
    serial = plan("bilevel", models(domain), X5, G5, cfg)
    assert serial.level == 1 and serial.symbolic_stats["serial"] == {"placed": [0, 2], "left": [], "error_m": 0.0}
    assert [tuple(a)[::2] for a in serial.plan] == [(0, 1), (2, 3)] and goal_error(execute(X5, serial.plan), G5) < 0.05
    assert serial.candidates[-1].verified and serial.candidates[-1].stages == (0, 2) and serial.plan_states is None
    assert serial.timings["symbolic"] > 0 and serial.timings["verify"] > 0  # both stages' Level-1 time
    assert plan("bilevel", models(domain), X5, G5, replace(cfg, level1=replace(cfg.level1, serial=False))).level == 2
    starved = plan("bilevel", models(domain), X5, G5, replace(cfg, level1=replace(cfg.level1, budget=1)))
    assert starved.level == 2 and starved.symbolic_stats["serial"] == {"placed": [0], "left": [2]}  # one budget:
    assert any("its budget (1 symbolic states" in r for r in starved.reasons)  # block 0's stage spent it
    bad = G5.copy()
    bad[2, :3] = [0.75, -0.25, 0.025]  # block 2 elsewhere on the table: no learned operator moves it there
    stuck = plan("bilevel", models(domain), X5, bad, cfg)
    assert stuck.level != 1 and stuck.symbolic_stats["serial"] == {"placed": [0], "left": [2]}
    assert any("one block at a time: no plan places any of blocks [2]" in r for r in stuck.reasons)
    alg1 = plan("bilevel_alg1", models(domain), X5, G5, cfg)
    assert alg1.level == 1 and alg1.symbolic_stats["objects"] is None


def test_a_failed_keep_is_counted_in_the_round_that_plans_again(domain):
    # the rest of the plan is on course but fails refinement from the observed scene: the round plans
    # again, and the refinement and time the keep attempt spent are in that round's record
    goal = execute(X_INIT, [(1, 0, 1, 1), (0, 0, 1, 0)])
    first = plan("cfs", models(domain), X_INIT, goal, PlanConfig(), kinematics=StubKinematics())
    rest = tuple(first.plan[1])
    kin = StubKinematics(unrefinable={rest})
    X = [X_INIT]

    def step(action):
        X.append(world_step(X[-1], action))
        return X[-1]

    loop = plan_closed_loop("cfs", models(domain), X_INIT, goal, step, rounds=1, kinematics=kin)
    second = loop.rounds[1]
    assert not second.kept and second.timings["keep"] > 0 and second.reasons[0].startswith("keep:")
    assert second.refinements[0]["plan"] == [list(rest)] and second.refinements[0]["failed_action"] == 0
    assert second.rejected[2]["refine_motion"] >= 1
