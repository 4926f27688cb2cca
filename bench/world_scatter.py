"""Does the world scatter? The same action from the same scene, and from the scene moved by a millimetre.

    .venv/bin/python bench/world_scatter.py --scenes 300 --seed 7
    .venv/bin/python bench/world_scatter.py --scenes 800 --seed 1 --stacked --model tamp/pretrained/dynamics.pt

A random scene of 2-4 blocks (blocks apart on the table), one action among those that grasp a block
(`World.graspable_actions`), run three times: from the scene itself with motion seed 1, and with motion
seeds 2 and 3 from the scene with every block shifted on the table by up to `--jitter-mm` in x and y.
Among the steps that moved something (all three executed), how often two outcomes differ by 2 cm (5 cm)
or more: the part of a Dynamics Model's misses that no smooth prediction from X could avoid, since a
state observed to a millimetre does not decide the outcome.

`--stacked` measures where the planner's steps miss: before the measured action, 2-8 random graspable
actions, and only scenes that then hold a stack or a leaning block (`start_scene`) are kept. `--model`
prints a Dynamics Model's miss beside the scatter (its prediction from X against the first run), split by
the scene and by the blocks' tilt, which X does not hold.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

TILTED_DEG = 5.0  # a block whose up axis leans this far from vertical counts as tilted


def tilt_deg(X_WB) -> float:
    """Degrees between a block's pose's z axis (or its opposite) and the vertical."""
    return float(np.degrees(np.arccos(min(1.0, abs(X_WB.rotation().matrix()[2, 2])))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenes", type=int, default=300, help="random scenes, one action each (default 300)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--jitter-mm", type=float, default=1.0, help="largest shift of a block in x and y (default 1)")
    ap.add_argument("--stacked", action="store_true",
                    help="measure steps that start from a stack or a leaning block, after 2-8 random actions")
    ap.add_argument("--model", type=Path, help="a Dynamics Model whose miss is printed beside the scatter")
    args = ap.parse_args()
    if args.scenes < 1 or not args.jitter_mm >= 0:
        ap.error("--scenes must be at least 1 and --jitter-mm 0 or more")

    from tamp.sim import World

    model = None
    if args.model is not None:
        from learned.ensemble import load_dynamics
        from tamp.planning.models import require_kind

        try:
            model = load_dynamics(args.model)
            require_kind(model, "dynamics", args.model)
        except (OSError, ValueError) as e:  # a UserError is a ValueError
            ap.error(f"--model {args.model}: {e}")
    world = World()
    rng = np.random.default_rng(args.seed)
    rows: list[tuple] = []
    try:
        with tqdm(total=args.scenes, unit="scene") as bar:
            while bar.n < args.scenes:
                X0 = draw_scene(world, rng, args.stacked)
                if X0 is None:
                    continue
                bar.update()
                row = measure(world, rng, X0, args.jitter_mm / 1000, model)
                if row is not None:
                    rows.append(row)
    except KeyboardInterrupt:  # the steps measured so far are still worth their figures
        print(f"interrupted after {bar.n} of {args.scenes} scenes; the figures so far:")
    report(rows, bar.n, model is not None)


def draw_scene(world, rng: np.random.Generator, stacked: bool) -> np.ndarray | None:
    """A random scene of 2-4 blocks; with `stacked`, after 2-8 random graspable actions, and None unless it then
    holds a stack or a leaning block."""
    from tamp.planning.calibration import SCENES, start_scene

    X0 = world.reset(n_objects=int(rng.integers(2, 5)), seed=int(rng.integers(2**62)))
    if stacked:
        for _ in range(int(rng.integers(2, 9))):
            actions = world.graspable_actions()
            X0, _ = world.step(actions[rng.integers(len(actions))])
        if start_scene(X0) == SCENES[0]:
            return None
    return X0


def measure(world, rng: np.random.Generator, X0: np.ndarray, jitter_m: float, model) -> tuple | None:
    """One graspable action from the world's scene X0, run three times (motion seed 1 from the scene, seeds 2 and 3
    from it shifted by up to `jitter_m`): (start scene, a block tilted, the block placed on tilted, the largest
    distance between two outcomes, the model's miss against the first; nan without a model), or None unless all
    three executed and moved something."""
    from pydrake.math import RigidTransform

    from tamp.planning.calibration import start_scene
    from tamp.sim.skill import Scene
    from tamp.sim.world_types import StepStatus

    scene, q = world.scene, world.q.copy()
    actions = world.graspable_actions()
    action = actions[rng.integers(len(actions))]
    outcomes = []
    for motion_seed in (1, 2, 3):
        shifted = scene if motion_seed == 1 else Scene(scene.types, [
            RigidTransform(X_WB.rotation(), X_WB.translation() + np.r_[rng.uniform(-1, 1, 2) * jitter_m, 0.0])
            for X_WB in scene.X_WB])
        world.set_scene(shifted, q, motion_seed=motion_seed)
        X, info = world.step(action)
        outcomes.append(X if info.status == StepStatus.OK else None)
    runs = [X for X in outcomes if X is not None]
    if len(runs) < 3 or np.abs(runs[0][:, :3] - X0[:, :3]).max() < 0.01:
        return None
    scatter = max(np.linalg.norm(runs[i][:, :3] - runs[j][:, :3], axis=1).max() for i, j in ((0, 1), (0, 2), (1, 2)))
    miss = np.nan
    if model is not None:
        effect = model.predict_effect(X0, np.asarray([tuple(action)], dtype=np.int64))[0]
        miss = float(np.linalg.norm(X0[:, :3] + effect - runs[0][:, :3], axis=1).max())
    tilts = [tilt_deg(X_WB) for X_WB in scene.X_WB]
    return start_scene(X0), max(tilts) >= TILTED_DEG, tilts[action.place] >= TILTED_DEG, scatter, miss


def shares(d: np.ndarray) -> str:
    """The percentages of distances (metres) of 2 cm or more and of 5 cm or more."""
    return f"{100 * np.mean(d >= 0.02):5.1f} / {100 * np.mean(d >= 0.05):4.1f} %"


def report(rows: list, n_scenes: int, with_model: bool) -> None:
    """The share of steps whose outcomes differ (and, with a model, whose prediction missed) by 2 and 5 cm."""
    from tamp.planning.calibration import SCENES

    if not rows:
        print("no step moved anything")
        return
    kind = np.array([r[0] for r in rows])
    tilted, place_tilted = np.array([r[1] for r in rows]), np.array([r[2] for r in rows])
    scatter, miss = np.array([r[3] for r in rows]), np.array([r[4] for r in rows])
    groups = [("every step", np.ones(len(rows), bool))]
    groups += [(f"from {s}", kind == s) for s in SCENES if (kind == s).any()]
    groups += [(f"no block tilted {TILTED_DEG:g} deg or more", ~tilted),
               (f"a block tilted {TILTED_DEG:g} deg or more", tilted),
               ("the block placed on is tilted", place_tilted)]
    print(f"{len(rows)} moving steps of {n_scenes} scenes; largest scatter {100 * scatter.max():.2f} cm")
    print(f"{'':40s} {'steps':>6s}   scatter >= 2 / 5 cm" + ("   model miss >= 2 / 5 cm" if with_model else ""))
    for name, m in groups:
        if not m.any():
            continue
        line = f"{name:40s} {m.sum():6d}   {shares(scatter[m])}"
        if with_model:
            line += f"        {shares(miss[m])}"
        print(line)


if __name__ == "__main__":
    main()
