"""Continuous Plan Verification (paper, Alg. 1 lines 9-14): roll a plan out with the Dynamics Model.

From X_init, each action's predicted displacement is added to the positions (X <- X + e_hat; block
types never change). A plan is verified iff the predicted final state is within tau_verify of X_goal.

The norm. The paper writes ||X_final - X_goal||_2 < tau over positions. Read literally over the
stacked (n, 3) positions, the same per-object error counts more the more objects there are, while
success is judged per object (every object within eps = 5 cm). We therefore use the per-object
maximum, max_i ||pos_i(X_final) - pos_i(X_goal)||_2 < tau (every object within tau), the same
form as the success test. The stacked norm is reported too (`error_stacked`) for comparison.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from tamp.errors import UserError

TAU_VERIFY = 0.07  # metres (the paper's choice)
EPS_SUCCESS = 0.05  # metres: success = every object within eps of its goal


@dataclass(frozen=True)
class VerifyConfig:
    """What counts as the goal, the one owner of the tolerances every stage tests against."""

    tau_verify: float = TAU_VERIFY  # metres: Level 1 takes a plan whose rollout ends this close (the paper's)
    eps: float = EPS_SUCCESS  # metres: success, every object within eps (the search's goal test, the loops, evaluation)
    confident: float = 0.035  # metres: a goal state predicted this close ends a search; a kept plan must end so

    def __post_init__(self) -> None:
        for name in ("tau_verify", "eps"):
            if not getattr(self, name) > 0:
                raise UserError(f"VerifyConfig.{name} must be positive, got {getattr(self, name)}")
        if not 0 < self.confident <= self.eps:
            raise UserError(f"VerifyConfig needs 0 < confident <= eps, got confident {self.confident} m, "
                            f"eps {self.eps} m")

    @property
    def misplaced(self) -> float:
        """Metres: the 2-D distance beyond which a block is off its goal (it needs an action): eps."""
        return self.eps


class DynamicsModel(Protocol):
    def predict_effect(self, X: np.ndarray, actions) -> np.ndarray:
        """(B, n, 3) absolute position displacements in metres for B actions on scene X (n, 5)."""


def goal_errors(X: np.ndarray, X_goal: np.ndarray) -> np.ndarray:
    """Per-object Euclidean position distance to the goal (n,), metres."""
    return np.linalg.norm(np.asarray(X)[:, :3] - np.asarray(X_goal)[:, :3], axis=1)


def goal_error(X: np.ndarray, X_goal: np.ndarray) -> float:
    """The largest per-object distance to the goal (metres): the verification and success measure."""
    return float(goal_errors(X, X_goal).max(initial=0.0))


def at_goal(X: np.ndarray, X_goal: np.ndarray, eps: float = EPS_SUCCESS) -> bool:
    """Every object within eps (metres) of its goal position."""
    return goal_error(X, X_goal) < eps


def rollout(model: DynamicsModel, X_init: np.ndarray, actions: Sequence) -> np.ndarray:
    """Predicted states (k + 1, n, 5) along the plan, X_init first (one forward pass per action)."""
    X = np.array(X_init, dtype=float)
    states = [X]
    for a in actions:
        e = model.predict_effect(X, np.asarray([tuple(a)], dtype=np.int64))[0]
        X = X.copy()
        X[:, :3] += e
        states.append(X)
    return np.stack(states)


@dataclass
class Verification:
    actions: tuple  # the plan, as 4-tuples
    trajectory: np.ndarray  # (k + 1, n, 5) predicted states
    errors: np.ndarray  # (n,) per-object distance of the predicted final state to the goal, metres
    tau: float  # metres

    @property
    def X_final(self) -> np.ndarray:
        return self.trajectory[-1]

    @property
    def error(self) -> float:
        """max_i ||pos_i(X_final) - pos_i(X_goal)||, metres (the verification measure)."""
        return float(self.errors.max(initial=0.0))

    @property
    def error_stacked(self) -> float:
        """||pos(X_final) - pos(X_goal)||_2 over all stacked positions, metres (the paper's literal norm)."""
        return float(np.sqrt(np.sum(self.errors ** 2)))

    @property
    def verified(self) -> bool:
        return self.error < self.tau


def predict_many(model: DynamicsModel, Xs: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """Displacements (B, n, 3), metres, of action b on scene Xs[b]: one forward pass if the model has
    `predict_effects` (the learned models), else one `predict_effect` call per distinct scene."""
    if hasattr(model, "predict_effects"):
        return model.predict_effects(Xs, actions)
    out = np.zeros((len(actions), Xs.shape[1], 3))
    for X in {Xs[b].tobytes(): Xs[b] for b in range(len(Xs))}.values():
        rows = np.flatnonzero(np.all(Xs == X, axis=(1, 2)))
        out[rows] = model.predict_effect(X, actions[rows])
    return out


def doubt(model: DynamicsModel, trajectory: np.ndarray, actions: Sequence) -> float:
    """Metres: the largest 95 % bound of a plan's steps (`learned.ensemble`: how far the farthest-off block may
    land from the prediction), each predicted from the plan's predicted state before it (`trajectory`, k + 1
    states for k actions); 0 for a model that gives no spread."""
    if not len(actions):
        return 0.0
    from learned.ensemble import distribution_of

    plan = np.asarray([tuple(int(v) for v in a) for a in actions], dtype=np.int64)
    return float(distribution_of(model, np.asarray(trajectory)[:len(plan)], plan).bound().max())


def verify_many(model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray, plans: Sequence[Sequence],
                tau: float = TAU_VERIFY) -> list[Verification]:
    """`verify` for many plans, sharing rollouts: each distinct plan prefix is predicted once, and
    all the prefixes of one length go through one batched forward pass (`predict_many`).

    Plans that agree on their first t actions share the predicted state after them, so M variants of
    a k-step plan cost at most k forward passes instead of M k.
    """
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    keyed = [tuple(tuple(int(v) for v in a) for a in plan) for plan in plans]
    states: dict[tuple, np.ndarray] = {(): X_init}
    for t in range(max((len(p) for p in keyed), default=0)):
        new = list(dict.fromkeys(plan[:t + 1] for plan in keyed if len(plan) > t and plan[:t + 1] not in states))
        if not new:
            continue
        Xs = np.stack([states[prefix[:t]] for prefix in new])
        effects = predict_many(model, Xs, np.asarray([prefix[t] for prefix in new], dtype=np.int64))
        for prefix, X, e in zip(new, Xs, effects):
            X_next = X.copy()
            X_next[:, :3] += e
            states[prefix] = X_next
    out = []
    for plan in keyed:
        trajectory = np.stack([states[plan[:t]] for t in range(len(plan) + 1)])
        out.append(Verification(plan, trajectory, goal_errors(trajectory[-1], X_goal), tau))
    return out


def states_pair(X_init, X_goal) -> tuple[np.ndarray, np.ndarray]:
    """X_init and X_goal as float arrays of one (n, 5) shape (ValueError otherwise): what every
    planner entry point takes."""
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    if X_init.shape != X_goal.shape or X_init.ndim != 2 or X_init.shape[1] != 5:
        raise ValueError(f"X_init and X_goal must both be (n, 5), got {X_init.shape} and {X_goal.shape}")
    return X_init, X_goal


def verify(model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray, actions: Sequence,
           tau: float = TAU_VERIFY) -> Verification:
    """Roll `actions` out from X_init with the Dynamics Model and compare with X_goal."""
    X_init, X_goal = states_pair(X_init, X_goal)
    trajectory = rollout(model, X_init, actions)
    return Verification(tuple(tuple(int(v) for v in a) for a in actions), trajectory,
                        goal_errors(trajectory[-1], X_goal), tau)
