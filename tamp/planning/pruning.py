"""Goal-oriented action pruning: the actions the continuous search (`tamp.planning.search`) offers from a state.

The paper's rule: objects whose 2-D (x, y) distance to their goal exceeds
`misplaced` are misplaced; for each misplaced o_i, the actions from o_i onto the other object o_j
closest (2-D) to o_i's goal position and from o_i onto itself, each with all 9 (grasp, release)
offset pairs: at most 18 per misplaced object. If no object is misplaced in 2-D but the goal test
fails (only heights differ), the objects off their goal in 3-D are treated as misplaced (our
extension; without it such states have no successors).

Release-point targets (our extension, `release_targets`): a block placed on o_j at release offset r,
grasped at offset g, ends near pos_j + (r - g) * OFFSET_STEP along the offset axis (world +y for
an axis-aligned block; X holds no yaw), so the object closest to o_i's goal need not be the one to
place it on: another, one or two offsets away, may put it right there. The object with the release
point closest (2-D) to o_i's goal is added as a third target when it is not the closest object
(at most 27 actions per misplaced object). From 4 blocks on the closest object is often the wrong
one, and without this target the search runs to its node budget (docs/beyond-the-paper.md). For a goal
above the table, the object the block would rest on is a target too (at most 36 actions): of the objects
at the level one block height below the goal, the one with the release point closest to it (the top of a
stack, where the object closest in 2-D may be its bottom: a tower of three bars was otherwise reached only
by detours; or a bar beside the goal's column, on whose end the block rests); with no object at that level
(a leaning block's goal), the object closest (3-D) to the place one block height below the goal.

"""
from __future__ import annotations

import numpy as np

from tamp.planning.verify import EPS_SUCCESS
from tamp.planning.vocabulary import BLOCK_HEIGHT, OFFSET_STEP, OFFSETS, ON_TABLE

_PAIRS = np.array([(g, r) for g in OFFSETS for r in OFFSETS], dtype=np.int64)  # the 9 offset pairs
# metres: where a placed block's centre ends relative to its target object's, (r - g) * OFFSET_STEP along y
_RELEASE_SHIFTS = np.array([(0.0, s * OFFSET_STEP) for s in range(-2, 3)])
_LEVEL = BLOCK_HEIGHT / 2  # metres: an object whose centre is this close to a height stands at that level of a stack


def misplaced_objects(X: np.ndarray, X_goal: np.ndarray, misplaced: float = EPS_SUCCESS,
                      eps: float = EPS_SUCCESS) -> np.ndarray:
    """Indices of the objects farther than `misplaced` (2-D) from their goal; if none, those at least
    `eps` off in 3-D (only heights differ). The objects a goal-oriented plan picks up."""
    wrong = np.flatnonzero(np.linalg.norm(X[:, :2] - X_goal[:, :2], axis=1) > misplaced)
    if wrong.size == 0:
        wrong = np.flatnonzero(np.linalg.norm(X[:, :3] - X_goal[:, :3], axis=1) >= eps)
    return wrong


def goal_oriented_actions(X: np.ndarray, X_goal: np.ndarray, misplaced: float = EPS_SUCCESS,
                          eps: float = EPS_SUCCESS, release_targets: bool = True) -> np.ndarray:
    """The pruned action set A(X) as a (B, 4) int array (see the module docstring); targets per misplaced
    object: the closest other object, the one with the closest release point and, for a goal above the
    table, the one below its goal (if `release_targets`, each when it differs), itself."""
    wrong = misplaced_objects(X, X_goal, misplaced, eps)
    n = len(X)
    if wrong.size == 0:
        return np.zeros((0, 4), np.int64)
    targets = [[i] for i in wrong.tolist()]  # each misplaced object onto itself
    if n > 1:
        goals = X_goal[wrong, None, :2]  # (w, 1, 2)
        mine = (np.arange(len(wrong)), wrong)
        dist = np.linalg.norm(X[None, :, :2] - goals, axis=2)  # (w, n)
        dist[mine] = np.inf
        closest = best = below = np.argmin(dist, axis=1)
        if release_targets:
            points = X[:, None, :2] + _RELEASE_SHIFTS[None]  # (n, 5, 2) release points of every object
            reach = np.linalg.norm(points[None] - goals[:, None], axis=3).min(axis=2)  # (w, n)
            reach[mine] = np.inf
            best = np.argmin(reach, axis=1)
            below = _below_goals(X, X_goal[wrong], mine, closest, reach)
        targets = [list(dict.fromkeys(row)) for row in zip(closest.tolist(), best.tolist(), below.tolist(),
                                                            wrong.tolist())]
    return np.concatenate([_actions_onto(i, row) for i, row in zip(wrong, targets)])


def _below_goals(X: np.ndarray, goals: np.ndarray, mine: tuple, closest: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """Per goal position (w, 3): for a goal above the table, the object a block placed there rests on: of the
    objects at the level one block height below it, the one whose release point (`reach`, (w, n) metres) is
    closest; with none at that level, the object closest (3-D) to the place one block height below it; for a
    goal on the table, `closest`."""
    support = goals[:, None, :3] - np.array([0.0, 0.0, BLOCK_HEIGHT])
    dist = np.linalg.norm(X[None, :, :3] - support, axis=2)  # (w, n)
    dist[mine] = np.inf
    level = np.abs(X[None, :, 2] - support[:, :, 2]) < _LEVEL  # (w, n): the objects at the height it rests on
    level[mine] = False
    on_level = np.where(level.any(axis=1), np.argmin(np.where(level, reach, np.inf), axis=1), np.argmin(dist, axis=1))
    return np.where(goals[:, 2] > ON_TABLE, on_level, closest)


def _actions_onto(i: int, targets) -> np.ndarray:
    """The (9 len(targets), 4) actions picking object i and placing it on each target, every offset pair."""
    rows = np.empty((9 * len(targets), 4), np.int64)
    rows[:, 0] = i
    rows[:, 1] = np.tile(_PAIRS[:, 0], len(targets))
    rows[:, 2] = np.repeat(np.asarray(targets, dtype=np.int64), 9)
    rows[:, 3] = np.tile(_PAIRS[:, 1], len(targets))
    return rows


def all_actions(n: int) -> np.ndarray:
    """All 9 n^2 actions (pick, grasp_offset, place, release_offset)."""
    return np.array([(i, g, j, r) for i in range(n) for g in OFFSETS for j in range(n) for r in OFFSETS],
                    dtype=np.int64)
