"""The search record of a planning call, with stub models (no Drake, no torch): Level 1's ranked candidates with
the chosen one marked, the continuous search's tree, its bound, and a planner that records nothing when off."""
from __future__ import annotations

import json

import numpy as np
import pytest

from tamp.planning.closed_loop import plan_closed_loop
from tamp.planning.config import Level1Config, PlanConfig
from tamp.planning.models import Models
from tamp.planning.planners import plan
from tamp.planning.results import PlanResult
from tamp.planning.search import SearchConfig, continuous_search
from tamp.planning.search_record import executed_record, round_record, tree_record
from tamp.planning.search_trace import Recorder, recording
from tests.planning_stubs import StubModel, two_block_domain, world_step

X_INIT = np.array([[0.6, 0.0, 0.025, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
A_ON_B = np.array([[0.7, 0.1, 0.075, 1, 0], [0.7, 0.1, 0.025, 1, 0]])
ELSEWHERE = world_step(X_INIT, (0, 0, 1, 1))  # block 0 released beside B: the same symbols, Level 1's plan is empty
CONFIG = PlanConfig(level1=Level1Config(n_domains=100, seed=0))


@pytest.fixture(scope="module")
def models() -> Models:
    stub = StubModel()
    return Models(dynamics=stub, symbolic=stub, domain=two_block_domain())


def recorded(models: Models, X_goal: np.ndarray) -> tuple[PlanResult, dict]:
    recorder = Recorder()
    with recording(recorder):
        result = plan("bilevel", models, X_INIT, X_goal, CONFIG)
    return result, json.loads(json.dumps(round_record(0, result, recorder, X_INIT)))


def test_level1_candidates_are_ranked_with_their_rollout_and_the_chosen_one_marked(models):
    result, round_ = recorded(models, A_ON_B)
    candidates = round_["level1"]["candidates"]
    assert result.level == 1 and round_["level"] == 1 and round_["level2"] is None
    assert [c["rank"] for c in candidates] == list(range(1, len(candidates) + 1)) and len(candidates) >= 2
    (chosen,) = [c for c in candidates if c["chosen"]]
    assert chosen["verified"] and chosen["actions"] == round_["plan"] == [[0, 0, 1, 0]]
    first = candidates[0]  # the most frequent plan: released beside B, it does not verify
    assert first["actions"] == [[0, 0, 1, 1]] and first["verified"] is False and first["error_m"] > 0.05
    for c in candidates:
        if c["verified"] is not None:  # checked: the rollout it was judged by, one verdict per action
            assert len(c["predicted"]) == len(c["actions"]) + 1 and len(c["predicted"][0]) == 2
            assert [k["verdict"] for k in c["kinematics"]] == ["unchecked"] * len(c["actions"])  # no kinematics
    assert chosen["predicted"][-1][0] == pytest.approx([0.7, 0.1, 0.075], abs=1e-3)
    assert round_["origin"] == "planned" and round_["why"].startswith("level 1")


def test_a_level2_record_is_a_tree_whose_path_ends_at_the_goal(models):
    result, round_ = recorded(models, ELSEWHERE)
    tree = round_["level2"]
    assert result.level == 2 and tree["status"] == "solved" and not tree["truncated"]
    nodes = {node["id"]: node for node in tree["nodes"]}
    assert len(nodes) == len(tree["nodes"]) and [n["id"] for n in tree["nodes"] if n["parent"] is None] == [0]
    for node in tree["nodes"]:
        if node["parent"] is not None:
            parent = nodes[node["parent"]]
            assert parent["order"] is not None and node["g"] == parent["g"] + 1  # only expanded nodes have children
    orders = sorted(n["order"] for n in tree["nodes"] if n["order"] is not None)
    assert orders == list(range(tree["expanded"]))
    path = tree["path"]
    assert path[0] == 0 and all(nodes[b]["parent"] == a for a, b in zip(path, path[1:]))
    assert [nodes[i]["action"] for i in path[1:]] == round_["plan"]
    goal = np.linalg.norm(np.array(nodes[path[-1]]["X"]) - ELSEWHERE[:, :3], axis=1).max()
    assert goal < CONFIG.verify.eps and nodes[path[-1]]["h"] < nodes[0]["h"]


def test_recording_leaves_the_plan_unchanged(models):
    def plain(result: PlanResult) -> dict:
        d = result.to_dict()
        d.pop("timings")
        d["symbolic"].pop("timings", None)
        if d["search"] is not None:
            d["search"].pop("time")
        return d

    for goal in (A_ON_B, ELSEWHERE):
        off = plan("bilevel", models, X_INIT, goal, CONFIG)
        on, _ = recorded(models, goal)
        assert plain(on) == plain(off)
        assert all(c.predicted is None and c.kinematics is None for c in off.candidates)  # kept only when recording


def test_a_large_tree_is_cut_to_its_byte_bound_keeping_what_was_expanded():
    stub = StubModel()
    unreachable = X_INIT.copy()
    unreachable[0, :2] = [0.3, 0.5]  # the stub world's actions cannot take block 0 there
    recorder = Recorder()
    with recording(recorder):
        out = continuous_search(stub, X_INIT, unreachable, SearchConfig(max_expansions=60))
    assert recorder.tree is not None and not out.solved
    whole = tree_record(recorder.tree, 1, PlanResult("cfs", None, search=out))
    cut = tree_record(recorder.tree, 1, PlanResult("cfs", None, search=out), max_bytes=11_000)
    assert not whole["truncated"] and cut["truncated"] and len(cut["nodes"]) < len(whole["nodes"])
    assert len(json.dumps(cut["nodes"], separators=(",", ":"))) <= 11_000
    kept = {n["id"] for n in cut["nodes"]}
    expanded = {n["id"] for n in whole["nodes"] if n["order"] is not None}
    assert expanded <= kept and set(cut["closest"]) <= kept and cut["omitted"] == len(whole["nodes"]) - len(kept)


def test_every_round_of_a_closed_loop_is_recorded_with_the_step_it_executed(models):
    recorder, rounds = Recorder(), []

    def on_round(r: int, result: PlanResult) -> None:
        rounds.append((result, round_record(r, result, recorder, X_INIT)))
        recorder.reset()

    world = [X_INIT]

    def step(action) -> np.ndarray:
        world.append(world_step(world[-1], action))
        return world[-1]

    with recording(recorder):
        loop = plan_closed_loop("bilevel", models, X_INIT, ELSEWHERE, step, None, CONFIG, on_round=on_round)
    assert loop.success and len(rounds) == len(loop.rounds) >= 1
    result, first = rounds[0]
    assert first["level2"] is not None and first["level2"]["path"]
    step = executed_record(result, loop.executed[0], loop.states[1])
    assert step is not None and step["action"] == first["plan"][0] and step["miss_m"] < 0.01  # the stub world is exact
