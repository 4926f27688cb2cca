"""A small PDDL / PPDDL domain parser and validator (the subset our writers emit, checked strictly).

Checks: balanced s-expressions, ``define``/``domain``, declared predicates and arities, every
action's parameters distinct, preconditions are conjunctions of declared atoms over the action's
parameters (or ``(not (= ?a ?b))``), effects are conjunctions of literals or ``(probabilistic p1
e1 ...)`` with probabilities in (0, 1] summing to 1. Raises ValueError with the offending action.
"""

from __future__ import annotations

from dataclasses import dataclass

SExpr = str | list


def tokenize(text: str) -> list[str]:
    lines = [line.split(";", 1)[0] for line in text.splitlines()]
    return " ".join(lines).replace("(", " ( ").replace(")", " ) ").split()


def parse_sexpr(text: str) -> SExpr:
    tokens = tokenize(text)
    stack: list[list] = [[]]
    for tok in tokens:
        if tok == "(":
            stack.append([])
        elif tok == ")":
            if len(stack) == 1:
                raise ValueError("unbalanced ')'")
            done = stack.pop()
            stack[-1].append(done)
        else:
            stack[-1].append(tok.lower())
    if len(stack) != 1 or len(stack[0]) != 1:
        raise ValueError("unbalanced '(' or more than one top-level expression")
    return stack[0][0]


@dataclass
class ParsedAction:
    name: str
    parameters: list[str]
    precondition: list[tuple[str, ...]]  # atoms; inequality as ("!=", a, b)
    outcomes: list[tuple[float, list[tuple[bool, tuple[str, ...]]]]]  # (probability, [(positive, atom)])


@dataclass
class ParsedDomain:
    name: str
    requirements: list[str]
    predicates: dict[str, int]
    actions: list[ParsedAction]


def _literals(expr: SExpr, where: str) -> list[tuple[bool, tuple[str, ...]]]:
    if not isinstance(expr, list) or not expr:
        raise ValueError(f"{where}: expected a conjunction, got {expr!r}")
    items = expr[1:] if expr[0] == "and" else [expr]
    out = []
    for lit in items:
        if isinstance(lit, list) and lit and lit[0] == "not":
            if len(lit) != 2 or not isinstance(lit[1], list):
                raise ValueError(f"{where}: malformed negation {lit!r}")
            out.append((False, tuple(lit[1])))
        elif isinstance(lit, list) and lit and all(isinstance(x, str) for x in lit):
            out.append((True, tuple(lit)))
        else:
            raise ValueError(f"{where}: not a literal: {lit!r}")
    return out


def _check_atom(atom: tuple[str, ...], preds: dict[str, int], params: set[str], where: str) -> None:
    if atom[0] not in preds:
        raise ValueError(f"{where}: undeclared predicate {atom[0]!r}")
    if len(atom) - 1 != preds[atom[0]]:
        raise ValueError(f"{where}: {atom[0]} takes {preds[atom[0]]} arguments, got {len(atom) - 1}")
    for arg in atom[1:]:
        if arg not in params:
            raise ValueError(f"{where}: {arg!r} is not a parameter")


def parse_domain(text: str, tolerance: float = 1e-6) -> ParsedDomain:
    tree = parse_sexpr(text)
    if not (isinstance(tree, list) and tree[:1] == ["define"] and isinstance(tree[1], list)
            and tree[1][:1] == ["domain"] and len(tree[1]) == 2):
        raise ValueError("expected (define (domain NAME) ...)")
    name, reqs, preds, actions = tree[1][1], [], {}, []
    for section in tree[2:]:
        if not isinstance(section, list) or not section:
            raise ValueError(f"unexpected {section!r} in domain")
        head = section[0]
        if head == ":requirements":
            reqs = list(section[1:])
        elif head == ":predicates":
            for p in section[1:]:
                if not isinstance(p, list) or not p or any(not a.startswith("?") for a in p[1:]):
                    raise ValueError(f"malformed predicate declaration {p!r}")
                preds[p[0]] = len(p) - 1
        elif head == ":action":
            actions.append(_parse_action(section, preds, tolerance))
        else:
            raise ValueError(f"unsupported domain section {head!r}")
    if len({a.name for a in actions}) != len(actions):
        raise ValueError("duplicate action names")
    if any(len(a.outcomes) > 1 for a in actions) and ":probabilistic-effects" not in reqs:
        raise ValueError("probabilistic effects used without :probabilistic-effects")
    return ParsedDomain(name, reqs, preds, actions)


def _parse_action(section: list, preds: dict[str, int], tolerance: float) -> ParsedAction:
    name = section[1]
    fields = dict(zip(section[2::2], section[3::2]))
    if set(fields) != {":parameters", ":precondition", ":effect"}:
        raise ValueError(f"action {name}: needs :parameters, :precondition and :effect")
    params = fields[":parameters"]
    if any(not p.startswith("?") for p in params) or len(set(params)) != len(params):
        raise ValueError(f"action {name}: parameters must be distinct variables, got {params}")
    pset = set(params)
    pre: list[tuple[str, ...]] = []
    for positive, atom in _literals(fields[":precondition"], f"action {name} precondition"):
        if atom[0] == "=":
            if positive or len(atom) != 3 or not set(atom[1:]) <= pset:
                raise ValueError(f"action {name}: only (not (= ?a ?b)) over parameters is supported")
            pre.append(("!=",) + atom[1:])
            continue
        if not positive:
            raise ValueError(f"action {name}: negative precondition {atom}")
        _check_atom(atom, preds, pset, f"action {name}")
        pre.append(atom)
    eff = fields[":effect"]
    if isinstance(eff, list) and eff[:1] == ["probabilistic"]:
        body = eff[1:]
        if len(body) % 2 or not body:
            raise ValueError(f"action {name}: probabilistic effect needs probability/effect pairs")
        outcomes = []
        for p, e in zip(body[::2], body[1::2]):
            try:
                prob = float(p)
            except (TypeError, ValueError):
                raise ValueError(f"action {name}: bad probability {p!r}") from None
            if not 0.0 < prob <= 1.0:
                raise ValueError(f"action {name}: probability {prob} outside (0, 1]")
            outcomes.append((prob, _literals(e, f"action {name} effect")))
        total = sum(p for p, _ in outcomes)
        if abs(total - 1.0) > tolerance:
            raise ValueError(f"action {name}: probabilities sum to {total}, not 1")
    else:
        outcomes = [(1.0, _literals(eff, f"action {name} effect") if eff != ["and"] else [])]
    for _, lits in outcomes:
        for _, atom in lits:
            _check_atom(atom, preds, pset, f"action {name} effect")
    return ParsedAction(name, list(params), pre, outcomes)
