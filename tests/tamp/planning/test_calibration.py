"""The Dynamics Model's predictions of executed steps: action classes, misses against the 95 % bound, and the
report's calibration section."""
import json

import numpy as np
import pytest

from evaluation.report import build_report
from evaluation.report.calibration import step_figures
from evaluation.report.results import Results
from tamp.planning.calibration import SCENES, action_class, start_scene, step_predictions

# a bar 0 and two cubes 1, 2 on the table
X = np.array([[0.55, -0.15, 0.025, 0, 1], [0.7, 0.1, 0.025, 1, 0], [0.8, -0.2, 0.025, 1, 0]])


def test_action_classes_name_what_is_moved_and_where():
    assert action_class(X, (1, 0, 2, 0)) == "cube on a cube"
    assert action_class(X, (1, 0, 2, 1)) == "cube beside a cube"
    assert action_class(X, (0, 1, 1, -1)) == "bar beside a cube"
    assert action_class(X, (1, 0, 0, 0)) == "cube on a bar's middle"
    assert action_class(X, (2, 0, 0, -1)) == "cube on a bar's end"
    assert action_class(X, (0, -1, 0, 1)) == "bar shifted"


def test_a_step_starts_from_blocks_on_the_table_a_stack_or_a_leaning_block():
    assert start_scene(X) == "blocks on the table"
    stacked, leaning = X.copy(), X.copy()
    stacked[1, :3] = (0.8, -0.2, 0.075)  # cube 1 on cube 2
    leaning[0, 2] = 0.059  # the bar's end up on something
    assert start_scene(stacked) == "a stack" and start_scene(leaning) == "a leaning block"
    stacked[1, 2] = 0.083  # 8 mm above the level: still stacked
    assert start_scene(stacked) == "a stack"
    after = X.copy()
    after[:, 0] += 0.01
    assert step_predictions(Gaussian(0.01), [leaning, after], [(1, 0, 2, 0)])[0].record()["scene"] == SCENES[2]


class Gaussian:
    """Predicts a 1 cm shift of every block along x with a spread of `sigma` metres per axis."""

    def __init__(self, sigma):
        self.sigma = sigma

    def predict_gaussian(self, Xs, actions):
        mean = np.zeros((len(actions), Xs.shape[1], 3))
        mean[..., 0] = 0.01
        return mean, np.full(mean.shape, self.sigma ** 2)


def test_each_step_is_judged_against_its_own_bound():
    after = X.copy()
    after[:, 0] += 0.01
    after[1, 1] += 0.04  # the world put cube 1 4 cm off the prediction
    wide, narrow = (step_predictions(Gaussian(s), [X, after], [(1, 0, 2, 0)])[0] for s in (0.03, 0.002))
    assert wide.miss_m == pytest.approx(0.04) and narrow.miss_m == pytest.approx(0.04)
    assert not wide.exceeded and narrow.exceeded
    assert wide.action_class == "cube on a cube" and wide.aleatoric_m > narrow.aleatoric_m
    record = wide.record()
    assert record["class"] == "cube on a cube" and record["bound_m"] == pytest.approx(wide.bound_m, abs=1e-6)
    assert step_predictions(Gaussian(0.01), [X], []) == []


def test_the_report_counts_misses_and_calibration_by_method_n_and_class(tmp_path):
    def row(problem, n, preds):
        return {"problem": problem, "n": n, "k": 1, "method": "bilevel", "solved": True, "success": True,
                "outcome": "success", "planning_time_s": 0.1, "predictions": preds}

    p = [{"class": "cube on a cube", "miss_m": m, "bound_m": 0.03, "epistemic_m": 0.01, "aleatoric_m": 0.01,
          "scene": scene} for m, scene in ((0.001, SCENES[0]), (0.025, SCENES[2]), (0.06, SCENES[2]), (0.01, None))]
    res = Results([row("a", 2, p[:2]), row("b", 3, p[2:])])
    figures = step_figures(p)
    assert figures["steps"] == 4 and figures["miss_ge_2cm_pct"] == 50.0 and figures["miss_ge_5cm_pct"] == 25.0
    assert figures["exceeded_pct"] == 25.0
    report, numbers = build_report(res, tmp_path)
    data = numbers["sections"]["calibration"]
    assert data["methods"]["bilevel"]["2"]["steps"] == 2 and data["methods"]["bilevel"]["3"]["exceeded_pct"] == 50.0
    assert data["classes"]["cube on a cube"]["steps"] == 4
    # by the scene a step starts from: rows that record it (the fourth step's row predates the split)
    assert data["scenes"][SCENES[0]]["steps"] == 1 and data["scenes"][SCENES[2]]["miss_ge_2cm_pct"] == 100.0
    assert SCENES[1] not in data["scenes"] and "By the scene the step starts from" in report
    assert "16. The Dynamics Model where the planner acts" in report
    json.dumps(numbers)
