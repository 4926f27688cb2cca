"""Does a Dynamics Model predict effects in scenes with more objects than it was trained on?

    tamp collect --samples 1200 --objects 4,5,6 --out runs/d456 --workers 2 --seed 11
    .venv/bin/python bench/generalization.py --data runs/d456            # the bundled Dynamics Model
    .venv/bin/python bench/generalization.py --data runs/d678 --trained-up-to 6

Per object count of the dataset: the mean effect error (cm per object, `learned.train.evaluate`) of
the model with its object limit lifted, beside predicting no motion (`zero`) and "the picked block
follows the gripper, nothing else moves" (`arm`), the error over the objects an action moves
(picked block displaced by more than 2 cm), and the share of those moving steps whose worst block lands
2 cm or more from its prediction (`bench/moving_misses.py`'s miss, the figure a closed loop feels: the
mean over objects falls as more blocks stand still). The counts the model was trained on are the
baseline measured in the same run.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, required=True, help="dataset directory (tamp collect)")
    ap.add_argument("--model", type=Path, default=None, help="Dynamics Model (default: the bundled one)")
    ap.add_argument("--trained-up-to", type=int, default=None,
                    help="the most objects the model's training data held, the baseline count (default: its "
                         "object limit, which a raised limit puts above the data's: the bundled ones saw up to 6)")
    args = ap.parse_args()

    import torch

    import learned
    from bench.moving_misses import misses
    from learned.train import evaluate
    from tamp.planning.models import DYNAMICS_FILE, pretrained_dir

    torch.set_num_threads(1)
    path = args.model or pretrained_dir() / DYNAMICS_FILE
    model = learned.load_model(path)
    trained_for = args.trained_up_to or model.config.n_max
    data = learned.load_transitions(args.data)
    model.config = dataclasses.replace(model.config, n_max=max(model.config.n_max, int(data.X.shape[1])))
    moved = learned.moved_picks(data.X, data.X_next, data.action)
    print(f"{path} (trained for up to {trained_for} objects) on {args.data}: {len(data)} transitions")
    print(f"{'n':>2} {'transitions':>11} {'error cm':>9} {'zero cm':>8} {'arm cm':>7} {'moved: error cm':>16} "
          f"{'zero cm':>8} {'worst >= 2 cm, of steps':>23}  ratio to n = {min(trained_for, int(data.n.max()))}")
    reference = None
    for n in np.unique(data.n).tolist():
        rows = np.flatnonzero(data.n == n)
        every = evaluate(model, data.subset(rows))
        movers = evaluate(model, data.subset(rows[moved[rows]])) if moved[rows].any() else None
        worst = misses(model, data.subset(rows))
        if n == min(trained_for, int(data.n.max())):
            reference = every["err_cm"]
        ratio = "" if reference is None else f"{every['err_cm'] / reference:.2f}x"
        print(f"{n:>2} {len(rows):>11} {every['err_cm']:9.3f} {every['zero_cm']:8.3f} {every['arm_cm']:7.3f} "
              f"{movers['err_cm'] if movers else float('nan'):16.3f} "
              f"{movers['zero_cm'] if movers else float('nan'):8.3f} "
              f"{100 * np.mean(worst >= 0.02) if len(worst) else float('nan'):13.1f} % of {len(worst):4d}  {ratio}"
              + ("  (beyond the trained counts)" if n > trained_for else ""))


if __name__ == "__main__":
    main()
