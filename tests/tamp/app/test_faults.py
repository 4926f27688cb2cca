"""Faults of a real cell: observation noise and one push, as `tamp evaluate --noise/--push` inject them
into closed loops. The push needs Drake's poses (no simulation runs)."""
from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RotationMatrix

from tamp.app.faults import Faults, _apart, footprint, push
from tamp.errors import UserError
from tamp.planning.config import LoopConfig
from tamp.planning.vocabulary import LARGE, SMALL
from tamp.sim.skill import Scene

pytestmark = pytest.mark.sim


def scene() -> Scene:
    """A bar turned 30 degrees with a cube on it, and a free cube on the table."""
    R = RotationMatrix.MakeZRotation(np.pi / 6)
    return Scene(np.array([LARGE, SMALL, SMALL]), [RigidTransform(R, [0.6, 0.0, 0.025]),
                                                    RigidTransform(R, [0.6, 0.0, 0.075]),
                                                    RigidTransform([0.7, 0.25, 0.025])])


def test_a_push_moves_one_free_block_by_the_asked_distance_to_free_space():
    faults = Faults(push_m=(0.03, 0.05))
    for seed in range(20):
        before = scene()
        after, note = push(before, faults, np.random.default_rng(seed))
        moved = [i for i in range(3) if not np.allclose(before.X_WB[i].translation(), after.X_WB[i].translation())]
        # the bar has a cube on it, the cube on the bar is not on the table: only block 2 may move
        assert moved == [2] and note.startswith("block 2 pushed")
        shift = after.X_WB[2].translation() - before.X_WB[2].translation()
        assert 0.03 <= np.linalg.norm(shift[:2]) <= 0.05 and shift[2] == 0
        assert np.allclose(after.X_WB[2].rotation().matrix(), before.X_WB[2].rotation().matrix())
        assert all(_apart(footprint(after, 2), footprint(after, j), 0.005) for j in (0, 1))


def test_no_free_block_no_push():
    boxed = Scene(np.array([SMALL, SMALL]), [RigidTransform([0.6, 0.0, 0.025]), RigidTransform([0.6, 0.0, 0.075])])
    boxed_in = Scene(np.array([SMALL, LARGE]), [RigidTransform([0.6, 0.0, 0.025]), RigidTransform([0.6, 0.0, 0.075])])
    for s in (boxed, boxed_in):
        after, note = push(s, Faults(push_m=(0.03, 0.05)), np.random.default_rng(0))
        assert note == "no free block had room to be pushed" and after is s


def test_observation_noise_has_the_asked_spread_and_leaves_heights_and_types():
    X = np.tile([[0.6, 0.0, 0.025, 1.0, 0.0]], (2000, 1))
    seen = Faults(noise_m=0.005).observe(X, np.random.default_rng(1))
    assert np.std(seen[:, :2] - X[:, :2]) == pytest.approx(0.005, rel=0.05)
    assert np.array_equal(seen[:, 2:], X[:, 2:]) and seen is not X  # resting blocks stay resting
    assert Faults().observe(X, np.random.default_rng(1)) is X


def test_footprints_apart_along_either_axis_are_apart():
    R = RotationMatrix.MakeZRotation(np.pi / 6)
    axis_y = np.array([-np.sin(np.pi / 6), np.cos(np.pi / 6)])  # the bar's long axis
    for offset, apart in ((0.16, True), (0.14, False)):  # bar half length 12.5 cm + cube half 2.5 cm = 15 cm
        s = Scene(np.array([LARGE, SMALL]), [RigidTransform(R, [0.6, 0.0, 0.025]),
                                            RigidTransform(R, [*(np.array([0.6, 0.0]) + offset * axis_y), 0.025])])
        assert _apart(footprint(s, 0), footprint(s, 1), 0.005) is apart


def test_noise_never_puts_touching_blocks_into_each_other():
    # a bar turned 30 degrees, end to end with a cube; a cube resting on the bar's other end
    yaw = RotationMatrix.MakeZRotation(np.pi / 6)
    end = np.array([0.6, 0.0]) + 0.15 * np.array([-np.sin(np.pi / 6), np.cos(np.pi / 6)])
    world = Scene(np.array([LARGE, SMALL, SMALL]), [RigidTransform(yaw, [0.6, 0.0, 0.025]),
                                                    RigidTransform(yaw, [*end, 0.025]),
                                                    RigidTransform(yaw, [0.6, 0.0, 0.075])])
    X = world.X()
    faults, overlapped = Faults(noise_m=0.005), 0
    for seed in range(200):
        raw = faults.observe(X, np.random.default_rng(seed))
        seen = faults.observe(X, np.random.default_rng(seed), world)
        overlapped += not _apart(footprint(world, 0, raw[0, :2]), footprint(world, 1, raw[1, :2]), 0.0)
        assert _apart(footprint(world, 0, seen[0, :2]), footprint(world, 1, seen[1, :2]), -1e-6)
        assert np.array_equal(seen[2], raw[2])  # the stacked cube is on another level: left as observed
        assert np.linalg.norm(seen[:2, :2] - raw[:2, :2], axis=1).max() < 0.03  # moved by the overlap only
    assert overlapped > 50  # the noise alone puts them into each other about half the time


@pytest.mark.parametrize("kwargs, words", [({"noise_m": -0.001}, "noise"), ({"noise_m": 0.2}, "noise"),
                                           ({"push_m": (0.05, 0.03)}, "push"), ({"push_m": (0.0, 0.03)}, "push")])
def test_bad_faults_are_user_errors(kwargs, words):
    with pytest.raises(UserError, match=words):
        Faults(**kwargs)


@pytest.mark.parametrize("flags, loop_keys, margin, looks", [
    (["--noise", "0.005"], "", 0.005, 2),  # the loop knows its observations' noise: 1 sigma, two looks
    (["--noise", "0.005"], "stop_margin = 0.0", 0.0, 2),  # a margin the configuration sets wins, looks follow noise
    (["--noise", "0.005"], "looks = 0", 0.005, 0),  # and looks it sets win
    ([], "stop_margin = 0.01", 0.01, 0),
    ([], "looks = 3", 0.0, 3),
    ([], "", 0.0, 0),  # exact observations: a second look sees the same
])
def test_tamp_evaluate_tells_the_loop_the_noise(tmp_path, flags, loop_keys, margin, looks):
    from evaluation.cli import _eval_config
    from tamp.app.cli import build_parser

    config = tmp_path / "c.toml"
    config.write_text(f"[loop]\n{loop_keys}\n")
    args = build_parser().parse_args(["evaluate", "--models", "pretrained", "--problems", "p.jsonl", "--out", "o",
                                      "--config", str(config), *flags])
    loop = _eval_config(args).planner.loop
    assert loop.stop_margin == pytest.approx(margin) and loop.looks == looks
    assert loop.max_actions == LoopConfig().max_actions  # the rest as the defaults
