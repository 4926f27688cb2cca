"""Skill geometry shared by the dataset, the model and its users: actions, arm motion, effects.

State ``X`` is an (n, 5) array per object: position (x, y, z) in metres and a one-hot type
(column 3 = small 5 cm cube, column 4 = large 5 x 25 x 5 cm bar along y). An action is
``(pick, grasp_offset, place, release_offset)`` with offsets in {-1, 0, +1} times
``OFFSET_M`` = 7.5 cm along world +y (blocks are axis-aligned in X).

Effect definition (the training target; the paper subtracts the arm's lateral movement)
-------------------------------------------------------------------------------------
The gripper's lateral (xy) movement is computable from X and the action alone::

    arm_xy = (p_place + d_release * 0.075 y_hat) - (p_pick + d_grasp * 0.075 y_hat)

The target effect for object i is its position change, minus ``arm_xy`` (z: 0) if and only if
i is the *pick* object of the action::

    e_i = X'_i[:3] - X_i[:3] - [i == pick] * (arm_x, arm_y, 0)

So a successful pick-place has target ~ (0, 0, dz) for the picked block whatever the distance
travelled, and a failed grasp (the block stays) has target -arm_xy. Subtracting from the
*pick* object (known from the action) rather than from the object actually grasped (known
only after execution) keeps the inverse exact at planning time::

    X'[:, :3] = X[:, :3] + e + onehot(pick) * (arm_x, arm_y, 0)

Failed grasps stay learnable because ``arm_xy`` is part of the pick object's action encoding
(see ``encode_actions``; the Symbolic Model goes without it and learns from the transitions that
moved the picked block, `moved_picks`); an object carried along without being the pick object (e.g. the
gripper reaches a block lying on top of the pick object) receives the arm motion through the
relational aggregation from the pick object's encoding.
"""
from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

OFFSET_M = 0.075
"""Grasp/release offset unit along world +y, metres."""
TYPE_NAMES = ("small", "large")
"""Column order of the one-hot type in X[:, 3:5]."""
STATE_DIM = 5
ACTION_ENC_DIM = 10
"""Per-object action encoding: is_pick, grasp one-hot(3), is_place, release one-hot(3), arm_xy(2)."""
WHOLE_ACTION_DIM = 10
"""Added with ``whole=True``: on the picked object the release one-hot(3) and the target's type(2), on the target
the grasp one-hot(3) and the picked object's type(2)."""


def action_encoding_dim(whole: bool = False) -> int:
    """Width of `encode_actions`' per-object encoding."""
    return ACTION_ENC_DIM + (WHOLE_ACTION_DIM if whole else 0)


def as_action_array(actions: np.ndarray | Sequence[Sequence[int]]) -> np.ndarray:
    """Actions as an int64 (B, 4) array; accepts a list of 4-tuples (e.g. PickPlace) or an array."""
    a = np.asarray(actions, dtype=np.int64)
    if a.ndim == 1 and a.shape[0] == 4:
        a = a[None]
    if a.ndim != 2 or a.shape[1] != 4:
        raise ValueError(f"actions must have shape (B, 4), got {a.shape}")
    return a


MOVED_M = 0.01
"""Metres: a transition moved its picked block when the block's position changed at least this much."""


def moved_picks(X: np.ndarray, X_next: np.ndarray, action: np.ndarray) -> np.ndarray:
    """(S,) bool: transitions whose picked block moved by at least MOVED_M (the rest grasped
    nothing or were blocked: 53-67 % of random actions). The paper's authors drop the transitions
    whose picked block was not lifted before learning symbols."""
    rows = np.arange(len(action))
    pick = np.asarray(action)[:, 0]
    return np.linalg.norm(X_next[rows, pick, :3] - X[rows, pick, :3], axis=-1) >= MOVED_M


def check_actions(actions: np.ndarray, n: int | np.ndarray) -> None:
    """Raise ValueError unless object indices are in [0, n) and offsets in {-1, 0, 1}."""
    n = np.asarray(n)
    for col, name in ((0, "pick"), (2, "place")):
        if np.any(actions[:, col] < 0) or np.any(actions[:, col] >= n):
            raise ValueError(f"action {name} index out of range for n={n.tolist()}")
    if np.any(np.abs(actions[:, [1, 3]]) > 1):
        raise ValueError("action offsets must be in {-1, 0, +1}")


def arm_displacement(X: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """Lateral gripper movement (B, 2) in metres from grasp point to release point.

    X: (B, N, 5) states (metres); action: (B, 4) long.
    """
    b = torch.arange(X.shape[0], device=X.device)
    p_pick = X[b, action[:, 0], :2]
    p_place = X[b, action[:, 2], :2]
    dy = (action[:, 3] - action[:, 1]).to(X.dtype) * OFFSET_M
    d = p_place - p_pick
    return torch.stack([d[:, 0], d[:, 1] + dy], dim=-1)


def arm_shift(X: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
    """(B, N, 3) displacement added to the effect target to get the absolute displacement:
    arm_xy on the pick object, zero elsewhere (metres)."""
    B, N, _ = X.shape
    shift = torch.zeros(B, N, 3, dtype=X.dtype, device=X.device)
    shift[torch.arange(B, device=X.device), action[:, 0], :2] = arm_displacement(X, action)
    return shift


def effect_targets(X: torch.Tensor, X_next: torch.Tensor, action: torch.Tensor,
                   mask: torch.Tensor) -> torch.Tensor:
    """Training target e (B, N, 3) in metres, zero at padded objects (see module docstring)."""
    e = X_next[..., :3] - X[..., :3] - arm_shift(X, action)
    return e * mask.unsqueeze(-1).to(e.dtype)


def encode_actions(X: torch.Tensor, action: torch.Tensor, arm_scale_m: float | torch.Tensor = 1.0,
                   arm: bool = True, whole: bool = False) -> torch.Tensor:
    """Per-object action encoding (B, N, `action_encoding_dim(whole)`).

    For each object: [is_pick, grasp-offset one-hot (if pick), is_place, release-offset one-hot
    (if place), arm_xy / arm_scale_m (if pick)]. Permuting objects permutes the rows. With
    ``arm=False`` the arm_xy columns are zero: the encoding is then purely symbolic (which objects,
    which offsets), so whatever the decoder needs about positions must pass through the bottleneck
    (the Symbolic Model; the paper's network gets no continuous displacement either). With ``whole=True``
    the picked object also reads the release offset and the target's type, and the target the grasp offset
    and the picked object's type: the picked block then knows where along what it lands, (release - grasp) *
    OFFSET_M from a cube's or a bar's centre, which decides whether a bar comes to rest on its target or
    beside it. In the paper's encoding these reach it only through its relations to the target, which the
    scene alone decides.
    """
    B, N, _ = X.shape
    dev, dt = X.device, X.dtype
    idx = torch.arange(N, device=dev)
    is_pick = (idx[None] == action[:, 0:1]).to(dt)                      # (B, N)
    is_place = (idx[None] == action[:, 2:3]).to(dt)
    grasp = torch.nn.functional.one_hot(action[:, 1] + 1, 3).to(dt)     # (B, 3)
    release = torch.nn.functional.one_hot(action[:, 3] + 1, 3).to(dt)
    arm_xy = arm_displacement(X, action) / arm_scale_m if arm else X.new_zeros(B, 2)  # (B, 2)
    parts = [
        is_pick[..., None],
        is_pick[..., None] * grasp[:, None],
        is_place[..., None],
        is_place[..., None] * release[:, None],
        is_pick[..., None] * arm_xy[:, None],
    ]
    if whole:
        b = torch.arange(B, device=dev)
        pick_type, place_type = X[b, action[:, 0], 3:5], X[b, action[:, 2], 3:5]  # (B, 2) one-hot types
        parts += [is_pick[..., None] * release[:, None], is_pick[..., None] * place_type[:, None],
                  is_place[..., None] * grasp[:, None], is_place[..., None] * pick_type[:, None]]
    return torch.cat(parts, dim=-1)
