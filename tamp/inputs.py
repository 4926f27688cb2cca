"""The pieces of JSON Schema that several of tamp's input files share (problem files and sets, plan
files, trajectory files, result rows), and the one range of seeds every command and file takes.
Standard library and `guarded` only, so every layer may use them."""
from __future__ import annotations

SEED_LIMIT = 2**63  # seeds are integers in [0, 2^63): numpy's generators and every --seed flag take them
MAX_DOMAINS = 10_000  # sampled domains at most: the paper's N is 100; 10,000 of a 21,000-operator domain hold 1.7 GB
SEED = {"type": "integer", "minimum": 0, "maximum": SEED_LIMIT - 1}
OFFSET = {"enum": [-1, 0, 1]}  # a grasp or release offset, in steps of 7.5 cm
BLOCK = {"type": "integer", "minimum": 0}  # an index into the scene's blocks (checked against n after the schema)
# (pick, grasp_offset, place, release_offset)
ACTION = {"type": "array", "minItems": 4, "maxItems": 4, "items": [BLOCK, OFFSET, BLOCK, OFFSET]}
# a block of a scene: x, y, z (m) and its one-hot type (small, large); one-hot is checked after the schema
SCENE_ROW = {"type": "array", "minItems": 5, "maxItems": 5, "items": {"type": "number"}}
SCENE = {"type": "array", "minItems": 1, "items": SCENE_ROW}


def blocks_out_of_range(actions: list, n: int) -> int | None:
    """The index of the first action (schema-checked) whose pick or place is not one of n blocks, or None."""
    return next((i for i, a in enumerate(actions) if a[0] >= n or a[2] >= n), None)
