"""How often do Dynamics Models miss on the transitions that moved their picked block?

    tamp collect --samples 3000 --objects 2,3,4 --seed 11 --sampling graspable --out runs/held
    .venv/bin/python bench/moving_misses.py --data runs/held --models tamp/pretrained runs/grasp

A step misses when some block lands 2 cm (5 cm) or more from where the model put it: the figure
`bench/dynamics.py` reports for the planner's executed steps, here on data no planner chose, so a
model's misses on moving steps in general are told apart from the planner's choice of steps. The mean
effect error over every block hides them: most random transitions move nothing. The first model is
the baseline, measured in the same run.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def misses(model, data) -> np.ndarray:
    """Per moving transition of `data`, the largest block distance (m) between prediction and outcome."""
    from learned.effects import moved_picks

    moving = moved_picks(data.X, data.X_next, data.action)
    out = []
    for n in np.unique(data.n):
        rows = np.flatnonzero((data.n == n) & moving)
        X, X_next, a = data.X[rows, :n].astype(float), data.X_next[rows, :n].astype(float), data.action[rows]
        effects = np.concatenate([model.predict_effects(X[i:i + 512], a[i:i + 512]) for i in range(0, len(rows), 512)])
        out.append(np.linalg.norm(X[:, :, :3] + effects - X_next[:, :, :3], axis=2).max(axis=1))
    return np.concatenate(out) if out else np.zeros(0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, nargs="+", required=True, help="dataset directories (tamp collect)")
    ap.add_argument("--models", type=Path, nargs="+", default=[Path("tamp/pretrained")],
                    help="Dynamics Models: a dynamics.pt or a models directory; the first is the baseline")
    args = ap.parse_args()

    import torch

    from learned import load_transitions
    from learned.ensemble import load_dynamics
    from tamp.planning.models import DYNAMICS_FILE

    torch.set_num_threads(1)
    data = load_transitions(args.data)
    baseline = None
    for path in args.models:
        model = load_dynamics(path / DYNAMICS_FILE if path.is_dir() else path)
        miss = misses(model, data)
        over2, over5 = 100 * np.mean(miss >= 0.02), 100 * np.mean(miss >= 0.05)
        line = f"{str(path):40s} {len(miss)} moving steps: >= 2 cm {over2:5.1f} %, >= 5 cm {over5:5.1f} %"
        if baseline is None:
            baseline = (over2, over5)
        else:
            line += f" ({over2 - baseline[0]:+.1f}, {over5 - baseline[1]:+.1f} points)"
        print(line, flush=True)


if __name__ == "__main__":
    main()
