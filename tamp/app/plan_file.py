"""Plan files: JSON with the initial scene and the actions, e.g.

    {"X": [[0.6, 0.15, 0.025, 1, 0], [0.7, -0.1, 0.025, 0, 1]],
     "actions": [[0, 0, 1, 0]]}

`X` is (n, 5): x, y, z in metres and a one-hot type (small cube, large bar); each action is
(pick, grasp_offset, place, release_offset), naming blocks of the scene. `X_init` is accepted for `X`.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from guarded import Schema, read_json
from tamp.errors import UserError
from tamp.inputs import ACTION, SCENE, blocks_out_of_range
from tamp.planning.validate import check_scene
from tamp.planning.vocabulary import PickPlace, action_words


def fmt_action(a) -> str:
    """An action as `tamp plan`, `tamp demo` and the per-step view print it."""
    return action_words(a)


PLAN = Schema({"type": "object", "required": ["actions"], "additionalProperties": False,
               "properties": {"X": SCENE, "X_init": SCENE,
                              "actions": {"type": "array", "minItems": 1, "maxItems": 1000, "items": ACTION}}})


def load_plan_file(path: str | Path) -> tuple[np.ndarray, list[PickPlace]]:
    """Read and check a plan file (the guarded reader, `PLAN`, then the scene); errors name the file
    and the field."""
    data = read_json(path, "plan file")
    PLAN.check(data, str(path))
    key = "X" if "X" in data else "X_init" if "X_init" in data else None
    if key is None:
        raise UserError(f"{path}: missing field 'X' (the initial scene, n rows of x, y, z, small, large)")
    X = np.array(data[key], dtype=float)
    check_scene(X, where=str(path), field=key, upright=True)  # the scene is placed as given
    actions = data["actions"]
    if (bad := blocks_out_of_range(actions, len(X))) is not None:
        raise UserError(f"{path}: actions[{bad}]: {actions[bad]} names a block beyond the scene's {len(X)} "
                        f"(0..{len(X) - 1})")
    return X, [PickPlace(*a) for a in actions]
