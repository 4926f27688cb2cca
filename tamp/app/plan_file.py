"""Plan files: JSON with the initial scene and the actions, e.g.

    {"X": [[0.6, 0.15, 0.025, 1, 0], [0.7, -0.1, 0.025, 0, 1]],
     "actions": [[0, 0, 1, 0]]}

`X` is (n, 5): x, y, z in metres and a one-hot type (small cube, large bar); each action is
(pick, grasp_offset, place, release_offset). `X_init` is accepted for `X`.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from tamp.errors import UserError
from tamp.planning.structs import PickPlace
from tamp.planning.validate import check_scene


def fmt_action(a) -> str:
    """An action as `tamp plan`, `tamp demo` and the per-step view print it."""
    return f"pick {a[0]} at {a[1]:+d}, place on {a[2]} at {a[3]:+d}"


def read_json_file(path: str | Path, kind: str):
    """The parsed content of a JSON file; a missing file or bad JSON is an error naming the file."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"no {kind} file at {path}")
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise UserError(f"{path}: not valid JSON ({error})") from None


def load_plan_file(path: str | Path) -> tuple[np.ndarray, list[PickPlace]]:
    """Read and check a plan file; errors name the file and the field."""
    path = Path(path)
    data = read_json_file(path, "plan")
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object with fields 'X' and 'actions'")
    key = "X" if "X" in data else "X_init" if "X_init" in data else None
    if key is None:
        raise UserError(f"{path}: missing field 'X' (the initial scene, n rows of x, y, z, small, large)")
    try:
        X = np.array(data[key], dtype=float)
    except (TypeError, ValueError):
        raise UserError(f"{path}: field '{key}' must be a list of [x, y, z, small, large] rows") from None
    if X.ndim != 2 or X.shape[1] != 5:
        raise UserError(f"{path}: field '{key}' must have rows of 5 numbers, got shape {X.shape}")
    check_scene(X, where=str(path), field=key, upright=True)  # the scene is placed as given
    if "actions" not in data:
        raise UserError(f"{path}: missing field 'actions' (a list of [pick, grasp_offset, place, release_offset])")
    actions = data["actions"]
    if not isinstance(actions, list) or not actions:
        raise UserError(f"{path}: field 'actions' must be a non-empty list")
    plan = []
    for k, a in enumerate(actions):
        if not (isinstance(a, list) and len(a) == 4 and all(isinstance(v, int) and not isinstance(v, bool) for v in a)):
            raise UserError(f"{path}: actions[{k}] must be 4 integers "
                            f"[pick, grasp_offset, place, release_offset], got {a!r}")
        plan.append(PickPlace(*a))
    return X, plan


def write_plan_file(path: str | Path, X: np.ndarray, plan: list) -> None:
    Path(path).write_text(json.dumps({"X": np.round(np.asarray(X), 5).tolist(),
                                      "actions": [list(map(int, a)) for a in plan]}, indent=1))
