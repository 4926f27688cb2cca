"""The rows indexed by method and problem (`Results`), the groups tables are made over, what the
methods are, paired success comparisons, the notes shared by sections, and the `Section` record."""
from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

from .. import paper
from ..stats import mean_std, paired_ttest, rate_pct

METHOD_ORDER = ("deterministic", "probabilistic", "probabilistic_oracle", "cfs", "bilevel", "bilevel_alg1",
                "bilevel_replan", "bilevel_loop", "symbolic_sigmoid", "cfs_gumbel", "cfs_nofeas", "bilevel_nofeas",
                "bilevel_replan_nofeas")
FEASIBILITY_PAIRS = (("cfs", "cfs_nofeas"), ("bilevel", "bilevel_nofeas"), ("bilevel_replan", "bilevel_replan_nofeas"))
METHOD_INFO = {
    "deterministic": "deterministic symbolic planner, Gumbel-Sigmoid Symbolic Model (baseline)",
    "probabilistic": "probabilistic symbolic planner, top plan of N sampled domains, unverified",
    "probabilistic_oracle": "ORACLE, the paper's measure: the N sampled domains' plans executed, most frequent "
                            "first, until one reaches the goal (no planner can choose so without the simulator)",
    "cfs": "continuous forward search, Sigmoid Dynamics Model",
    "bilevel": "Algorithm 1 with our extensions (kinematics in the loop, the goal's sub-scene from 5 blocks "
               "on), else continuous search (Level 2)",
    "bilevel_alg1": "the paper's Algorithm 1 exactly: verified probabilistic plan (Level 1), else continuous "
                    "search (Level 2)",
    "bilevel_replan": "bilevel in the paper's closed loop, up to k - 1 replanning rounds",
    "bilevel_loop": "bilevel in the closed loop that does not know k: until the goal or 30 actions, widening the "
                    "search when a round finds no plan (the default of `tamp plan --replan` and `tamp demo`)",
    "symbolic_sigmoid": "deterministic symbolic planner, Sigmoid Symbolic Model and its domain (Fig. 4)",
    "cfs_gumbel": "continuous forward search, Gumbel-Sigmoid Dynamics Model (Fig. 4)",
    "cfs_nofeas": "`cfs` without kinematics in the planning loop (no feasibility check, no refinement)",
    "bilevel_nofeas": "`bilevel` without kinematics in the planning loop",
    "bilevel_replan_nofeas": "`bilevel_replan` without kinematics in the planning loop",
}
BACKEND_INFO = {"python": "our in-process search (`python`)", "fd": "Fast Downward (`fd`, as in the paper)"}
PROTOCOL_INFO = {"strict": "`strict` (every one of the k random actions moved a block)",
                 "paper": "`paper` (the k random actions kept whatever their outcome, as the paper's authors do)"}
TAUS_CM = tuple(range(1, 16))  # the verifier sweep (the paper's Fig. 6)


def fmt_paper_p(p: float) -> str:
    """A p-value of the paper as printed: '< 0.0001' for `paper.P_BELOW`, else two decimals."""
    return "< 0.0001" if p <= paper.P_BELOW else f"{p:.2f}"


def _paper_pm(pair: tuple[float, float], digits: int = 2, scale: float = 1.0) -> str:
    return f"{pair[0] * scale:.{digits}f} ± {pair[1] * scale:.{digits}f}"


@dataclass
class Results:
    """The rows, indexed by method and problem."""

    rows: list[dict]
    meta: dict | None = None
    notes: list[str] = field(default_factory=list)  # said under Setup (e.g. an incomplete last line)
    by_method: dict[str, dict[str, dict]] = field(init=False)
    cells: dict[str, tuple[int, int]] = field(init=False)  # problem -> (n, k)
    run_of: dict[str, int] = field(init=False)  # problem -> run (0 without one)

    def __post_init__(self) -> None:
        self.by_method, self.cells, self.run_of = {}, {}, {}
        for r in self.rows:
            self.by_method.setdefault(r["method"], {})[r["problem"]] = r
            self.cells[r["problem"]] = (r["n"], r["k"])
            self.run_of[r["problem"]] = r.get("run") or 0

    @property
    def runs(self) -> list[int]:
        return sorted(set(self.run_of.values()))

    def distinct(self, name: str, methods: Sequence[str] | None = None) -> list[str]:
        """The distinct non-null values of a row field (of `methods`' rows), as strings."""
        return sorted({str(r[name]) for r in self.rows if r.get(name) is not None
                       and (methods is None or r["method"] in methods)})

    def per_run(self, rows: Sequence[dict], value: Callable[[list[dict]], float | None]
                ) -> tuple[float | None, float | None] | None:
        """Mean ± sample std over runs of `value` of each run's rows; None with fewer than two runs."""
        if len(self.runs) < 2:
            return None
        groups = [[r for r in rows if self.run_of[r["problem"]] == run] for run in self.runs]
        values = [value(g) for g in groups if g]
        return mean_std([v for v in values if v is not None])

    @property
    def methods(self) -> list[str]:
        return [m for m in METHOD_ORDER if m in self.by_method] + sorted(set(self.by_method) - set(METHOD_ORDER))

    @property
    def ns(self) -> list[int]:
        return sorted({n for n, _ in self.cells.values()})

    @property
    def ks(self) -> list[int]:
        return sorted({k for _, k in self.cells.values()})

    def has(self, *methods: str) -> bool:
        return all(m in self.by_method for m in methods)

    def common(self, name: str, default: Any = None) -> Any:
        """The most frequent non-null value of a field over the rows."""
        values = Counter(r.get(name) for r in self.rows if r.get(name) is not None)
        return values.most_common(1)[0][0] if values else default

    def paired(self, a: str, b: str, keep: Callable[[int, int], bool] = lambda n, k: True
               ) -> list[tuple[dict, dict]]:
        """(row of a, row of b) for every problem both methods were run on, by problem name."""
        ra, rb = self.by_method.get(a, {}), self.by_method.get(b, {})
        return [(ra[p], rb[p]) for p in sorted(set(ra) & set(rb)) if keep(*self.cells[p])]

    def select(self, method: str, keep: Callable[[int, int], bool] = lambda n, k: True) -> list[dict]:
        rows = self.by_method.get(method, {})
        return [rows[p] for p in sorted(rows) if keep(*self.cells[p])]


Keep = Callable[[int, int], bool]  # (n, k) of a problem -> whether a group holds it


def _n_is(n: int) -> Keep:
    return lambda n_, k_: n_ == n


def _k_in(ks: Sequence[int]) -> Keep:
    return lambda n_, k_: k_ in ks


def _cell_is(n: int, k: int) -> Keep:
    return lambda n_, k_: (n_, k_) == (n, k)


def _everything(n: int, k: int) -> bool:
    return True


def _by_n(res: Results) -> list[tuple[str, Keep]]:
    return [(str(n), _n_is(n)) for n in res.ns] + [("all", _everything)]


def _by_k(res: Results, ks: Sequence[int] | None = None, all_label: str = "all"
          ) -> list[tuple[str, Keep]]:
    ks = res.ks if ks is None else ks
    return [(str(k), _k_in((k,))) for k in ks] + [(all_label, _k_in(tuple(ks)))]


def _success(rows: Sequence[dict]) -> float | None:
    return rate_pct([r["success"] for r in rows])


def compare_success(res: Results, a: str, b: str, groups) -> list[dict]:
    """Per group: paired problems, success (%) of a and b on them, paired t-test p on 0/1 success;
    with several runs also each method's mean ± std over runs (keys "<method> runs")."""
    out = []
    for label, keep in groups:
        pairs = res.paired(a, b, keep)
        sa = [ra["success"] for ra, _ in pairs]
        sb = [rb["success"] for _, rb in pairs]
        entry = {"group": label, "problems": len(pairs), a: rate_pct(sa), b: rate_pct(sb), "p": paired_ttest(sa, sb)}
        if len(res.runs) > 1:
            entry[f"{a} runs"] = res.per_run([x for x, _ in pairs], _success)
            entry[f"{b} runs"] = res.per_run([y for _, y in pairs], _success)
        out.append(entry)
    return out


def _runs_note(res: Results) -> str:
    """What "runs" columns mean, or '' for a single run."""
    if len(res.runs) < 2:
        return ""
    return (f" Columns marked 'runs': mean ± sample std over the {len(res.runs)} runs (problem sets of different "
            "seeds) of each run's figure, as the paper reports; the other columns pool every run.")


def _backend_note(res: Results, methods: Sequence[str]) -> str:
    backends = res.distinct("symbolic_backend", methods)
    if not backends:
        return ""
    return " Symbolic planner: " + ", ".join(BACKEND_INFO.get(b, f"`{b}`") for b in backends) + "."


def _protocol_note(res: Results) -> str:
    protocols = res.distinct("protocol")
    if not protocols:
        return " Problem protocol unknown (rows without `protocol`)."
    return " Problems: " + ", ".join(PROTOCOL_INFO.get(p, f"`{p}`") for p in protocols) + " protocol."


def _moved(res: Results) -> dict[tuple[int, int], tuple[int, int, int]]:
    """(n, k) -> (actions that moved a block, all k actions, problems with no moving action), over the
    problems whose rows say `moved`; empty if none do."""
    seen: dict[str, int] = {}
    for r in res.rows:
        if r.get("moved") is not None:
            seen[r["problem"]] = r["moved"]
    out: dict[tuple[int, int], tuple[int, int, int]] = {}
    for p, m in seen.items():
        n, k = res.cells[p]
        a, b, c = out.get((n, k), (0, 0, 0))
        out[n, k] = (a + m, b + k, c + (m == 0))
    return out


@dataclass
class Section:
    key: str
    title: str
    lines: list[str]
    data: dict | None  # None: skipped (the one line in `lines` says why)


def _skipped(key: str, title: str, why: str) -> Section:
    return Section(key, title, [why, ""], None)
