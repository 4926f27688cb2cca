"""Problem files, problem sets and trajectory files, property-tested: what a writer writes its reader reads back
equal, and a write cut short by a full disk leaves the file that was there and nothing else."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from evaluation.problems import write_problems
from tamp.app.problem import Problem, load_problem, read_problem_set, save_problem
from tests.paths import ROOT
from tests.test_no_data_loss import written_on_a_small_disk

HELD_OUT = read_problem_set(ROOT / "results" / "problems" / "strict-n2-4-s781.jsonl.gz")  # valid scenes, n = 2-4
CASES = settings(max_examples=int(os.environ.get("TAMP_FUZZ_EXAMPLES", "60")), deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])


@st.composite
def problems(draw) -> Problem:
    """A held-out problem, its blocks in another order, with metadata of any kind a problem may carry."""
    p = draw(st.sampled_from(HELD_OUT))
    order = draw(st.permutations(range(p.n)))
    k = draw(st.none() | st.integers(1, 5))
    actions = tuple(draw(st.lists(st.tuples(st.integers(0, p.n - 1), st.integers(-1, 1), st.integers(0, p.n - 1),
                                            st.integers(-1, 1)), max_size=k or 0)))
    return Problem(p.X_init[list(order)], p.X_goal[list(order)], k, draw(st.integers(0, 2**62)),
                   draw(st.none() | st.text(min_size=1, max_size=30)), actions,
                   draw(st.none() | st.sampled_from(["strict", "paper"])), None, draw(st.none() | st.integers(0, 9)))


def same(a: Problem, b: Problem) -> bool:
    return a.to_dict() == b.to_dict() and np.array_equal(a.X_init, np.round(b.X_init, 5))


@CASES
@given(problem=problems())
def test_a_problem_file_reads_back_equal(tmp_path, problem):
    path = tmp_path / "p.json"
    save_problem(path, problem)
    assert same(load_problem(path), problem)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.json"]  # no temporary left


@CASES
@given(problem=problems(), new=problems(), room=st.integers(0, 2000))
def test_a_problem_write_cut_short_leaves_the_old_file(tmp_path, monkeypatch, problem, new, room):
    folder = tmp_path / f"w{room}"
    folder.mkdir(exist_ok=True)
    path = folder / "p.json"
    save_problem(path, problem)
    wrote = written_on_a_small_disk(monkeypatch, room, lambda: save_problem(path, new), path)
    assert sorted(p.name for p in folder.iterdir()) == ["p.json"]
    assert same(load_problem(path), new if wrote else problem)


@CASES
@given(chosen=st.lists(problems(), min_size=1, max_size=4))
def test_a_problem_set_reads_back_equal_in_order(tmp_path, chosen):
    named = [Problem(p.X_init, p.X_goal, p.k, p.seed, f"p{i}", p.actions, p.protocol, p.moved, p.run)
             for i, p in enumerate(chosen)]
    path = write_problems(tmp_path / "set.jsonl", named)
    back = read_problem_set(path)
    assert len(back) == len(named) and all(same(a, b) for a, b in zip(back, named))


@pytest.fixture(scope="module")
def trajectory_file(tmp_path_factory) -> Path:
    """A one-action trajectory file of the fast world (the cube onto the bar)."""
    from tamp.app.runner import execute_plan, executed_trajectory
    from tamp.sim.trajectory_file import write_trajectory

    X_init = np.array([[0.60, 0.15, 0.025, 1, 0], [0.70, -0.10, 0.025, 0, 1]])
    X_goal = np.array([[0.70, -0.10, 0.075, 1, 0], [0.70, -0.10, 0.025, 0, 1]])
    ex = execute_plan([(0, 0, 1, 0)], X_init, X_goal, "fast")
    return write_trajectory(tmp_path_factory.mktemp("trajectory") / "t.json", executed_trajectory(ex, "test"))


@pytest.mark.sim
@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(room=st.integers(0, 40_000))
def test_a_trajectory_reads_back_equal_and_a_write_cut_short_leaves_the_old_file(tmp_path, monkeypatch, room,
                                                                                  trajectory_file):
    from tamp.sim.trajectory_file import read_trajectory, to_document, write_trajectory

    plan = read_trajectory(trajectory_file)
    assert to_document(plan) == to_document(read_trajectory(write_trajectory(tmp_path / "again.json", plan)))
    folder = tmp_path / f"w{room}"
    folder.mkdir(exist_ok=True)
    path = folder / "t.json"
    old = b"{}\n"  # whatever was there
    path.write_bytes(old)
    wrote = written_on_a_small_disk(monkeypatch, room, lambda: write_trajectory(path, plan), path)
    assert sorted(p.name for p in folder.iterdir()) == ["t.json"]
    assert wrote == (trajectory_file.stat().st_size <= room)
    assert path.read_bytes() == (trajectory_file.read_bytes() if wrote else old)
