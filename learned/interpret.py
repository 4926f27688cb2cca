"""What a Symbolic Model's bits mean: each learned unary bit and relation against geometric facts.

    report = interpret_symbols(model.symbols, scenes)      # scenes: (n, 5) states, held out
    print(format_symbols_markdown(report))

For every unary bit u_b(i) and relation r_k(i, j) (i != j; the self relation r_k(i, i) is read as a
unary bit) the report gives its rate (how often it is 1) and its agreement with each fact a reader
understands: block type, resting on another block, carrying one, left / right along y (strictly, and
by more than 2 cm), nearer the arm (the same two ways), near, on top of, above (over the footprint,
any height), vertical order, level, in line along the offset axis (y). Agreement is the share of
objects (pairs) where the bit equals the fact, or its negation (polarity "not"), whichever is
higher; phi (the Matthews correlation) is given beside it, because a
rare fact agrees with an almost-always-0 bit without meaning anything. The facts are computed from X
alone (upright blocks, sizes of `effects.TYPE_NAMES`), so any scene source works: the scenes of a
problem set (never trained on) or of a dataset.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from guarded import Schema, output, read_json

BLOCK_HALF_XY = np.array([[0.025, 0.025], [0.025, 0.125]])  # small cube, large bar (along y): half sizes, metres
HEIGHT_M = 0.05  # every block is 5 cm tall
ON_TOLERANCE_M = 0.015  # z gap and footprint slack for "on top of"
NEAR_M = 0.10  # centre distance on the table for "near"
FAR_HALF_X_M = 0.65  # the middle of the random scenes' workspace along x (0.45-0.85 m from the arm)
SIDE_M = 0.02  # "higher", "right of", "nearer the arm": by more than this, so that blocks in line are neither


def _type(X: np.ndarray) -> np.ndarray:
    return np.argmax(X[..., 3:5], axis=-1)


def _over(X: np.ndarray) -> np.ndarray:
    """(n, n) bool: i's centre lies over j's footprint (with ON_TOLERANCE_M slack), at any height."""
    half = BLOCK_HALF_XY[_type(X)]
    d = X[:, None, :3] - X[None, :, :3]
    return np.all(np.abs(d[..., :2]) <= half[None, :, :] + ON_TOLERANCE_M, axis=-1) & ~np.eye(len(X), dtype=bool)


def _on(X: np.ndarray) -> np.ndarray:
    """(n, n) bool: i rests directly on j (i above j by one block height, centre over j's top)."""
    d = X[:, None, 2] - X[None, :, 2]
    return _over(X) & (np.abs(d - HEIGHT_M) <= ON_TOLERANCE_M)


def unary_facts(X: np.ndarray) -> dict[str, np.ndarray]:
    """Facts about each object of one scene X (n, 5): name -> (n,) bool."""
    on = _on(X)
    return {"large (type)": _type(X) == 1,
            "elevated (z > 4 cm)": X[:, 2] > 0.04,
            "on another block": on.any(axis=1),
            "carries a block": on.any(axis=0),
            "left half (y > 0)": X[:, 1] > 0.0,
            "far half (x > 0.65 m)": X[:, 0] > FAR_HALF_X_M}


def relation_facts(X: np.ndarray) -> dict[str, np.ndarray]:
    """Facts about each ordered pair (i, j) of one scene: name -> (n, n) bool (the diagonal unused)."""
    on, over = _on(X), _over(X)
    z, y, x = X[:, 2], X[:, 1], X[:, 0]
    dist = np.linalg.norm(X[:, None, :2] - X[None, :, :2], axis=-1)
    t = _type(X)
    higher = z[:, None] > z[None, :] + SIDE_M
    farther = x[:, None] > x[None, :] + SIDE_M  # [i, j]: i farther from the arm than j
    left = y[:, None] > y[None, :] + SIDE_M  # [i, j]: i left of j
    return {"i on j": on, "j on i": on.T,
            "i above j": over & higher, "j above i": over.T & higher.T,
            "z_i > z_j (i higher)": higher, "z_j > z_i (j higher)": higher.T,
            "z_i <= z_j (vertical order)": z[:, None] <= z[None, :] + 0.02,
            "same level (|dz| < 2 cm)": np.abs(z[:, None] - z[None, :]) < 0.02,
            "aligned in x (|dx| < 2 cm)": np.abs(x[:, None] - x[None, :]) < 0.02,
            "y_i < y_j": y[:, None] < y[None, :], "x_i < x_j": x[:, None] < x[None, :],
            "i right of j (> 2 cm)": left.T, "j right of i (> 2 cm)": left,
            "i nearer the arm (> 2 cm)": farther.T, "j nearer the arm (> 2 cm)": farther,
            "near (< 10 cm)": dist < NEAR_M, "same type": t[:, None] == t[None, :],
            "i large": np.broadcast_to(t[:, None] == 1, on.shape),
            "j large": np.broadcast_to(t[None, :] == 1, on.shape)}


@dataclass
class BitReport:
    """One learned bit against every fact of its kind."""

    name: str  # "u0", "r1", "r1(i,i)"
    rate: float  # share of objects (pairs) where the bit is 1
    count: int  # objects (pairs) it was read on
    agreement: dict[str, float]  # fact -> best agreement over both polarities
    negated: dict[str, bool]  # fact -> the best polarity is "not fact"
    phi: dict[str, float]  # fact -> Matthews correlation (signed)

    @property
    def best(self) -> str:
        return max(self.agreement, key=lambda f: (abs(self.phi[f]), self.agreement[f]))

    def to_dict(self) -> dict:
        return {"name": self.name, "rate": self.rate, "count": self.count, "best": self.best,
                "agreement": self.agreement, "negated": self.negated, "phi": self.phi}


def _phi(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a.astype(float), b.astype(float)
    if a.std() == 0 or b.std() == 0:
        return 0.0
    return float(np.corrcoef(a, b)[0, 1])


def _bit_report(name: str, bits: np.ndarray, facts: dict[str, np.ndarray]) -> BitReport:
    agreement, negated, phi = {}, {}, {}
    for f, v in facts.items():
        same = float(np.mean(bits == v))
        agreement[f], negated[f] = max(same, 1 - same), same < 0.5
        phi[f] = _phi(bits, v)
    return BitReport(name, float(np.mean(bits)), int(bits.size), agreement, negated, phi)


def interpret_symbols(symbols: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                      scenes: Sequence[np.ndarray]) -> list[BitReport]:
    """Every unary bit, every relation (i != j) and every self relation r_k(i, i) of `symbols`
    (a Symbolic Model's `symbols(X) -> (unary (n, d_z), relations (K, n, n))`) on `scenes`."""
    if not len(scenes):
        raise ValueError("no scenes to read the symbols on")
    unary_f: dict[str, list[np.ndarray]] = {}
    rel_f: dict[str, list[np.ndarray]] = {}
    unary_bits, rel_bits, self_bits = [], [], []
    for X in scenes:
        X = np.asarray(X, dtype=float)
        u, r = symbols(X)
        off = ~np.eye(len(X), dtype=bool)
        unary_bits.append(np.asarray(u, dtype=bool))
        rel_bits.append(np.asarray(r, dtype=bool)[:, off])
        self_bits.append(np.asarray(r, dtype=bool)[:, ~off])
        for name, v in unary_facts(X).items():
            unary_f.setdefault(name, []).append(v)
        for name, v in relation_facts(X).items():
            rel_f.setdefault(name, []).append(v[off])
    U = np.concatenate(unary_bits)  # (objects, d_z)
    R = np.concatenate(rel_bits, axis=1)  # (K, pairs)
    S = np.concatenate(self_bits, axis=1)  # (K, objects)
    uf = {k: np.concatenate(v) for k, v in unary_f.items()}
    rf = {k: np.concatenate(v) for k, v in rel_f.items()}
    out = [_bit_report(f"u{b}", U[:, b], uf) for b in range(U.shape[1])]
    out += [_bit_report(f"r{k}", R[k], rf) for k in range(R.shape[0])]
    out += [_bit_report(f"r{k}(i,i)", S[k], uf) for k in range(S.shape[0])]
    return out


# A bit is named by its best fact when |phi| reaches this (the fact explains the bit, not only agrees
# with it because both are rare).
STRONG_PHI = 0.7
# The facts as phrases about objects {i}, {j}; {neg} is "not " where the bit says the fact is false.
FACT_PHRASES = {
    "large (type)": "{i} {neg}large", "elevated (z > 4 cm)": "{i} {neg}elevated",
    "on another block": "{i} {neg}on a block", "carries a block": "{i} {neg}carrying a block",
    "left half (y > 0)": "{i} {neg}in the left half", "far half (x > 0.65 m)": "{i} {neg}in the far half",
    "i on j": "{i} {neg}on {j}", "j on i": "{j} {neg}on {i}", "z_i > z_j (i higher)": "{i} {neg}higher than {j}",
    "i above j": "{i} {neg}above {j}", "j above i": "{j} {neg}above {i}",
    "z_j > z_i (j higher)": "{j} {neg}higher than {i}", "same level (|dz| < 2 cm)": "{i} {neg}level with {j}",
    "aligned in x (|dx| < 2 cm)": "{i} {neg}in line with {j} along y",
    "z_i <= z_j (vertical order)": "{i} {neg}at most as high as {j}", "y_i < y_j": "{i} {neg}right of {j}",
    "x_i < x_j": "{i} {neg}nearer the arm than {j}", "near (< 10 cm)": "{i} {neg}near {j}",
    "i right of j (> 2 cm)": "{i} {neg}right of {j}", "j right of i (> 2 cm)": "{j} {neg}right of {i}",
    "i nearer the arm (> 2 cm)": "{i} {neg}nearer the arm than {j}",
    "j nearer the arm (> 2 cm)": "{j} {neg}nearer the arm than {i}",
    "same type": "{i} {neg}the same type as {j}", "i large": "{i} {neg}large", "j large": "{j} {neg}large"}


_BY_FACT = {"type": "object", "additionalProperties": {"type": "number"}}
# a symbols table (`tamp symbols --json`, an evaluation's symbols.json): BitReport.to_dict per bit
SYMBOLS_SCHEMA = Schema({"type": "array", "items": {
    "type": "object", "required": ["name", "rate", "count", "best", "agreement", "negated", "phi"],
    "properties": {"name": {"type": "string"}, "rate": {"type": "number"}, "count": {"type": "integer", "minimum": 0},
                   "best": {"type": "string"}, "agreement": _BY_FACT, "phi": _BY_FACT,
                   "negated": {"type": "object", "additionalProperties": {"type": "boolean"}}}}})


def read_symbols(path: str | Path) -> list[dict]:
    """A symbols table, through the guarded reader and `SYMBOLS_SCHEMA`; ValueError naming the file
    and the bit otherwise."""
    table = read_json(path, "symbols table")
    SYMBOLS_SCHEMA.check(table, f"{path} (a symbols table of `tamp symbols --json`)")
    for i, bit in enumerate(table):
        if bit["best"] not in bit["phi"] or bit["best"] not in bit["negated"]:
            raise ValueError(f"{path}: [{i}].best: {bit['best'][:40]!r} is not one of the bit's facts")
    return table


@dataclass
class BitNames:
    """Names of a Symbolic Model's bits for people: the raw bit (``u0(o2)``, ``r1(o2,o0)``) and, where
    `tamp symbols`' table finds a strong agreement (|phi| >= `min_phi`), what its value says, e.g.
    ``u0(o2)=0 ~ o2 elevated``. Built from that table (`interpret_symbols`, or the dicts of its
    ``--json`` file)."""

    facts: dict[str, tuple[str, bool]]  # bit name ("u0", "r1", "r1(i,i)") -> (fact, bit 1 means "not fact")

    @classmethod
    def from_report(cls, report: Sequence[BitReport | dict], min_phi: float = STRONG_PHI) -> "BitNames":
        facts = {}
        for bit in report:
            b = bit.to_dict() if isinstance(bit, BitReport) else bit
            best = b["best"]
            if abs(b["phi"][best]) >= min_phi:
                facts[b["name"]] = (best, bool(b["negated"][best]))
        return cls(facts)

    @classmethod
    def none(cls) -> "BitNames":
        """No meanings: every bit by its raw name."""
        return cls({})

    @staticmethod
    def bit(kind: str, k: int, i: str, j: str | None = None) -> str:
        """The raw name: ``u{k}(i)`` for a unary bit, ``r{k}(i,j)`` for a relation (i == j included)."""
        return f"u{k}({i})" if kind == "u" else f"r{k}({i},{j})"

    def meaning(self, kind: str, k: int, value: int, i: str, j: str | None = None) -> str | None:
        """What the bit's `value` says about the objects, or None when the bit has no strong meaning."""
        key = f"u{k}" if kind == "u" else (f"r{k}(i,i)" if i == j else f"r{k}")
        if key not in self.facts:
            return None
        fact, negated = self.facts[key]
        holds = bool(value) != negated
        template = FACT_PHRASES.get(fact, "{neg}" + fact + ("({i})" if kind == "u" or i == j else "({i},{j})"))
        return template.format(i=i, j=j, neg="" if holds else "not ")

    def describe(self, kind: str, k: int, value: int, i: str, j: str | None = None) -> str:
        """``u0(o2)=0 ~ o2 elevated``, or ``r0(o1,o2)=1`` for a bit without a strong meaning."""
        text = f"{self.bit(kind, k, i, j)}={int(value)}"
        meaning = self.meaning(kind, k, value, i, j)
        return text if meaning is None else f"{text} ~ {meaning}"


TYPE_FACTS = frozenset({"large (type)", "same type", "i large", "j large"})  # what the input features already say
SPATIAL_PHI = 0.8  # a relation "says where blocks are" when a spatial fact explains it this well
CONSTANT_RATE = 0.02  # a bit set in under 2 % or over 98 % of the objects (pairs) it is read on carries ~nothing


@dataclass
class SymbolSummary:
    """The few figures that say whether a Symbolic Model's bits are worth planning with."""

    spatial: list[str]  # relations (i != j) whose best fact is spatial with |phi| >= SPATIAL_PHI
    constant: list[str]  # bits (any kind) set in under CONSTANT_RATE or over 1 - CONSTANT_RATE
    typed: list[str]  # bits whose best fact is the block type, which the input already has
    goals_like_init: int | None = None  # goals whose symbols equal their initial scene's (problem sets)
    goals: int | None = None

    def lines(self) -> list[str]:
        out = [f"relations with a spatial meaning (|phi| >= {SPATIAL_PHI}): {len(self.spatial)}"
               + (f" ({', '.join(self.spatial)})" if self.spatial else ""),
               f"near-constant bits (rate under {CONSTANT_RATE:.0%} or over {1 - CONSTANT_RATE:.0%}): "
               + (", ".join(self.constant) or "none"),
               "bits whose best fact is the block type: " + (", ".join(self.typed) or "none")]
        if self.goals:
            assert self.goals_like_init is not None
            out.append(f"goals whose symbols equal their initial scene's: {self.goals_like_init} of {self.goals} "
                       f"({100 * self.goals_like_init / self.goals:.1f} %)")
        return out


def summarize_symbols(report: Sequence[BitReport],
                      symbols: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None,
                      problems: Sequence[tuple[np.ndarray, np.ndarray]] = (),
                      given: Sequence[str] = ()) -> SymbolSummary:
    """`SymbolSummary` of a report; with `symbols` and (X_init, X_goal) `problems`, also how many goals
    read exactly like their initial scene (a symbolic planner cannot tell them apart). `given`: bits
    that are not learned (the type symbol), left out of the checks."""
    report = [b for b in report if b.name not in given]
    spatial = [b.name for b in report if b.name.startswith("r") and "(i,i)" not in b.name
               and b.best not in TYPE_FACTS and abs(b.phi[b.best]) >= SPATIAL_PHI]
    constant = [b.name for b in report if not CONSTANT_RATE <= b.rate <= 1 - CONSTANT_RATE]
    typed = [b.name for b in report if b.best in TYPE_FACTS and abs(b.phi[b.best]) > 0]
    summary = SymbolSummary(spatial, constant, typed)
    if symbols is not None and len(problems):
        same = 0
        for X_init, X_goal in problems:
            (ui, ri), (ug, rg) = symbols(np.asarray(X_init, float)), symbols(np.asarray(X_goal, float))
            same += int(np.array_equal(ui, ug) and np.array_equal(ri, rg))
        summary.goals_like_init, summary.goals = same, len(problems)
    return summary


def format_symbols_markdown(report: Sequence[BitReport]) -> str:
    """One line per bit: its rate and the fact it agrees with best (by |phi|), then every fact."""
    lines = ["| bit | read on | rate | best fact | agreement | phi |", "|---|---|---|---|---|---|"]
    for b in report:
        f = b.best
        lines.append(f"| {b.name} | {b.count} | {b.rate:.3f} | {'not ' if b.negated[f] else ''}{f} | "
                     f"{b.agreement[f] * 100:.1f} % | {b.phi[f]:+.2f} |")
    lines += ["", "Agreement with every fact (%, 'not' where the negation agrees better; phi in parentheses):", ""]
    for kind in ("u", "r"):
        rows = [b for b in report if b.name.startswith(kind) and "(i,i)" not in b.name] + \
            ([b for b in report if "(i,i)" in b.name] if kind == "u" else [])
        if not rows:
            continue
        facts = list(rows[0].agreement)
        lines += ["| bit | " + " | ".join(facts) + " |", "|---|" + "---|" * len(facts)]
        for b in rows:
            cells = [f"{'not ' if b.negated[f] else ''}{b.agreement[f] * 100:.0f} ({b.phi[f]:+.2f})" for f in facts]
            lines.append(f"| {b.name} | " + " | ".join(cells) + " |")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def write_symbols_png(report: Sequence[BitReport], path) -> None:
    """A heat map of |phi| (bits x facts), one panel for unary bits and one for relations."""
    from pathlib import Path

    from matplotlib.figure import Figure

    groups = [("unary bits and self relations", [b for b in report if b.name.startswith("u") or "(i,i)" in b.name]),
              ("relations (i != j)", [b for b in report if b.name.startswith("r") and "(i,i)" not in b.name])]
    groups = [(t, g) for t, g in groups if g]
    fig = Figure(figsize=(11, 1.6 + 0.45 * sum(len(g) for _, g in groups) + 1.6 * len(groups)), layout="constrained")
    for k, (title, bits) in enumerate(groups):
        ax = fig.add_subplot(len(groups), 1, k + 1)
        facts = list(bits[0].phi)
        M = np.array([[b.phi[f] for f in facts] for b in bits])
        im = ax.imshow(np.abs(M), vmin=0, vmax=1, cmap="viridis", aspect="auto")
        ax.set_xticks(range(len(facts)), facts, rotation=25, ha="right", fontsize=8)
        ax.set_yticks(range(len(bits)), [f"{b.name} (rate {b.rate:.2f})" for b in bits], fontsize=8)
        for (i, j), v in np.ndenumerate(M):
            ax.text(j, i, f"{v:+.2f}", ha="center", va="center", fontsize=7, color="white" if abs(v) < 0.6 else "black")
        ax.set_title(f"|phi| of learned {title} with geometric facts", fontsize=9)
        fig.colorbar(im, ax=ax, fraction=0.02, pad=0.01)
    path = Path(path)
    output.atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight"))
