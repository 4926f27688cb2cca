"""Each executed step of a plan seen through the learned abstraction: what the symbols were, which
learned operator the step used, what it expected, and what the world's motion actually produced.

For step k, from the states the world was in before and after it (`symbolic_steps`):

- the Symbolic Model's symbols before the step (read on the observed state);
- the learned operator that grounds the step's action in those symbols, its effect and that effect's
  probability, and the symbols it expects after. For a Level-1 plan whose symbols before the step
  are the plan's, the effect is the one the plan counted on (it leads to the plan's next symbolic
  state); otherwise it is the action's most probable outcome. Several operators can ground one
  action: a domain learned on the objects each transition involved (`tamp domain --involved-only`)
  adds a bystander to an operator only when the bystander changed, so the action's outcomes are
  spread over its operators (one without bystanders, one per bystander change seen). An outcome's
  weight is the number of training transitions that showed it (operator count x effect
  probability), summed over the operators that give the same symbols; the expected outcome is the
  heaviest, named by the operator that gives most of its weight;
- the symbols read on the state observed after the step, and whether they equal the expected ones:
  a mismatch is a step whose motion did not produce the symbolic effect the abstraction counted on;
  and which learned effect of the action's operators, if any, gives them (the outcome was one the
  abstraction allows, if not the one it counted on): the expected operator's own, else the heaviest;
- the Dynamics Model's position error predicting the step from the observed state before it.

A step whose action could not be refined has no observed symbols (it changed nothing). Steps after
it were not reached and have no record.

A Level-1 plan made in a sub-scene (`bilevel.level1_scene`: from 5 blocks on, the objects the goal
involves) is read in that sub-scene, as it was planned: the symbols are those of its objects only,
named by their indices in the whole scene (the raw bit arrays are in the sub-scene's object order,
`SymbolicStep.objects`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from learned.interpret import BitNames
from tamp.planning.models import Models


@dataclass(frozen=True)
class Symbols:
    """One symbolic state: unary bits (n, d_z) and relation bits (K, n, n), 0/1."""

    unary: np.ndarray
    rel: np.ndarray

    @classmethod
    def of(cls, unary, rel) -> "Symbols":
        return cls(np.asarray(unary, np.uint8), np.asarray(rel, np.uint8))

    def key(self) -> bytes:
        """The bits as bytes, equal for equal symbols of one scene (a dict key)."""
        return self.unary.tobytes() + self.rel.tobytes()

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Symbols) and np.array_equal(self.unary, other.unary) and \
            np.array_equal(self.rel, other.rel)

    __hash__ = None  # type: ignore[assignment]  # arrays: compared, not hashed

    @property
    def n(self) -> int:
        return int(self.unary.shape[0])

    def bits(self) -> list[tuple[str, int, int, int | None, int]]:
        """Every bit as (kind "u" or "r", index k, object i, object j or None, value)."""
        out: list[tuple[str, int, int, int | None, int]] = [
            ("u", k, i, None, int(self.unary[i, k])) for i in range(self.n) for k in range(self.unary.shape[1])]
        out += [("r", k, i, j, int(self.rel[k, i, j]))
                for k in range(self.rel.shape[0]) for i in range(self.n) for j in range(self.n)]
        return out

    def differences(self, other: "Symbols") -> list[tuple[str, int, int, int | None, int, int]]:
        """The bits where `other` differs: (kind, k, i, j, value here, value in other)."""
        return [(kind, k, i, j, v, w) for (kind, k, i, j, v), (*_, w) in zip(self.bits(), other.bits()) if v != w]

    def to_dict(self) -> dict:
        return {"unary": self.unary.tolist(), "relations": self.rel.tolist()}


def _name(i: int, objects: Sequence[int] | None = None) -> str:
    """The name of object i of a state (of the sub-scene `objects`: by its index in the whole scene)."""
    return f"o{i if objects is None else objects[i]}"


def _obj(j: int | None, objects: Sequence[int] | None = None) -> str | None:
    return None if j is None else _name(j, objects)


def named_facts(symbols: Symbols, names: BitNames, objects: Sequence[int] | None = None) -> list[str]:
    """The facts the named bits of a state say hold (e.g. "o2 on a block"), negative ones left out;
    `objects`: the sub-scene the state describes."""
    out = []
    for kind, k, i, j, v in symbols.bits():
        meaning = names.meaning(kind, k, v, _name(i, objects), _obj(j, objects))
        if meaning is not None and " not " not in f" {meaning} ":
            out.append(meaning)
    return out


@dataclass
class SymbolicStep:
    """One executed (or attempted) step of a plan through the learned abstraction."""

    index: int
    action: tuple[int, int, int, int]
    before: Symbols | None  # read on the observed state before the step (None: no Symbolic Model)
    operator: str | None = None  # the learned operator grounding the action (None: no operator applies)
    binding: tuple[int, ...] | None = None  # its parameters' objects (indices into the state's objects)
    effect: int | None = None  # index of the effect expected (into the operator's effects)
    n_effects: int | None = None
    probability: float | None = None  # of that effect
    expected: Symbols | None = None  # before with the expected effect applied
    observed: Symbols | None = None  # read on the observed state after (None: the step changed nothing)
    on_plan: bool | None = None  # the symbols before equal the Level-1 plan's (None: no plan symbols)
    observed_effect: int | None = None  # the learned effect that gives the observed symbols (None: none does) ...
    observed_operator: str | None = None  # ... of this operator grounding the action (the expected one if it can)
    dynamics_error_m: float | None = None  # mean over objects of |predicted - observed| position
    objects: tuple[int, ...] | None = None  # the sub-scene the symbols describe (whole-scene indices); None: all

    @property
    def executed(self) -> bool:
        return self.observed is not None

    @property
    def match(self) -> bool | None:
        """Observed symbols equal the expected ones (None: not executed, or no operator)."""
        if self.observed is None or self.expected is None:
            return None
        return self.observed == self.expected

    def mismatches(self) -> list[tuple[str, int, int, int | None, int, int]]:
        """Bits where the observed symbols differ from the expected: (kind, k, i, j, expected, observed)."""
        if self.observed is None or self.expected is None:
            return []
        return self.expected.differences(self.observed)

    def to_dict(self, names: BitNames) -> dict:
        """JSON-ready: raw bits, set bits by name, the changes expected and observed, the mismatches (the
        step's index, action and Dynamics Model error sit beside it in `tamp.app.step_report.step_records`)."""
        def n(i: int) -> str:
            return _name(i, self.objects)

        def o(j: int | None) -> str | None:
            return _obj(j, self.objects)

        def changes(a: Symbols | None, b: Symbols | None) -> list[dict] | None:
            if a is None or b is None:
                return None
            return [{"bit": names.bit(kind, k, n(i), o(j)), "value": w,
                     "meaning": names.meaning(kind, k, w, n(i), o(j))} for kind, k, i, j, _, w in a.differences(b)]

        def state(s: Symbols | None) -> dict | None:
            if s is None:
                return None
            return {**s.to_dict(), "set": [names.bit(kind, k, n(i), o(j)) for kind, k, i, j, v in s.bits() if v],
                    "facts": named_facts(s, names, self.objects)}

        return {"executed": self.executed,
                "objects": None if self.objects is None else [n(i) for i in range(len(self.objects))],
                "operator": self.operator, "binding": None if self.binding is None else [n(b) for b in self.binding],
                "effect": self.effect, "n_effects": self.n_effects,
                "probability": None if self.probability is None else round(self.probability, 4),
                "before": state(self.before), "expected": state(self.expected), "observed": state(self.observed),
                "expected_changes": changes(self.before, self.expected),
                "observed_changes": changes(self.before, self.observed),
                "match": self.match, "on_plan": self.on_plan, "observed_effect": self.observed_effect,
                "observed_operator": self.observed_operator,
                "mismatches": [{"bit": names.bit(kind, k, n(i), o(j)), "expected": e, "observed": w,
                                "meaning_observed": names.meaning(kind, k, w, n(i), o(j))}
                               for kind, k, i, j, e, w in self.mismatches()]}


def dynamics_errors(models: Models, states: Sequence[np.ndarray], actions, worst: bool = False) -> list[float] | None:
    """Per executed action: the Dynamics Model's position error (metres, mean over objects, or with
    `worst` the largest: how far the block it missed most landed from its prediction) predicting its
    effect from the state the world was in before it; None without a Dynamics Model."""
    if models.dynamics is None:
        return None
    out = []
    for X, X_next, action in zip(states, states[1:], actions):
        e_hat = models.dynamics.predict_effect(X, np.asarray([tuple(action)], dtype=np.int64))[0]
        distances = np.linalg.norm(X[:, :3] + e_hat - X_next[:, :3], axis=1)
        out.append(float(distances.max() if worst else distances.mean()))
    return out


def symbolic_steps(models: Models, states: Sequence[np.ndarray], actions: Sequence,
                   plan_states: Sequence[int] | None = None,
                   errors: Sequence[float] | None = None,
                   objects: Sequence[int] | None = None) -> list[SymbolicStep]:
    """The steps of a plan as executed: `states` are the observed states X_0 .. X_m (m executed
    actions), `actions` the plan (m actions, or more when action m could not be refined: its step is
    recorded without observed symbols). `plan_states`: a Level-1 plan's packed symbolic states, of
    the sub-scene `objects` if given (`PlanResult.plan_scene`: the symbols are then read on those
    objects only). `errors`: `dynamics_errors` of these states and actions when the caller has them
    already (whole scene)."""
    actions = [tuple(int(v) for v in a) for a in actions]
    m = len(states) - 1
    steps: list[SymbolicStep] = []
    if errors is None:
        errors = dynamics_errors(models, states, actions[:m]) or []
    scene = None if objects is None else tuple(int(o) for o in objects)
    if scene is not None and any(a[0] not in scene or a[2] not in scene for a in actions):
        scene, plan_states = None, None  # an action beyond the sub-scene: read the whole scene
    if scene is not None:
        states = [np.asarray(X)[list(scene)] for X in states]
    symbols = models.symbolic
    observed = [None if symbols is None else Symbols.of(*symbols.symbols(X)) for X in states]
    for k, action in enumerate(actions[:m + 1]):
        step = SymbolicStep(k, action, observed[k], observed=observed[k + 1] if k < m else None,
                            dynamics_error_m=errors[k] if k < min(m, len(errors)) else None, objects=scene)
        if step.before is not None and models.domain is not None:
            planned = _plan_symbols(models, plan_states, k, step.before.n)
            _ground(models, step, planned)
        steps.append(step)
    return steps


def _plan_symbols(models: Models, plan_states, k: int, n: int) -> tuple[Symbols, Symbols] | None:
    """The Level-1 plan's symbols before and after step k, if it has them."""
    if plan_states is None or k + 1 >= len(plan_states):
        return None
    from symbolic.atoms import unpack_state

    assert models.domain is not None
    d, K = models.domain.n_unary, models.domain.n_relations
    return (Symbols.of(*unpack_state(plan_states[k], n, d, K)), Symbols.of(*unpack_state(plan_states[k + 1], n, d, K)))


def _ground(models: Models, step: SymbolicStep, planned: tuple[Symbols, Symbols] | None) -> None:
    """Fill the step's operator, effect and expected symbols (see the module docstring)."""
    from symbolic import apply_effect
    from symbolic.atoms import pack_state

    assert models.domain is not None and step.before is not None
    ops = models.domain
    task = models.symbolic_planner().task(step.before.n)
    state = pack_state(step.before.unary, step.before.rel)
    i, g_offset, j, r_offset = step.action
    if step.objects is not None:  # the action on the sub-scene's objects
        i, j = step.objects.index(i), step.objects.index(j)
    action = (i, g_offset, j, r_offset)
    candidates = [g for g in task.applicable(state) if task.action(g) == action]
    if planned is not None:
        step.on_plan = planned[0] == step.before
    if not candidates:
        return
    # every learned outcome of the action: (symbols after, ground action, effect, transitions that showed it)
    outcomes = []
    for g in candidates:
        op = ops.operators[task.operator(g)]
        outcomes += [(Symbols.of(*apply_effect(step.before.unary, step.before.rel, effect, task.binding(g))), g, e,
                      op.count * float(op.probabilities[e])) for e, effect in enumerate(op.effects)]
    choice = None
    if step.on_plan and planned is not None:  # the operator and effect the plan counted on
        choice = next(((g, e) for after, g, e, _ in outcomes if after == planned[1]), None)
    if choice is None:  # the action's most probable outcome, by the operator that gives most of its weight
        weight: dict[bytes, float] = {}
        for after, _, _, w in outcomes:
            weight[after.key()] = weight.get(after.key(), 0.0) + w
        heaviest = max(weight, key=lambda k: weight[k])  # first of equals: candidates' order
        _, g, e, _ = max((o for o in outcomes if o[0].key() == heaviest), key=lambda o: o[3])
        choice = (g, e)
    g, e = choice
    op = ops.operators[task.operator(g)]
    step.operator, step.binding = op.name, tuple(task.binding(g))
    step.effect, step.n_effects, step.probability = e, len(op.effects), float(op.probabilities[e])
    step.expected = Symbols.of(*apply_effect(step.before.unary, step.before.rel, op.effects[e], step.binding))
    if step.observed is not None:  # did the world do one of the things the action's operators learned it may do?
        given = [o for o in outcomes if o[0] == step.observed]
        if given:
            _, g_obs, step.observed_effect, _ = max(given, key=lambda o: (o[1] == g, o[3]))
            step.observed_operator = ops.operators[task.operator(g_obs)].name
