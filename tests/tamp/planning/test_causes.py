"""Every failure has a cause a user can read: one test per cause, from the fields a row stores, and
the closed loop's stops mapped onto them."""
from __future__ import annotations

import pytest

from evaluation.row import row_cause
from tamp.planning.causes import AIMED, MISS, Cause, Failure, failure_cause


def row(outcome: str, **fields) -> dict:
    """An evaluation row with the fields `row_cause` reads."""
    stop = {"loop": fields.pop("loop", None), "search": fields.pop("search", None),
            "rejected": fields.pop("rejected", 0), "predicted_error_m": fields.pop("predicted", None),
            "goals_rejected": fields.pop("goals_rejected", 0)}
    return {"outcome": outcome, "step_miss_m": fields.pop("misses", []), "stop": stop,
            "refine_failure": fields.pop("refine_failure", None), **fields}


@pytest.mark.parametrize("fields, cause, words", [
    (row("wrong_plan", misses=[0.004, 0.063, 0.01], predicted=0.01), Cause.MODEL_MISS,
     "step 2 landed 6.3 cm from the Dynamics Model's prediction"),
    (row("wrong_plan", misses=[0.004, 0.012], predicted=0.045), Cause.AIMED_NEAR_TOLERANCE,
     "predicted 4.5 cm from the goal"),
    (row("wrong_plan", misses=[0.015, 0.012], predicted=0.012), Cause.SMALL_ERRORS, "added up"),
    (row("no_plan", search="node_limit"), Cause.SEARCH_BUDGET, "node limit"),
    (row("no_plan", search="time_limit"), Cause.SEARCH_BUDGET, "time limit"),
    (row("no_plan", search="exhausted"), Cause.PRUNED, "ran out of actions"),
    (row("no_plan", search="exhausted", rejected=40), Cause.KINEMATICS, "40 rejections"),
    (row("no_plan", search="refinement_budget"), Cause.KINEMATICS, "kinematic check"),
    (row("no_plan", search="node_limit", rejected=90, goals_rejected=12), Cause.KINEMATICS,
     "reached 12 goal states only by actions the kinematic check rejects"),
    (row("no_plan"), Cause.NO_SYMBOLIC_PLAN, "no symbolic plan"),
    (row("refinement_failure", refine_failure={"action": 1, "stage": "motion", "where": "descend", "reason": "x"}),
     Cause.EXECUTION, "action 1 could not be carried out at execution (motion, descend)"),
    (row("kinematic_failure", refine_failure={"action": 0, "stage": "ik", "where": None, "reason": "x"}),
     Cause.EXECUTION, "(ik)"),
    # closed loops
    (row("wrong_plan", loop="budget", misses=[0.1]), Cause.OUT_OF_ROUNDS, "action or search budget"),
    (row("wrong_plan", loop="budget", search="node_limit", goals_rejected=1, misses=[0.01]), Cause.OUT_OF_ROUNDS,
     "its last search reached 1 goal state only by actions the kinematic check rejects"),
    (row("wrong_plan", loop="no_plan", search="exhausted", rejected=3, misses=[0.01]), Cause.KINEMATICS,
     "after executed actions"),
    (row("wrong_plan", loop="empty_plan", misses=[0.01]), Cause.EMPTY_PLAN, "no action"),
    (row("wrong_plan", loop="rounds", misses=[0.01, 0.08], predicted=0.01), Cause.MODEL_MISS, "step 2"),
    (row("wrong_plan", loop="rounds", misses=[0.01], predicted=0.01), Cause.OUT_OF_ROUNDS, "replanning rounds"),
])
def test_each_cause_is_produced_by_its_failure(fields, cause, words):
    got = row_cause(fields)
    assert got is not None and got[0] == cause and words in got[1]


def test_a_success_or_an_error_row_has_no_cause():
    assert row_cause(row("success", misses=[0.2])) is None
    assert row_cause({"outcome": "error"}) is None
    assert failure_cause(Failure("success")) is None


def test_the_thresholds_are_the_documented_two_centimetres():
    assert MISS == AIMED == 0.02
    just = failure_cause(Failure("wrong_plan", step_miss_m=[MISS]))
    below = failure_cause(Failure("wrong_plan", step_miss_m=[MISS - 1e-4], predicted_error_m=AIMED))
    assert just is not None and just[0] == Cause.MODEL_MISS
    assert below is not None and below[0] == Cause.AIMED_NEAR_TOLERANCE
