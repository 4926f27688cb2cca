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
    misplaced: float = EPS_SUCCESS  # metres: 2-D distance beyond which a block is off its goal (it needs an action)

    def __post_init__(self) -> None:
        for name in ("tau_verify", "eps", "misplaced"):
            if not getattr(self, name) > 0:
                raise UserError(f"VerifyConfig.{name} must be positive, got {getattr(self, name)}")
        if not 0 < self.confident <= self.eps:
            raise UserError(f"VerifyConfig needs 0 < confident <= eps, got confident {self.confident} m, "
                            f"eps {self.eps} m")


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


def fragility(model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray, actions: Sequence,
              eps: float = EPS_SUCCESS, noise: float = 0.005, samples: int = 32, seed: int = 0) -> float:
    """Fraction of `samples` perturbed rollouts of the plan that end with some object eps or farther
    (metres) from its goal: before each action every block's (x, y) input to the Dynamics Model is
    shifted by Gaussian noise of `noise` metres, and the predicted effect is added to the unperturbed
    positions.

    A plan whose prediction reaches the goal only from exactly these positions is one whose outcome
    the model finds uncertain (a block released at an edge, on a tilted block): in the held-out rows
    such plans ended off the goal in execution far more often than their predicted error says.
    One batched forward pass per action; deterministic for a given `seed`.
    """
    X_init, X_goal = states_pair(X_init, X_goal)
    plan = np.asarray([tuple(int(v) for v in a) for a in actions], dtype=np.int64).reshape(-1, 4)
    rng = np.random.default_rng(seed)
    Xs = np.repeat(X_init[None], samples, axis=0)
    for a in plan:
        inputs = Xs.copy()
        inputs[:, :, :2] += rng.normal(0.0, noise, size=(samples, len(X_init), 2))
        Xs = Xs.copy()
        Xs[:, :, :3] += predict_many(model, inputs, np.repeat(a[None], samples, axis=0))
    worst = np.linalg.norm(Xs[:, :, :3] - X_goal[None, :, :3], axis=2).max(axis=1)
    return float(np.mean(worst >= eps))


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


def refine_skeleton(model: DynamicsModel, X_init: np.ndarray, X_goal: np.ndarray,
                    options: Sequence[Sequence], width: int, tau: float = TAU_VERIFY,
                    also: Sequence | None = None) -> tuple[list[Verification], Verification | None]:
    """Concrete plans for a symbolic skeleton, best first, verified: a beam search with the Dynamics Model.

    `options[t]` are the actions that can take step t of the skeleton (every action that leads
    from its symbolic state to the next: `SymbolicPlanner.skeleton_options`). Step by step, every
    kept partial plan is extended by every option (one batched forward pass per step) and the
    `width` best are kept: by the sum of per-object distances to the goal (the continuous
    search's heuristic) after an intermediate step, by the largest per-object distance (the
    verification measure) after the last; plans that predict the same state (to 1 mm) count once.
    Which offsets and which of several symbolically alike objects a plan uses decides where the
    blocks end, and symbols of a few bits cannot say; the Dynamics Model can. The rollouts of the
    search are the plans' verifications (the same predictions as `verify`). `also`, a plan of the
    skeleton's length (the ranked plan itself), is rolled out in the same forward passes and returned
    verified beside the best plans (None without it).
    """
    X_init, X_goal = np.asarray(X_init, dtype=float), np.asarray(X_goal, dtype=float)
    beam: list[tuple[tuple, list[np.ndarray]]] = [((), [X_init])]
    extra = None if also is None else [tuple(int(v) for v in a) for a in also]
    if extra is not None and len(extra) != len(options):
        raise ValueError(f"`also` has {len(extra)} actions, the skeleton {len(options)} steps")
    extra_states = [X_init]
    for t, step in enumerate(options):
        step = [tuple(int(v) for v in a) for a in step]
        if not step or width < 1:
            return [], (None if extra is None else verify_many(model, X_init, X_goal, [extra], tau)[0])
        plans = [(plan + (a,), states) for plan, states in beam for a in step]
        Xs = np.repeat(np.stack([states[-1] for _, states in beam]), len(step), axis=0)
        actions = [p[-1] for p, _ in plans]
        if extra is not None:  # the extra plan's step t rides along in the same pass
            Xs = np.concatenate([Xs, extra_states[-1][None]])
            actions.append(extra[t])
        effects = predict_many(model, Xs, np.asarray(actions, dtype=np.int64))
        Xs = Xs.copy()
        Xs[:, :, :3] += effects
        if extra is not None:
            extra_states.append(Xs[-1])
            Xs = Xs[:-1]
        dist = np.linalg.norm(Xs[:, :, :3] - X_goal[None, :, :3], axis=-1)
        score = dist.max(axis=1) if t == len(options) - 1 else dist.sum(axis=1)
        beam, seen = [], set()
        for b in np.argsort(score, kind="stable"):
            key = np.round(Xs[b, :, :3] * 1000).astype(np.int64).tobytes()
            if key not in seen:
                seen.add(key)
                beam.append((plans[b][0], plans[b][1] + [Xs[b]]))
                if len(beam) == width:
                    break
    beam = [(plan, states) for plan, states in beam if plan]
    if beam:  # every plan's per-object errors in one operation
        finals = np.stack([states[-1][:, :3] for _, states in beam])
        errors = np.linalg.norm(finals - X_goal[None, :, :3], axis=-1)
    best = [Verification(plan, np.stack(states), errors[b], tau) for b, (plan, states) in enumerate(beam)]
    if extra is None:
        return best, None
    return best, Verification(tuple(extra), np.stack(extra_states), goal_errors(extra_states[-1], X_goal), tau)


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
