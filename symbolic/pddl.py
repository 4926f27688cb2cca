"""PDDL / PPDDL writers for lifted operators and symbolic problems.

Parameters are ``?p`` (picked object), ``?t`` (target, absent when pick == place) and ``?x1 ..``
(other objects), pairwise distinct. Preconditions are positive atoms (see `atoms.py`); an effect
adds the new atom of each flipped bit and deletes the old one. Every action's text is rendered once
per writer, so writing N sampled domains is string joining.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from guarded import atomic_write_text
from symbolic.atoms import predicate_declarations, rel_atom, state_atoms, unary_atom
from symbolic.grounding import check_problem
from symbolic.structs import Effect, Operator, OperatorSet, SymbolicProblem

PRECISION = 1_000_000  # PPDDL probabilities are written in millionths that sum exactly to 1


def parameter_names(op: Operator) -> list[str]:
    named = ["?p"] if op.same else ["?p", "?t"]
    return named + [f"?x{i}" for i in range(1, op.arity - len(named) + 1)]


def effect_probabilities(op: Operator, min_prob: float = 0.0) -> np.ndarray:
    """Empirical effect probabilities; effects below min_prob get 0 and the rest is renormalised
    (the most frequent effect is always kept)."""
    p = op.probabilities
    if min_prob > 0.0:
        keep = p >= min_prob
        keep[0] = True
        p = np.where(keep, p, 0.0)
        p = p / p.sum()
    return p


def _millionths(p: np.ndarray) -> list[int]:
    q = np.round(p * PRECISION).astype(int)
    q[int(np.argmax(q))] += PRECISION - int(q.sum())
    return q.tolist()


class DomainWriter:
    """Renders the deterministic, sampled, union and probabilistic domains of an operator set."""

    def __init__(self, ops: OperatorSet, domain_name: str = "symbolic"):
        self.ops, self.domain_name = ops, domain_name
        self._head = [self._render_head(op) for op in ops.operators]
        self._effects = [[self._render_effect(op, e) for e in op.effects] for op in ops.operators]

    @staticmethod
    def _render_head(op: Operator) -> str:
        names = parameter_names(op)
        pre = [f"(not (= {a} {b}))" for i, a in enumerate(names) for b in names[i + 1:]]
        d, K = op.pre_unary.shape[1], op.pre_rel.shape[0]
        known = op.known_bits()
        unary = [(i, k) for i in range(op.arity) for k in range(d)]
        rel = [(k, i, j) for k in range(K) for i in range(op.arity) for j in range(op.arity)]
        pre += [unary_atom(k, names[i], int(op.pre_unary[i, k])) for (i, k), ok in zip(unary, known) if ok]
        pre += [rel_atom(k, names[i], names[j], int(op.pre_rel[k, i, j]))
                for (k, i, j), ok in zip(rel, known[len(unary):]) if ok]
        return (f" :parameters ({' '.join(names)})\n"
                f"  :precondition (and {' '.join(pre)})\n  :effect ")

    @staticmethod
    def _render_effect(op: Operator, e: Effect) -> str:
        names = parameter_names(op)
        lits = []
        for i, k in e.unary_flips:
            old = int(op.pre_unary[i, k])
            lits += [unary_atom(k, names[i], 1 - old), f"(not {unary_atom(k, names[i], old)})"]
        for k, i, j in e.rel_flips:
            old = int(op.pre_rel[k, i, j])
            lits += [rel_atom(k, names[i], names[j], 1 - old), f"(not {rel_atom(k, names[i], names[j], old)})"]
        return f"(and {' '.join(lits)})"

    def _domain(self, actions: list[str], probabilistic: bool = False) -> str:
        req = ":strips :equality" + (" :probabilistic-effects" if probabilistic else "")
        preds = " ".join(predicate_declarations(self.ops.n_unary, self.ops.n_relations))
        return (f"(define (domain {self.domain_name})\n (:requirements {req})\n (:predicates {preds})\n"
                + "".join(actions) + ")\n")

    def pddl(self, choice: np.ndarray | None = None) -> str:
        """Deterministic domain: effect choice[i] for operator i (default: most frequent effect)."""
        ch = [0] * len(self._head) if choice is None else np.asarray(choice).tolist()
        return self._domain([f" (:action {op.name}\n {h}{e[c]})\n"
                             for op, h, e, c in zip(self.ops.operators, self._head, self._effects, ch)])

    def union(self) -> str:
        """Every (operator, effect) pair as its own action ``{name}__e{j}``: translated once per
        problem, then restricted to one sampled domain by dropping the other variants."""
        return self._domain([f" (:action {op.name}__e{j}\n {h}{eff})\n"
                             for op, h, es in zip(self.ops.operators, self._head, self._effects)
                             for j, eff in enumerate(es)])

    def ppddl(self, min_prob: float = 0.0) -> str:
        """PPDDL domain with ``(probabilistic p1 e1 p2 e2 ...)`` effects (deterministic ones plain)."""
        actions = []
        for op, h, es in zip(self.ops.operators, self._head, self._effects):
            q = _millionths(effect_probabilities(op, min_prob))
            branches = [(qi, e) for qi, e in zip(q, es) if qi > 0]
            if len(branches) == 1:
                body = branches[0][1]
            else:
                body = "(probabilistic " + " ".join(f"{qi / PRECISION:.6f} {e}" for qi, e in branches) + ")"
            actions.append(f" (:action {op.name}\n {h}{body})\n")
        return self._domain(actions, probabilistic=True)


PDDL_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_-]*$")


def pddl_name(text: str, default: str = "symbolic-task") -> str:
    """`text` as a PDDL name: letters, digits, '-' and '_', starting with a letter (else `default`);
    never a bare keyword such as `problem` or `domain`, which parsers reject."""
    name = re.sub(r"[^A-Za-z0-9_-]", "-", text.strip())
    if not PDDL_NAME.match(name) or name.lower() in ("problem", "domain", "define", "and", "not", "or"):
        name = f"{default}-{name}" if name and PDDL_NAME.match(f"x{name}") else default
    return name


def problem_pddl(ops: OperatorSet, problem: SymbolicProblem, domain_name: str = "symbolic",
                 name: str = "symbolic-task") -> str:
    """Problem from Sigma_init / Sigma_goal bits; the goal is every atom of the goal state."""
    check_problem(ops, problem)
    name = pddl_name(name)
    init = " ".join(state_atoms(problem.init_unary, problem.init_rel))
    goal = " ".join(state_atoms(problem.goal_unary, problem.goal_rel))
    return (f"(define (problem {name}) (:domain {domain_name})\n (:objects {' '.join(problem.objects)})\n"
            f" (:init {init})\n (:goal (and {goal})))\n")


def write_domains(ops: OperatorSet, out_dir: str | Path, min_prob: float = 0.0) -> dict[str, Path]:
    """Write domain.pddl (most frequent effects) and domain.ppddl into out_dir."""
    out = Path(out_dir)
    w = DomainWriter(ops)
    paths = {"pddl": out / "domain.pddl", "ppddl": out / "domain.ppddl"}
    atomic_write_text(paths["pddl"], w.pddl())
    atomic_write_text(paths["ppddl"], w.ppddl(min_prob))
    return paths
