"""Data structures shared by the symbolic package (all plain data, no behaviour beyond views).

Conventions used everywhere in `symbolic/`:
- An action is a 4-tuple ``(pick, grasp_offset, place, release_offset)`` of ints, objects are indices
  ``0..n-1`` of the scene, offsets are in {-1, 0, +1}; ``pick == place`` is allowed.
- Unary bits have shape (n, d_z), relation bits (K, n, n); both hold 0/1.
- A lifted operator has ``arity`` parameters: parameter 0 is the picked object, parameter 1 the
  target object when it differs from the picked one, the remaining parameters are the other objects
  of the scene the transition was observed in (in a canonical order, see `operators.py`).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

Action = tuple[int, int, int, int]
OFFSETS = (-1, 0, 1)


@dataclass(frozen=True, order=True)
class Effect:
    """A symbolic effect: which bits flip, in parameter indices of the operator.

    unary_flips: (param, bit) pairs; rel_flips: (relation, param_i, param_j) triples. A flip turns
    the bit to the opposite of its (fully specified) precondition value.
    """

    unary_flips: tuple[tuple[int, int], ...] = ()
    rel_flips: tuple[tuple[int, int, int], ...] = ()

    @property
    def is_noop(self) -> bool:
        return not self.unary_flips and not self.rel_flips


@dataclass
class Operator:
    """A lifted operator: the symbolic pre-state over its parameters plus observed effects.

    ``effects`` are sorted by decreasing count (ties by the effect itself), so ``effects[0]`` is the
    most frequent effect used by the deterministic domain.
    """

    name: str
    arity: int
    same: bool  # pick == place: the action is (param0, grasp, param0, release)
    grasp: int
    release: int
    pre_unary: np.ndarray  # (arity, d_z) uint8
    pre_rel: np.ndarray  # (K, arity, arity) uint8
    effects: tuple[Effect, ...]
    counts: tuple[int, ...]
    # Which precondition bits the operator tests (None: every one). A general operator
    # (`learn_operators(general_bystanders=True)`) leaves out its bystanders' unary bits and the
    # relations among them; its pre_unary / pre_rel hold 0 there, and no effect flips them.
    known_unary: np.ndarray | None = None  # (arity, d_z) bool
    known_rel: np.ndarray | None = None  # (K, arity, arity) bool

    @property
    def is_general(self) -> bool:
        return self.known_unary is not None

    def known_bits(self) -> np.ndarray:
        """The tested bits in the local layout (unary bits of each parameter, then each relation's
        arity x arity matrix), as a bool vector."""
        if self.known_unary is None or self.known_rel is None:
            return np.ones(self.pre_unary.size + self.pre_rel.size, dtype=bool)
        return np.concatenate([self.known_unary.ravel(), self.known_rel.ravel()]).astype(bool)

    def holds(self, unary: np.ndarray, rel: np.ndarray) -> bool:
        """The precondition holds on the parameters' bits: unary (arity, d_z), relations (K, arity, arity)."""
        bits = np.concatenate([np.asarray(unary).ravel(), np.asarray(rel).ravel()])
        pre = np.concatenate([self.pre_unary.ravel(), self.pre_rel.ravel()])
        known = self.known_bits()
        return bits.shape == pre.shape and bool(np.array_equal(bits[known], pre[known]))

    @property
    def count(self) -> int:
        return int(sum(self.counts))

    @property
    def probabilities(self) -> np.ndarray:
        c = np.asarray(self.counts, dtype=float)
        return c / c.sum()

    @property
    def place_param(self) -> int:
        return 0 if self.same else 1

    @property
    def is_probabilistic(self) -> bool:
        return len(self.effects) > 1

    def action(self, binding: tuple[int, ...]) -> Action:
        """The pick-place action of this operator with parameters bound to scene objects."""
        return (binding[0], self.grasp, binding[self.place_param], self.release)


@dataclass
class OperatorSet:
    """Operators of one learned domain together with the symbol dimensions they were learned for."""

    operators: list[Operator]
    n_unary: int  # d_z
    n_relations: int  # K
    _names: dict[str, int] | None = field(default=None, init=False, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.operators)

    def by_name(self) -> dict[str, int]:
        """Operator name -> index; built once (the planner looks names up for every ranked plan)."""
        if self._names is None or len(self._names) != len(self.operators):
            self._names = {op.name: i for i, op in enumerate(self.operators)}
        return self._names


@dataclass
class SymbolicDataset:
    """Symbolic transitions, padded to n_max objects; transition t uses objects 0..n[t]-1."""

    unary_pre: np.ndarray  # (T, n_max, d_z)
    rel_pre: np.ndarray  # (T, K, n_max, n_max)
    actions: np.ndarray  # (T, 4)
    unary_post: np.ndarray  # (T, n_max, d_z)
    rel_post: np.ndarray  # (T, K, n_max, n_max)
    n: np.ndarray  # (T,)

    def __len__(self) -> int:
        return int(self.actions.shape[0])

    @property
    def n_unary(self) -> int:
        return int(self.unary_pre.shape[2])

    @property
    def n_relations(self) -> int:
        return int(self.rel_pre.shape[1])

    def subset(self, index: np.ndarray) -> "SymbolicDataset":
        return SymbolicDataset(self.unary_pre[index], self.rel_pre[index], self.actions[index],
                               self.unary_post[index], self.rel_post[index], self.n[index])


@dataclass
class SymbolicProblem:
    """Sigma_init and Sigma_goal bits of one scene; the goal is the full goal state."""

    init_unary: np.ndarray  # (n, d_z)
    init_rel: np.ndarray  # (K, n, n)
    goal_unary: np.ndarray
    goal_rel: np.ndarray
    # At least one action, even when Sigma_init already equals Sigma_goal: the caller knows the
    # continuous goal is not met (the symbols cannot tell where on the table a block stands).
    # Honoured by the python backend; Fast Downward still returns the empty plan then.
    nonempty: bool = False
    # The objects a plan may pick up (None: any). The caller knows which blocks are off their goal;
    # restricting picks to them (as the continuous search's goal-oriented pruning does) shrinks the
    # branching by n / len(movable). Honoured by the python backend only.
    movable: tuple[int, ...] | None = None

    @property
    def n(self) -> int:
        return int(self.init_unary.shape[0])

    @property
    def objects(self) -> list[str]:
        return [f"o{i}" for i in range(self.n)]


class PlannerStatus(enum.Enum):
    SOLVED = "solved"
    UNSOLVABLE = "unsolvable"
    TIMEOUT = "timeout"
    CRASHED = "crashed"
    STOPPED = "stopped"  # the shared search stopped once a plan ranked ahead of any it could still find was taken


PlanStep = tuple[str, tuple[str, ...]]  # (operator name, argument object names)


@dataclass
class PlannerResult:
    """Outcome of one classical planning call (Fast Downward or the in-process search)."""

    status: PlannerStatus
    plan: list[PlanStep] | None = None
    message: str = ""
    wall_time: float = 0.0
    returncode: int | None = None
    stderr_tail: str = ""
    states: list[int] | None = None  # python backend: packed symbolic states along the plan (len + 1)

    @property
    def solved(self) -> bool:
        return self.status is PlannerStatus.SOLVED


@dataclass
class RankedPlan:
    """A unique plan of the probabilistic planner with its (domain-weighted) occurrence count."""

    actions: tuple[Action, ...]
    steps: tuple[PlanStep, ...]  # operator names of the first domain that produced it
    count: int
    probability: float
    states: tuple[int, ...] | None = None  # packed states along it in that domain (python backend)


@dataclass
class ProbabilisticPlanResult:
    plans: list[RankedPlan]
    n_domains: int
    n_unique_domains: int | None  # distinct sampled domains (Fast Downward backends; None: not needed)
    n_searches: int  # planner calls actually made (after dedup; the python backend: one shared search)
    statuses: dict[str, int]  # outcome -> number of domains (weighted)
    timings: dict[str, float] = field(default_factory=dict)  # seconds: sampling, planner, parsing, ...
    expanded: int = 0  # python backend: states expanded by the shared search (forward and backward)
    generated: int = 0  # python backend: states those expansions generated (the budget's unit)
