"""Is a missed step the model's fault or the state's? Executed steps replayed from their observed state alone.

    .venv/bin/python bench/replay_steps.py --rows runs/practice/round-1/eval/rows.jsonl --models M

For every executed transition (X, a, X') of the rows (`transitions`), the fast world is reset to X (blocks
upright and axis-aligned, as X says: the state holds no orientation) and runs a again, from X and from X
with every block's (x, y) shifted by 2 mm of Gaussian noise (three draws). It prints, for the steps the
Dynamics Model missed by 2 cm or more and for the others:

- how far the replay from X landed from what the world did (X'): large when the outcome depended on what X
  does not hold (a block's yaw or tilt after earlier steps);
- how far it landed from the model's prediction: small when the model is right about X as X describes it;
- how far the 2 mm replays landed from the replay from X: large when the outcome flips with millimetres.

Each distance is the largest over blocks (metres), as the rows' `miss_m`.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def worst(A: np.ndarray, B: np.ndarray) -> float:
    return float(np.linalg.norm(A[:, :3] - B[:, :3], axis=1).max())


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rows", type=Path, required=True, help="a `tamp evaluate` rows.jsonl with `transitions`")
    p.add_argument("--models", default="tamp/pretrained", help="the models whose Dynamics Model judged the steps")
    p.add_argument("--limit", type=int, default=400, help="transitions replayed at most")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    from tamp.app.runner import executing_world
    from tamp.errors import UserError
    from tamp.planning.models import load_models

    model = load_models(args.models, need_symbolic=False).require_dynamics()
    steps = [t for line in args.rows.read_text().splitlines() for t in (json.loads(line).get("transitions") or [])]
    steps = steps[:args.limit]
    world, rng = executing_world("fast"), np.random.default_rng(args.seed)
    out: dict[bool, list[tuple[float, float, float]]] = {True: [], False: []}
    unplaceable = {True: 0, False: 0}  # X cannot be set up upright and axis-aligned (blocks would overlap)
    for t in steps:
        X, X_next, a = np.asarray(t["X"]), np.asarray(t["X_next"]), tuple(t["action"])
        predicted = X.copy()
        predicted[:, :3] += model.predict_effect(X, np.asarray([a]))[0]
        missed = worst(X_next, predicted) >= 0.02
        try:
            world.reset(X=X, seed=args.seed)
        except UserError:
            unplaceable[missed] += 1
            continue
        replay, _ = world.step(a)
        jitter = []
        for _ in range(3):
            Y = X.copy()
            Y[:, :2] += rng.normal(0.0, 0.002, size=(len(X), 2))
            try:
                world.reset(X=Y, seed=args.seed)
            except UserError:
                continue
            jitter.append(worst(world.step(a)[0], replay))
        out[missed].append((worst(replay, X_next), worst(replay, predicted), max(jitter, default=np.nan)))
    for missed in (True, False):
        rows = np.asarray(out[missed]).reshape(-1, 3)
        if not len(rows):
            continue
        label = "missed by >= 2 cm" if missed else "within 2 cm"
        print(f"{label}: {len(rows)} steps replayed, {unplaceable[missed]} whose X cannot stand upright and "
              "axis-aligned (tilted or rotated blocks)")
        for k, what in enumerate(("replay from X vs the world's X'", "replay from X vs the prediction",
                                  "2 mm replays vs the replay from X")):
            d = rows[:, k][~np.isnan(rows[:, k])]
            print(f"  {what}: median {100 * np.median(d):.2f} cm, >= 2 cm in {100 * np.mean(d >= 0.02):.0f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
