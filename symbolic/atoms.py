"""Bits -> ground atoms, and the bit layout of a symbolic state.

Atom names (PDDL predicates):
- ``(u{k} o)``      unary bit k of object o is 1,   ``(not-u{k} o)``   it is 0;
- ``(r{k} a b)``    relation bit k of (a, b) is 1,  ``(not-r{k} a b)`` it is 0 (a == b included).

Every bit is written as exactly one of the two atoms, so preconditions and goals are conjunctions of
positive atoms (Fast Downward prefers these to negative preconditions) and a state is fully
determined by its bits. Objects are named ``o0 .. o{n-1}`` after their index in the scene.

In-process search packs a state into one Python int: unary bit (i, k) at ``i * d_z + k`` and
relation bit (k, i, j) at ``n * d_z + k * n * n + i * n + j``.
"""

from __future__ import annotations

import re

import numpy as np

_OBJECT = re.compile(r"^o(\d+)$")


def object_name(i: int) -> str:
    return f"o{i}"


def object_index(name: str, n: int) -> int:
    """Index of an object name ``o{i}`` in an n-object scene; ValueError for unknown objects."""
    m = _OBJECT.match(name.strip().lower())
    if m is None or int(m.group(1)) >= n:
        raise ValueError(f"unknown object {name!r}: the problem has objects o0..o{n - 1}")
    return int(m.group(1))


def check_bits(unary: np.ndarray, rel: np.ndarray, what: str = "state",
               n_unary: int | None = None, n_relations: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Validate one state's bits: unary (n, d_z), relation (K, n, n), values in {0, 1}."""
    unary, rel = np.asarray(unary), np.asarray(rel)
    if unary.ndim != 2:
        raise ValueError(f"{what}: unary bits must have shape (n, d_z), got {unary.shape}")
    n, d = unary.shape
    if rel.ndim != 3 or rel.shape[1:] != (n, n):
        raise ValueError(f"{what}: relation bits must have shape (K, {n}, {n}), got {rel.shape}")
    if n == 0:
        raise ValueError(f"{what}: a state needs at least one object")
    if n_unary is not None and d != n_unary:
        raise ValueError(f"{what}: expected {n_unary} unary bits per object, got {d}")
    if n_relations is not None and rel.shape[0] != n_relations:
        raise ValueError(f"{what}: expected {n_relations} relations, got {rel.shape[0]}")
    for name, a in (("unary", unary), ("relation", rel)):
        if a.size and not np.isin(a, (0, 1)).all():
            raise ValueError(f"{what}: {name} bits must be 0 or 1")
    return unary.astype(np.uint8), rel.astype(np.uint8)


def unary_atom(k: int, obj: str, value: int) -> str:
    return f"({'' if value else 'not-'}u{k} {obj})"


def rel_atom(k: int, a: str, b: str, value: int) -> str:
    return f"({'' if value else 'not-'}r{k} {a} {b})"


def state_atoms(unary: np.ndarray, rel: np.ndarray, names: list[str] | None = None) -> list[str]:
    """All ground atoms (one per bit) of a state, unary first, then relations in (k, i, j) order."""
    unary, rel = check_bits(unary, rel)
    n = unary.shape[0]
    names = names or [object_name(i) for i in range(n)]
    atoms = [unary_atom(k, names[i], int(unary[i, k])) for i in range(n) for k in range(unary.shape[1])]
    atoms += [rel_atom(k, names[i], names[j], int(rel[k, i, j]))
              for k in range(rel.shape[0]) for i in range(n) for j in range(n)]
    return atoms


def predicate_declarations(n_unary: int, n_relations: int) -> list[str]:
    decl = []
    for k in range(n_unary):
        decl += [f"(u{k} ?o)", f"(not-u{k} ?o)"]
    for k in range(n_relations):
        decl += [f"(r{k} ?a ?b)", f"(not-r{k} ?a ?b)"]
    return decl


def n_bits(n: int, n_unary: int, n_relations: int) -> int:
    return n * n_unary + n_relations * n * n


def unary_bit(n: int, d: int, i: int, k: int) -> int:
    return i * d + k


def rel_bit(n: int, d: int, k: int, i: int, j: int) -> int:
    return n * d + k * n * n + i * n + j


def pack_state(unary: np.ndarray, rel: np.ndarray) -> int:
    """Bits -> int, in the layout of the module docstring."""
    flat = np.concatenate([np.asarray(unary, np.uint8).ravel(), np.asarray(rel, np.uint8).ravel()])
    return int.from_bytes(np.packbits(flat[::-1]).tobytes(), "big") >> ((-flat.size) % 8)


def unpack_state(state: int, n: int, n_unary: int, n_relations: int) -> tuple[np.ndarray, np.ndarray]:
    size = n_bits(n, n_unary, n_relations)
    flat = np.array([(state >> b) & 1 for b in range(size)], dtype=np.uint8)
    return flat[: n * n_unary].reshape(n, n_unary), flat[n * n_unary:].reshape(n_relations, n, n)
