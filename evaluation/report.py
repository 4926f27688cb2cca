"""The evaluation report: the paper's tables and figures next to ours, from OUT/rows.jsonl.

    write_report(Path("OUT"))   # -> OUT/report.md, OUT/report.json, OUT/figures/*.png

One row per (problem, method) (see `load_rows` for the fields used). Every table compares methods
on the problems both were run on (paired by problem name), so that the paired t-tests
(`scipy.stats.ttest_rel` on per-problem 0/1 success, or planning times) and the rates describe the
same problems. Success is a percentage of problems with one decimal, times are seconds with three
decimals; the paper's numbers (`evaluation.paper`) are quoted as printed. A section whose rows or
files are absent says so in one line.
"""
from __future__ import annotations

import json
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

from tamp.errors import UserError
from tamp.planning.structs import OUTCOMES, Outcome
from tamp.records import atomic_write_text

from . import paper, plots, refinability, scaling
from .format import DASH, fmt_p, fmt_pct, fmt_pm, fmt_ratio, fmt_s, md_table
from .stats import confusion, mean_std, median, paired_ttest, percentile, rate_pct

METHOD_ORDER = ("deterministic", "probabilistic", "probabilistic_oracle", "cfs", "bilevel", "bilevel_alg1",
                "bilevel_replan", "symbolic_sigmoid", "cfs_gumbel", "cfs_nofeas", "bilevel_nofeas",
                "bilevel_replan_nofeas")
FEASIBILITY_PAIRS = (("cfs", "cfs_nofeas"), ("bilevel", "bilevel_nofeas"), ("bilevel_replan", "bilevel_replan_nofeas"))
METHOD_INFO = {
    "deterministic": "deterministic symbolic planner, Gumbel-Sigmoid Symbolic Model (baseline)",
    "probabilistic": "probabilistic symbolic planner, top plan of N sampled domains, unverified",
    "probabilistic_oracle": "ORACLE, the paper's measure: the N sampled domains' plans executed, most frequent "
                            "first, until one reaches the goal (no planner can choose so without the simulator)",
    "cfs": "continuous forward search, Sigmoid Dynamics Model",
    "bilevel": "Algorithm 1 with our Level-1 extensions (look-alike alternatives, non-empty plans), else "
               "continuous search (Level 2)",
    "bilevel_alg1": "the paper's Algorithm 1 exactly: verified probabilistic plan (Level 1), else continuous "
                    "search (Level 2)",
    "bilevel_replan": "bilevel in closed loop, up to k - 1 replanning rounds",
    "symbolic_sigmoid": "deterministic symbolic planner, Sigmoid Symbolic Model and its domain (Fig. 4)",
    "cfs_gumbel": "continuous forward search, Gumbel-Sigmoid Dynamics Model (Fig. 4)",
    "cfs_nofeas": "`cfs` without kinematics in the planning loop (no feasibility check, no refinement)",
    "bilevel_nofeas": "`bilevel` without kinematics in the planning loop",
    "bilevel_replan_nofeas": "`bilevel_replan` without kinematics in the planning loop",
}
ERROR_OUTCOME = Outcome.ERROR.value  # a (problem, method) that raised (evaluation.run): listed, left out of the tables
STAGES = ("ik", "motion", "grasp")
BACKEND_INFO = {"python": "our in-process search (`python`)", "fd": "Fast Downward (`fd`, as in the paper)"}
PROTOCOL_INFO = {"strict": "`strict` (every one of the k random actions moved a block)",
                 "paper": "`paper` (the k random actions kept whatever their outcome, as the paper's authors do)"}
TAUS_CM = tuple(range(1, 16))  # the verifier sweep (the paper's Fig. 6)


# --- formatting ----------------------------------------------------------------------------------
def fmt_paper_p(p: float) -> str:
    """A p-value of the paper as printed: '< 0.0001' for `paper.P_BELOW`, else two decimals."""
    return "< 0.0001" if p <= paper.P_BELOW else f"{p:.2f}"


def _paper_pm(pair: tuple[float, float], digits: int = 2, scale: float = 1.0) -> str:
    return f"{pair[0] * scale:.{digits}f} ± {pair[1] * scale:.{digits}f}"


# --- the rows ------------------------------------------------------------------------------------
_NUMBER = (int, float)


def _check(path: Path, line: int, row: dict, name: str, types: tuple, nullable: bool, what: str) -> None:
    value = row.get(name)
    if name not in row and not nullable:
        raise UserError(f"{path}, line {line}: missing field {name!r}")
    if value is None and nullable:
        return
    if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
        raise UserError(f"{path}, line {line}: field {name!r} must be {what}, got {value!r}")


def load_rows(path: Path) -> list[dict]:
    """The result rows of `path` (JSONL); a ValueError names the file and line of any malformed row.

    Fields used: problem, n, k, method, solved, success, outcome, planning_time_s (required);
    level, plan, predicted_error_m, refined, refine_failure, refine_time_s, executed_actions,
    executed_plans, rounds, eps_m, tau_verify_m, fidelity, run, protocol, moved, symbolic_backend
    (may be null or absent; a row without `run` belongs to run 0). A last line cut short by an interrupted
    evaluation (no newline, not JSON) is left out, as the runner does when it resumes.
    """
    return _read_rows(Path(path))[0]


def _read_rows(path: Path) -> tuple[list[dict], int | None]:
    """(rows, number of an incomplete last line that was left out, or None)."""
    if not path.is_file():
        raise UserError(f"{path}: no rows file (expected the JSONL written by `tamp evaluate`)")
    seen: dict[tuple[str, str], int] = {}  # (problem, method) -> line
    cells: dict[str, tuple[int, int, int]] = {}  # problem -> (n, k, line)
    rows, dropped = [], None
    try:
        lines = path.read_text().split("\n")
    except UnicodeDecodeError as error:
        raise UserError(f"{path}: not a text file ({error.reason} at byte {error.start})") from None
    for i, text in enumerate(lines, start=1):
        if not text.strip():
            continue
        try:
            row = json.loads(text)
        except json.JSONDecodeError as error:
            if i == len(lines):  # no newline after it: an append cut short
                dropped = i
                break
            raise UserError(f"{path}, line {i}: not valid JSON ({error.msg})") from None
        if not isinstance(row, dict):
            raise UserError(f"{path}, line {i}: expected a JSON object, got {type(row).__name__}")
        _check_row(path, i, row)
        key = (row["problem"], row["method"])
        if key in seen:
            raise UserError(f"{path}, line {i}: problem {key[0]!r} with method {key[1]!r} already on "
                             f"line {seen[key]}")
        seen[key] = i
        cell = cells.setdefault(row["problem"], (row["n"], row["k"], i))
        if cell[:2] != (row["n"], row["k"]):
            raise UserError(f"{path}, line {i}: problem {row['problem']!r} has n={row['n']}, k={row['k']} "
                             f"but n={cell[0]}, k={cell[1]} on line {cell[2]}")
        rows.append(row)
    if not rows:
        raise UserError(f"{path}: no rows")
    return rows, dropped


def _check_row(path: Path, i: int, row: dict) -> None:
    for name, types, what in (("problem", (str,), "a string"), ("method", (str,), "a string"),
                              ("n", (int,), "an integer"), ("k", (int,), "an integer"),
                              ("solved", (bool,), "true or false"), ("success", (bool,), "true or false"),
                              ("outcome", (str,), "a string"), ("planning_time_s", _NUMBER, "a number")):
        _check(path, i, row, name, types, False, what)
    for name in ("level", "predicted_error_m", "executed_actions", "rounds", "eps_m", "tau_verify_m",
                 "level1_time_s", "final_error_m", "run", "moved", "executed_plans"):
        _check(path, i, row, name, _NUMBER, True, "a number or null")
    _check(path, i, row, "refined", (bool,), True, "true, false or null")
    _check(path, i, row, "refine_failure", (dict,), True, "an object or null")
    _check(path, i, row, "refine_time_s", (list,), True, "a list of seconds or null")
    if row["outcome"] not in OUTCOMES + (ERROR_OUTCOME,):
        raise UserError(f"{path}, line {i}: field 'outcome' must be one of {', '.join(OUTCOMES + (ERROR_OUTCOME,))}, "
                         f"got {row['outcome']!r}")
    if isinstance(row.get("refine_failure"), dict) and row["refine_failure"].get("stage") not in STAGES:
        raise UserError(f"{path}, line {i}: field 'refine_failure.stage' must be one of "
                         f"{', '.join(STAGES)}, got {row['refine_failure'].get('stage')!r}")
    if not all(isinstance(t, _NUMBER) and not isinstance(t, bool) for t in row.get("refine_time_s") or []):
        raise UserError(f"{path}, line {i}: field 'refine_time_s' must be a list of seconds")


def read_json_object(path: Path, what: str) -> dict:
    """The JSON object in `path` (`what` it should be, for the error); UserError when it is not one."""
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise UserError(f"{path}: not valid JSON ({error.msg}, line {error.lineno}); expected {what}") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object ({what})")
    return data


def _read_symbols(path: Path) -> list[dict]:
    """OUT/symbols.json (`learned.interpret.BitReport.to_dict` per bit); a ValueError names the file."""
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise UserError(f"{path}: not valid JSON ({error.msg}, line {error.lineno})") from None
    keys = {"name", "rate", "count", "best", "agreement", "negated", "phi"}
    if not isinstance(data, list) or not all(isinstance(b, dict) and keys <= set(b) for b in data):
        raise UserError(f"{path}: expected a list of bits with fields {', '.join(sorted(keys))}")
    return data


def load_ablation(path: Path) -> dict:
    """The JSON of `tamp ablate-activations` (`learned.ablation`); a ValueError names the file and field."""
    data = read_json_object(path, "the output of `tamp ablate-activations`")
    acts = data.get("activations")
    if not isinstance(acts, dict) or not acts:
        raise UserError(f"{path}: field 'activations' must be an object of activation -> results")
    for name, r in acts.items():
        for f in ("mean_cm", "std_cm"):
            if not isinstance(r, dict) or not isinstance(r.get(f), _NUMBER):
                raise UserError(f"{path}: field 'activations.{name}.{f}' must be a number")
    return data


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


# --- the sections --------------------------------------------------------------------------------
@dataclass
class Section:
    key: str
    title: str
    lines: list[str]
    data: dict | None  # None: skipped (the one line in `lines` says why)


def _skipped(key: str, title: str, why: str) -> Section:
    return Section(key, title, [why, ""], None)


def _flatten(d: dict, prefix: str = "") -> list[tuple[str, Any]]:
    out = []
    for k, v in d.items():
        if isinstance(v, dict):
            out += _flatten(v, f"{prefix}{k}.")
        elif not isinstance(v, list):
            out.append((f"{prefix}{k}", v))
    return out


def _short(value: Any) -> str:
    """A meta.json value for a table cell; sha256 digests shortened to 12 characters."""
    text = str(value)
    return text[:12] + "…" if len(text) == 64 and all(c in "0123456789abcdef" for c in text) else text


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


def section_setup(res: Results, figures: Path) -> Section:
    eps, tau = res.common("eps_m"), res.common("tau_verify_m")
    distinct = {f: sorted({str(r.get(f)) for r in res.rows if r.get(f) is not None})
                for f in ("fidelity", "eps_m", "tau_verify_m")}
    items = [("rows", str(len(res.rows))), ("problems", str(len(res.cells))), ("runs", str(len(res.runs))),
             ("protocol", ", ".join(res.distinct("protocol")) or DASH),
             ("symbolic backend", ", ".join(res.distinct("symbolic_backend")) or DASH),
             ("methods", ", ".join(res.methods)), ("fidelity", ", ".join(distinct["fidelity"]) or DASH),
             ("eps (cm)", ", ".join(f"{float(e) * 100:g}" for e in distinct["eps_m"]) or DASH),
             ("tau_verify (cm)", ", ".join(f"{float(t) * 100:g}" for t in distinct["tau_verify_m"]) or DASH)]
    items += [(f"meta: {k}", _short(v)) for k, v in _flatten(res.meta or {})]
    lines = md_table(["item", "value"], items) + [note for n in res.notes for note in (n, "")]
    if res.meta is None:
        lines += ["No meta.json beside the rows: models and configuration unknown.", ""]
    counts = Counter(res.cells.values())
    grid = [[str(n)] + [str(counts.get((n, k), 0)) for k in res.ks] + [str(sum(counts.get((n, k), 0) for k in res.ks))]
            for n in res.ns]
    grid.append(["all"] + [str(sum(counts.get((n, k), 0) for n in res.ns)) for k in res.ks] + [str(len(res.cells))])
    lines += ["Problems per (n, k):", ""] + md_table(["n"] + [f"k={k}" for k in res.ks] + ["all"], grid)
    moved = _moved(res)
    if moved:
        def cell(keep) -> str:
            m, total, still = (sum(v[i] for (n, k), v in moved.items() if keep(n, k)) for i in range(3))
            return f"{m}/{total} ({still})" if total else DASH
        mgrid = [[str(n)] + [cell(lambda n_, k_, n=n, k=k: (n_, k_) == (n, k)) for k in res.ks] +
                 [cell(lambda n_, k_, n=n: n_ == n)] for n in res.ns]
        mgrid.append(["all"] + [cell(lambda n_, k_, k=k: k_ == k) for k in res.ks] + [cell(lambda n, k: True)])
        lines += ["Goal-generating actions that moved a block, of all k actions of the cell's problems, and in "
                  "parentheses the problems whose goal is their initial scene (no action moved anything):", ""]
        lines += md_table(["n"] + [f"k={k}" for k in res.ks] + ["all"], mgrid)
    per_method = [[f"`{m}`", str(len(res.by_method[m])), METHOD_INFO.get(m, "")] for m in res.methods]
    lines += md_table(["method", "rows", "what"], per_method)
    data = {"rows": len(res.rows), "notes": res.notes, "problems": len(res.cells), "methods": res.methods,
            "runs": res.runs, "protocols": res.distinct("protocol"),
            "symbolic_backends": res.distinct("symbolic_backend"),
            "moved": {f"{n},{k}": {"moved": v[0], "actions": v[1], "goal_is_init": v[2]}
                      for (n, k), v in sorted(moved.items())},
            "distinct": distinct, "eps_m": eps, "tau_verify_m": tau, "meta": res.meta,
            "problems_per_cell": {f"{n},{k}": c for (n, k), c in sorted(counts.items())},
            "rows_per_method": {m: len(res.by_method[m]) for m in res.methods}}
    return Section("setup", "1. Setup", lines, data)


def section_table1(ablation: dict | None, source: Path) -> Section:
    title = "2. Table I: effect prediction error per bottleneck activation"
    if ablation is None:
        return _skipped("table1", title, f"No ablation results ({source} not found; run `tamp "
                                          "ablate-activations`): Table I is not reproduced here.")
    acts = ablation["activations"]
    order = [a for a in paper.TABLE1_ERROR_CM if a in acts] + [a for a in acts if a not in paper.TABLE1_ERROR_CM]
    rows, data = [], {}
    for a in order:
        row = acts[a]
        n = row.get("runs", len(row.get("runs_cm", [])) or ablation.get("runs"))
        ours = (row["mean_cm"], row["std_cm"] if n != 1 else None)
        p = paper.TABLE1_ERROR_CM.get(a)
        shown = DASH if ours[0] is None else f"{ours[0]:.2f}" + ("" if ours[1] is None else f" ± {ours[1]:.2f}")
        training = [f"{p_['test_cm']:.2f} after {p_['epochs']} epochs, run {p_['run']}"
                    for p_ in row.get("in_progress", [])]
        rows.append([row.get("label", a), shown, str(n), ", ".join(map(str, row.get("epochs", []))) or DASH,
                     "; ".join(training) or DASH, _paper_pm(p) if p else DASH])
        data[a] = {"ours_cm": {"mean": ours[0], "std": ours[1]}, "runs": n, "epochs": row.get("epochs"),
                   "in_progress": row.get("in_progress", []),
                   "paper_cm": None if p is None else {"mean": p[0], "std": p[1]}}
    lines = md_table(["activation", "ours (cm)", "runs", "epochs per run", "still training (best so far, cm)",
                      "paper (cm)"], rows)
    trained = ablation.get("trained") or f"{ablation.get('epochs', '?')} epochs"
    zero = ablation.get("zero_effect_cm")
    zero_text = "" if zero is None else f"; predicting no effect: {zero:.2f} cm"
    lines += [f"Ours: mean ± sample std over the finished runs, {trained}, {ablation.get('num_test', '?')} "
              f"held-out test transitions ({source}){zero_text}. Paper: ten runs."
              + ("" if ablation.get("complete", True) else " Runs still training are not in the means."), ""]
    return Section("table1", title, lines, {"activations": data, "runs": ablation.get("runs"),
                                            "epochs": ablation.get("epochs"), "trained": ablation.get("trained"),
                                            "complete": ablation.get("complete", True),
                                            "num_test": ablation.get("num_test")})


def section_dual_model(res: Results, figures: Path) -> Section:
    title = "3. Fig. 4: dual-model validation"
    comparisons = (("symbolic", "Symbolic Model in symbolic planning", "deterministic", "symbolic_sigmoid",
                    "Gumbel-Sigmoid", "Sigmoid", paper.FIG4_SYMBOLIC_BETTER),
                   ("search", "Dynamics Model in continuous forward search", "cfs", "cfs_gumbel",
                    "Sigmoid", "Gumbel-Sigmoid", paper.FIG4_SEARCH_BETTER))
    lines, data, series = [], {}, {}
    for key, what, a, b, la, lb, better in comparisons:
        if not res.has(a, b):
            missing = ", ".join(f"`{m}`" for m in (a, b) if not res.has(m))
            lines += [f"{what}: no {missing} rows, comparison skipped.", ""]
            continue
        table = compare_success(res, a, b, _by_n(res))
        lines += [f"{what} (success %, problems both were run on):", ""]
        rows = [[t["group"], str(t["problems"]), fmt_pct(t[a]), fmt_pct(t[b]), fmt_p(t["p"])] for t in table]
        worse = b if better == a else a
        rows.append(["paper", DASH, "higher" if better == a else "lower", "higher" if better == b else "lower",
                     fmt_paper_p(paper.FIG4_P)])
        lines += md_table(["n", "problems", f"{la} `{a}` (%)", f"{lb} `{b}` (%)", "p"], rows)
        data[key] = {"methods": [a, b], "paper_better": better, "paper_worse": worse, "paper_p_below": paper.FIG4_P,
                     "groups": table}
        series[f"{la} ({a})"] = [t[a] for t in table]
        series[f"{lb} ({b})"] = [t[b] for t in table]
    if not data:
        return _skipped("dual_model", title, "No `symbolic_sigmoid` or `cfs_gumbel` rows (the models directory has "
                                             "no variants/): the dual-model comparison is skipped.")
    png = plots.grouped_bars(figures / "dual_model.png", "Fig. 4: success by bottleneck activation",
                             [f"n={g}" if g != "all" else "all" for g in [str(n) for n in res.ns] + ["all"]], series)
    lines += ["The paper gives Fig. 4 as bars without numbers: only the ordering and p are compared.", "",
              f"![Fig. 4]({png.parent.name}/{png.name})", ""]
    return Section("dual_model", title, lines, data)


def section_table2(res: Results, figures: Path) -> Section:
    title = "4. Table II: deterministic vs probabilistic symbolic planning"
    if not res.has("deterministic", "probabilistic"):
        return _skipped("table2", title, "No `deterministic` and `probabilistic` rows together: Table II skipped.")
    table = compare_success(res, "deterministic", "probabilistic", _by_k(res))
    oracle = res.has("probabilistic_oracle")
    runs = len(res.runs) > 1
    moved = _moved(res)
    rows = []
    for t, (_, keep) in zip(table, _by_k(res)):
        pk = paper.TABLE2_SUCCESS_PCT.get(int(t["group"])) if t["group"] != "all" else None
        row = [t["group"], str(t["problems"])]
        if moved:
            m, total, still = (sum(v[i] for (n, k), v in moved.items() if keep(n, k)) for i in range(3))
            row += [f"{m}/{total}", str(still)]
        row += [fmt_pct(t["deterministic"])] + ([fmt_pm(t["deterministic runs"], 1)] if runs else []) + \
            [_paper_pm(pk["deterministic"]) if pk else DASH, fmt_pct(t["probabilistic"])] + \
            ([fmt_pm(t["probabilistic runs"], 1)] if runs else [])
        if oracle:
            o = res.select("probabilistic_oracle", keep)
            t["probabilistic_oracle"] = _success(o)
            t["probabilistic_oracle runs"] = res.per_run(o, _success)
            t["oracle_plans_mean"] = mean_std([r["executed_plans"] for r in o if r.get("executed_plans")])[0]
            row += [fmt_pct(t["probabilistic_oracle"])] + ([fmt_pm(t["probabilistic_oracle runs"], 1)] if runs else [])
        row += [_paper_pm(pk["probabilistic"]) if pk else DASH]
        if oracle:
            row += [fmt_ratio(t["oracle_plans_mean"])]
        row += [fmt_p(t["p"]), fmt_paper_p(paper.TABLE2_P) if t["group"] == "all" else DASH]
        rows.append(row)
    header = ["k", "problems"] + (["moved actions", "goal = init"] if moved else []) + ["deterministic (%)"] + \
        (["deterministic runs (%)"] if runs else []) + ["paper deterministic (%)", "probabilistic (%)"] + \
        (["probabilistic runs (%)"] if runs else []) + \
        (["oracle (%)"] + (["oracle runs (%)"] if runs else []) if oracle else []) + ["paper probabilistic (%)"] + \
        (["oracle plans executed (mean)"] if oracle else []) + ["p", "paper p"]
    lines = md_table(header, rows)
    cap = (res.meta or {}).get("config", {}).get("oracle_max_plans")
    lines += ["Ours: all n pooled (problems both planners were run on); p on deterministic vs probabilistic. "
              "Paper: mean ± std over ten runs, averaged over n." + _runs_note(res) + _protocol_note(res) +
              _backend_note(res, ("deterministic", "probabilistic", "probabilistic_oracle")), ""]
    if moved:
        lines += ["moved actions: goal-generating actions that moved a block, of all k per problem; goal = init: "
                  "problems where none did, so that the empty plan solves them.", ""]
    if oracle:
        lines += ["`oracle` is the paper's \"probabilistic\" measure, an EXECUTION ORACLE: the plans of the N "
                  "sampled domains are executed, most frequent first, until one reaches the goal"
                  + (f" (at most {cap} per problem)" if cap else "") + "; no planner could choose among its plans "
                  "this way without the simulator. Our `probabilistic` column executes the top plan only. Compare "
                  "the paper's probabilistic column with `oracle`, its deterministic column with ours.", ""]
    else:
        lines += ["No `probabilistic_oracle` rows: the paper's probabilistic column is an execution oracle (any of "
                  "the sampled domains' plans reaching the goal), ours executes the top plan only.", ""]
    return Section("table2", title, lines, {"groups": table, "paper": paper.TABLE2_SUCCESS_PCT,
                                            "oracle_max_plans": cap})


def _verifier_rows(res: Results) -> tuple[list[dict], int]:
    rows = res.select("probabilistic")
    planned = [r for r in rows if r["solved"] and r.get("predicted_error_m") is not None]
    return planned, len(rows) - len(planned)


def section_verifier(res: Results, figures: Path) -> Section:
    title = "5. The verifier (Figs. 6 and 7)"
    if not res.has("probabilistic"):
        return _skipped("verifier", title, "No `probabilistic` rows: the verifier is not evaluated.")
    planned, left_out = _verifier_rows(res)
    tau = res.common("tau_verify_m", paper.VERIFIER_TAU_M)
    groups = [(str(n), [r for r in planned if r["n"] == n]) for n in res.ns] + [("all", planned)]
    conf = {g: confusion([r["predicted_error_m"] for r in rs], [r["success"] for r in rs], tau) for g, rs in groups}
    rows = [[g, str(c.total), str(c.tp), str(c.fp), str(c.tn), str(c.fn), fmt_pct(c.verified_success_pct),
             fmt_pct(c.unverified_failure_pct), fmt_ratio(c.accuracy), fmt_ratio(c.f1)] for g, c in conf.items()]
    pv = paper.VERIFIER
    rows.append(["paper", DASH, DASH, DASH, DASH, DASH, fmt_pct(pv["verified_success_pct"]),
                 fmt_pct(pv["unverified_failure_pct"]), fmt_ratio(pv["accuracy"]), fmt_ratio(pv["f1"])])
    lines = [f"The top plan of every `probabilistic` row, executed whatever its verification: verified iff its "
             f"predicted error < tau_verify = {tau * 100:g} cm; {len(planned)} plans, {left_out} rows without a "
             f"plan left out.", ""]
    lines += md_table(["n", "plans", "TP", "FP", "TN", "FN", "verified: success (%)", "unverified: failure (%)",
                       "accuracy", "F1"], rows)
    lines += ["TP verified and succeeded, FP verified and failed, TN unverified and failed, FN unverified and "
              "succeeded. Ours pooled over k; the paper's accuracy and F1 are means over its test scenarios." +
              _protocol_note(res) + _backend_note(res, ("probabilistic",)), ""]
    kinds = [("non-empty plans", [r for r in planned if r.get("plan")]),
             ("empty plans", [r for r in planned if r.get("plan") == []]), ("all plans", planned)]
    split: dict[str, dict[str, Any]] = {}
    srows = []
    for label, rs in kinds:
        c = confusion([r["predicted_error_m"] for r in rs], [r["success"] for r in rs], tau)
        split[label] = {"confusion": c.to_dict()}
        row = [label, str(c.total), str(c.tp), str(c.fp), str(c.tn), str(c.fn), fmt_pct(c.verified_success_pct),
               fmt_pct(c.unverified_failure_pct), fmt_ratio(c.accuracy), fmt_ratio(c.f1)]
        if len(res.runs) > 1:
            def score(rows, name):
                return getattr(confusion([r["predicted_error_m"] for r in rows], [r["success"] for r in rows], tau),
                               name)
            split[label]["accuracy runs"] = res.per_run(rs, lambda g: score(g, "accuracy"))
            split[label]["f1 runs"] = res.per_run(rs, lambda g: score(g, "f1"))
            row += [fmt_pm(split[label]["accuracy runs"], 2), fmt_pm(split[label]["f1 runs"], 2)]
        srows.append(row)
    lines += ["Empty plans (the initial symbols already equal the goal's) are judged by the distance of X_init "
              "itself to the goal, so they are easy cases either way; the same counts without them and for them "
              "alone:", ""]
    lines += md_table(["plans", "count", "TP", "FP", "TN", "FN", "verified: success (%)", "unverified: failure (%)",
                       "accuracy", "F1"] + (["accuracy runs", "F1 runs"] if len(res.runs) > 1 else []), srows)
    sweep: dict[str, dict[str, list[float | None]]] = {g: {"accuracy": [], "f1": []} for g, _ in groups}
    for tau_cm in TAUS_CM:
        for g, rs in groups:
            c = confusion([r["predicted_error_m"] for r in rs], [r["success"] for r in rs], tau_cm / 100)
            sweep[g]["accuracy"].append(c.accuracy)
            sweep[g]["f1"].append(c.f1)
    header = ["tau (cm)"] + [f"{'n=' + g if g != 'all' else 'all'} {m}" for g, _ in groups for m in ("accuracy", "F1")]
    grid = [[str(t)] + [fmt_ratio(sweep[g][m][i]) for g, _ in groups for m in ("accuracy", "f1")]
            for i, t in enumerate(TAUS_CM)]
    lines += ["Accuracy and F1 against tau_verify (the paper's Fig. 6):", ""] + md_table(header, grid)
    labels = [f"n={g}" if g != "all" else "all" for g, _ in groups]
    f1 = plots.verifier_sweep(figures / "verifier_tau.png", TAUS_CM,
                              {lab: sweep[g] for lab, (g, _) in zip(labels, groups)}, tau * 100)
    f2 = plots.confusion_bars(figures / "verifier_confusion.png", labels, list(conf.values()), tau * 100)
    lines += [f"![Fig. 6]({f1.parent.name}/{f1.name}) ![Fig. 7]({f2.parent.name}/{f2.name})", ""]
    data = {"tau_m": tau, "plans": len(planned), "left_out_no_plan": left_out,
            "confusion": {g: c.to_dict() for g, c in conf.items()}, "by_plan_kind": split, "paper": pv,
            "sweep": {"tau_cm": list(TAUS_CM), "groups": sweep}}
    return Section("verifier", title, lines, data)


def section_success(res: Results, figures: Path) -> Section:
    title = "6. Success per (n, k) (Fig. 5) and failure breakdown"
    methods = res.methods
    split = "bilevel" in res.by_method
    cells = [(str(n), str(k), _cell_is(n, k)) for n in res.ns for k in res.ks]
    cells += [(str(n), "all", _n_is(n)) for n in res.ns] + [("all", "all", _everything)]
    header = ["n", "k", "problems"] + [f"`{m}` (%)" for m in methods]
    if split:
        header += ["`bilevel` Level 1 (%)", "`bilevel` Level 2 (%)"]
    rows, data = [], []
    for n, k, keep in cells:
        entry: dict[str, Any]
        entry = {"n": n, "k": k, "problems": sum(1 for c in res.cells.values() if keep(*c)), "success_pct": {}}
        for m in methods:
            entry["success_pct"][m] = rate_pct([r["success"] for r in res.select(m, keep)])
        if split:
            b = res.select("bilevel", keep)
            entry["bilevel_level_pct"] = {lvl: rate_pct([r["success"] and r.get("level") == lvl for r in b])
                                          for lvl in (1, 2)}
        rows.append([n, k, str(entry["problems"])] + [fmt_pct(entry["success_pct"][m]) for m in methods] +
                    ([fmt_pct(entry["bilevel_level_pct"][1]), fmt_pct(entry["bilevel_level_pct"][2])] if split else []))
        data.append(entry)
    lines = ["Success (%) of each method over its rows in the cell; the `bilevel` split counts successes whose "
             "plan came from Level 1 (verified symbolic plan) or Level 2 (continuous search).", ""]
    lines += md_table(header, rows)
    lines += ["The paper gives Fig. 5 as bars without numbers, so no cell can be compared; it reports continuous "
              "forward search above both symbolic planners in every condition.", ""]
    out: dict[str, Any] = {"cells": data}
    if res.has("bilevel", "cfs"):
        table = compare_success(res, "bilevel", "cfs", _by_n(res))
        lines += ["Bilevel vs continuous forward search (problems both were run on):", ""]
        lines += md_table(["n", "problems", "`bilevel` (%)", "`cfs` (%)", "p", "paper p"],
                          [[t["group"], str(t["problems"]), fmt_pct(t["bilevel"]), fmt_pct(t["cfs"]), fmt_p(t["p"]),
                            fmt_paper_p(paper.BILEVEL_VS_CFS_P) if t["group"] == "all" else DASH] for t in table])
        out["bilevel_vs_cfs"] = {"groups": table, "paper_p": paper.BILEVEL_VS_CFS_P}
    else:
        lines += ["No `bilevel` and `cfs` rows together: no bilevel vs continuous search test.", ""]
    breakdown = {}
    brows = []
    for m in methods:
        rs = res.select(m)
        breakdown[m] = {"rows": len(rs), **{o: rate_pct([r["outcome"] == o for r in rs]) for o in OUTCOMES}}
        brows.append([f"`{m}`", str(len(rs))] + [fmt_pct(breakdown[m][o]) for o in OUTCOMES])
    lines += ["Outcomes per method (% of its rows): no_plan (planner failed), kinematic_failure (an IK stage of "
              "refinement failed), refinement_failure (motion or grasp), wrong_plan (executed, final error >= eps):",
              ""]
    lines += md_table(["method", "rows"] + [f"{o} (%)" for o in OUTCOMES], brows)
    out["outcomes"] = breakdown
    ns, ks = res.ns, res.ks
    per_cell = {m: {(int(e["n"]), int(e["k"])): e["success_pct"][m] for e in data if "all" not in (e["n"], e["k"])}
                for m in methods}
    levels = {(int(e["n"]), int(e["k"])): (e["bilevel_level_pct"][1], e["bilevel_level_pct"][2])
              for e in data if "all" not in (e["n"], e["k"])} if split else None
    png = plots.success_by_nk(figures / "success.png", ns, ks, per_cell, levels)
    lines += [f"![Fig. 5]({png.parent.name}/{png.name})", ""]
    return Section("success", title, lines, out)


def _times(pairs: list[tuple[dict, dict]]) -> tuple[list[float], list[float]]:
    return [a["planning_time_s"] for a, _ in pairs], [b["planning_time_s"] for _, b in pairs]


def section_table3(res: Results, figures: Path) -> Section:
    title = "7. Table III: planning time, bilevel vs continuous forward search"
    if not res.has("bilevel", "cfs"):
        return _skipped("table3", title, "No `bilevel` and `cfs` rows together: Table III skipped.")
    rows, groups, runs = [], [], len(res.runs) > 1
    for label, keep in _by_n(res):
        pairs = res.paired("bilevel", "cfs", keep)
        tb, tc = _times(pairs)
        mb, mc = mean_std(tb), mean_std(tc)
        speedup = mc[0] / mb[0] if pairs and mc[0] is not None and mb[0] is not None and mb[0] > 0 else None
        p3 = paper.TABLE3_TIME_S.get(int(label)) if label != "all" else None
        ps = paper.TABLE3_SPEEDUP.get(int(label)) if label != "all" else None
        g: dict[str, Any]
        g = {"group": label, "problems": len(pairs), "bilevel_s": mb, "bilevel_median_s": median(tb), "cfs_s": mc,
             "cfs_median_s": median(tc), "speedup": speedup, "p": paired_ttest(tb, tc)}
        run_cols = []
        if runs:
            def mean_time(rows):
                return mean_std([r["planning_time_s"] for r in rows])[0]
            g["bilevel runs"] = res.per_run([a for a, _ in pairs], mean_time)
            g["cfs runs"] = res.per_run([b for _, b in pairs], mean_time)
            run_cols = [fmt_pm(g["bilevel runs"]), fmt_pm(g["cfs runs"])]
        groups.append(g)
        rows.append([label, str(len(pairs)), fmt_pm(mb), fmt_s(g["bilevel_median_s"]), fmt_pm(mc),
                     fmt_s(g["cfs_median_s"]), fmt_ratio(speedup), fmt_p(g["p"])] + run_cols +
                    [_paper_pm(p3["bilevel"]) if p3 else DASH, _paper_pm(p3["cfs"]) if p3 else DASH,
                     fmt_ratio(ps) if ps else DASH])
    lines = ["Planning time (s) of every problem both were run on, solved or not (the planner call alone); "
             "mean ± std over problems, median; speedup = mean `cfs` / mean `bilevel`; p on paired times." +
             (" Columns marked 'runs': mean ± std over runs of each run's mean time." if runs else ""), ""]
    lines += md_table(["n", "problems", "`bilevel` (s)", "`bilevel` median (s)", "`cfs` (s)", "`cfs` median (s)",
                       "speedup", "p"] + (["`bilevel` runs (s)", "`cfs` runs (s)"] if runs else []) +
                      ["paper bilevel (s)", "paper cfs (s)", "paper speedup"], rows)
    split_rows, split = [], []
    for subset, want in (("Level 1", True), ("rest", False)):
        for label, keep in _by_n(res):
            everything = res.paired("bilevel", "cfs", keep)
            pairs = [(a, b) for a, b in everything if (a.get("level") == 1) == want]
            tb, tc = _times(pairs)
            s: dict[str, Any] = {"subset": subset, "group": label, "problems": len(pairs),
                 "share_pct": 100.0 * len(pairs) / len(everything) if everything else None,
                 "bilevel_s": mean_std(tb), "cfs_s": mean_std(tc),
                 "bilevel_success_pct": rate_pct([a["success"] for a, _ in pairs]),
                 "cfs_success_pct": rate_pct([b["success"] for _, b in pairs])}
            split.append(s)
            split_rows.append([subset, label, str(s["problems"]), fmt_pct(s["share_pct"]), fmt_pm(s["bilevel_s"]),
                               fmt_pm(s["cfs_s"]), fmt_pct(s["bilevel_success_pct"]), fmt_pct(s["cfs_success_pct"])])
    split_rows.append(["paper: Level 1", "all", DASH, f"≈{paper.LEVEL1_SHARE_PCT:.0f}",
                       _paper_pm(paper.LEVEL1_TIME_S["bilevel"], 3), _paper_pm(paper.LEVEL1_TIME_S["cfs"], 3),
                       DASH, DASH])
    split_rows.append(["paper: rest", "all", DASH, DASH, _paper_pm(paper.REST_TIME_S["bilevel"]),
                       _paper_pm(paper.REST_TIME_S["cfs"]), DASH, DASH])
    lines += ["Problems the bilevel planner solved at Level 1 (a verified symbolic plan) and the rest (Level 2 or "
              "no plan), with both methods' planning time (s) and success on the same problems:", ""]
    lines += md_table(["subset", "n", "problems", "share (%)", "`bilevel` (s)", "`cfs` (s)", "`bilevel` success (%)",
                       "`cfs` success (%)"], split_rows)
    series: dict[str, list[float | None]] = {}
    errors: dict[str, list[float | None]] = {}
    for m in ("bilevel", "cfs"):  # one bar per n and method, ours and the paper's
        ours = [g[f"{m}_s"] for g in groups[:-1]]
        theirs = [paper.TABLE3_TIME_S.get(n, {}).get(m, (None, None)) for n in res.ns]
        series[f"{m} (ours)"], errors[f"{m} (ours)"] = [v[0] for v in ours], [v[1] for v in ours]
        series[f"{m} (paper)"], errors[f"{m} (paper)"] = [v[0] for v in theirs], [v[1] for v in theirs]
    png = plots.grouped_bars(figures / "planning_time.png", "Table III: planning time", [f"n={n}" for n in res.ns],
                             series, ylabel="planning time (s)", errors=errors, ylim=None,
                             colors={"bilevel (ours)": plots.COLORS["bilevel"], "cfs (ours)": plots.COLORS["cfs"],
                                     "bilevel (paper)": "#98df8a", "cfs (paper)": "#aec7e8"})
    lines += [f"![Table III]({png.parent.name}/{png.name})", ""]
    return Section("table3", title, lines, {"groups": groups, "levels": split,
                                            "paper": {"time_s": paper.TABLE3_TIME_S, "speedup": paper.TABLE3_SPEEDUP,
                                                      "level1_share_pct": paper.LEVEL1_SHARE_PCT,
                                                      "level1_time_s": paper.LEVEL1_TIME_S,
                                                      "rest_time_s": paper.REST_TIME_S}})


def section_replanning(res: Results, figures: Path) -> Section:
    title = "8. Replanning (Table IV)"
    if not res.has("bilevel", "bilevel_replan"):
        return _skipped("replanning", title, "No `bilevel` and `bilevel_replan` rows together: replanning skipped.")
    ks = [k for k in res.ks if k > 1]
    if not ks:
        return _skipped("replanning", title, "No problems with k > 1: replanning skipped.")
    table = compare_success(res, "bilevel", "bilevel_replan", _by_k(res, ks, "all k > 1"))
    rows = []
    for t, (_, keep) in zip(table, _by_k(res, ks)):
        rounds = [b["rounds"] for _, b in res.paired("bilevel", "bilevel_replan", keep) if b.get("rounds") is not None]
        t["rounds_mean"] = mean_std(rounds)[0]
        t["gain_points"] = None if t["bilevel"] is None else t["bilevel_replan"] - t["bilevel"]
        pk = paper.REPLAN_SUCCESS.get(int(t["group"])) if t["group"].isdigit() else None
        runs = [fmt_pm(t["bilevel runs"], 1), fmt_pm(t["bilevel_replan runs"], 1)] if "bilevel runs" in t else []
        rows.append([t["group"], str(t["problems"]), fmt_pct(t["bilevel"]), fmt_pct(t["bilevel_replan"]),
                     fmt_pct(t["gain_points"]), fmt_p(t["p"]), fmt_ratio(t["rounds_mean"])] + runs +
                    [_paper_pm(pk["bilevel"], 1, 100) if pk else DASH,
                     _paper_pm(pk["bilevel_replan"], 1, 100) if pk else DASH])
    lines = md_table(["k", "problems", "`bilevel` (%)", "`bilevel_replan` (%)", "gain (points)", "p",
                      "rounds (mean)"] + (["`bilevel` runs (%)", "`bilevel_replan` runs (%)"]
                                          if len(res.runs) > 1 else []) + ["paper w/o (%)", "paper w (%)"], rows)
    lines += ["Paper: success fractions of its Table IV as percent, mean ± std over ten runs, averaged over n; "
              "it gives no p-values." + _runs_note(res) + _protocol_note(res) +
              _backend_note(res, ("bilevel", "bilevel_replan")), ""]
    return Section("replanning", title, lines, {"groups": table, "paper": paper.REPLAN_SUCCESS})


def section_refinement(res: Results, figures: Path) -> Section:
    title = "9. Refinement"
    rows, data = [], {}
    for m in res.methods:
        rs = res.select(m)
        plans = [r for r in rs if r.get("refined") is not None]
        stages = Counter((r.get("refine_failure") or {}).get("stage") for r in rs if r.get("refine_failure"))
        times = [t for r in rs for t in (r.get("refine_time_s") or [])]
        executed = [r.get("executed_actions") or 0 for r in plans]
        d: dict[str, Any]
        d = {"rows": len(rs), "plans": len(plans), "refined_pct": rate_pct([r["refined"] for r in plans]),
             "failures": {s: stages.get(s, 0) for s in STAGES}, "refine_time_median_s": median(times),
             "refine_time_p90_s": percentile(times, 90), "refined_actions": len(times),
             "executed_actions_mean": mean_std(executed)[0]}
        data[m] = d
        rows.append([f"`{m}`", str(len(rs)), str(len(plans)), fmt_pct(d["refined_pct"])] +
                    [str(d["failures"][s]) for s in STAGES] +
                    [str(len(times)), fmt_s(d["refine_time_median_s"]), fmt_s(d["refine_time_p90_s"]),
                     fmt_ratio(d["executed_actions_mean"])])
    lines = ["Plans are rows with a refinement outcome; refined (%) = every action refined (IK, motion, grasp); "
             "failures by stage count rows; refinement time per action over every action it was tried on "
             "(closed loop: the whole step).", ""]
    lines += md_table(["method", "rows", "plans", "refined (%)", "ik failures", "motion failures", "grasp failures",
                       "actions timed", "refine time median (s)", "refine time p90 (s)", "executed actions (mean)"],
                      rows)
    lines += ["The paper reports no refinement figures.", ""]
    return Section("refinement", title, lines, data)


def section_feasibility(res: Results, figures: Path) -> Section:
    title = "12. Kinematics in the planning loop: before and after"
    pairs = [(a, b) for a, b in FEASIBILITY_PAIRS if res.has(a, b)]
    if not pairs:
        return _skipped("feasibility", title, "No method was run both with and without kinematics in the planning "
                        "loop (e.g. `cfs` and `cfs_nofeas`).")
    lines = ["Each method with the kinematic check and refinement in the planning loop (after) and without "
             "(before, `*_nofeas`), on the same problems. Refined = the returned plan refined completely "
             "(% of plans); p from a paired t-test on 0/1 success.", ""]
    srows, trows, crows, data = [], [], [], {}
    for a, b in pairs:
        both = res.paired(a, b)
        plans = {m: [r for r in (ra if m == a else rb for ra, rb in both) if r.get("refined") is not None]
                 for m in (a, b)}
        sa, sb = [ra["success"] for ra, _ in both], [rb["success"] for _, rb in both]
        entry: dict[str, Any]
        entry = {"problems": len(both), "refined_pct": {m: rate_pct([r["refined"] for r in plans[m]]) for m in (a, b)},
                 "success_pct": {a: rate_pct(sa), b: rate_pct(sb)}, "p": paired_ttest(sa, sb), "time": {}}
        srows.append([f"`{a}`", str(len(both)), fmt_pct(entry["refined_pct"][b]), fmt_pct(entry["refined_pct"][a]),
                      fmt_pct(entry["success_pct"][b]), fmt_pct(entry["success_pct"][a]),
                      fmt_ratio(None if sa == [] else (rate_pct(sa) or 0) - (rate_pct(sb) or 0), 1), fmt_p(entry["p"])])
        for label, keep in _by_n(res):
            pn = res.paired(a, b, keep)
            ta, tb = [ra["planning_time_s"] for ra, _ in pn], [rb["planning_time_s"] for _, rb in pn]
            entry["time"][label] = {"mean_before_s": mean_std(tb)[0], "mean_after_s": mean_std(ta)[0],
                                    "median_before_s": median(tb), "median_after_s": median(ta)}
            t = entry["time"][label]
            trows.append([f"`{a}`", label, str(len(pn)), fmt_s(t["mean_before_s"]), fmt_s(t["mean_after_s"]),
                          fmt_s(t["median_before_s"]), fmt_s(t["median_after_s"])])
        after = [ra for ra, _ in both]
        check = sum(r.get("feasibility_time_s") or 0.0 for r in after)
        search = sum(r.get("search_time_s") or 0.0 for r in after)
        refine = sum(r.get("plan_refine_time_s") or 0.0 for r in after)
        rejected: Counter = Counter()
        for r in after:
            for level, counts in ((r.get("feasibility") or {}).get("rejected") or {}).items():
                for reason, c in counts.items():
                    rejected[f"{level}: {reason}"] += c
        refinements = sum((r.get("feasibility") or {}).get("refinements", 0) for r in after)
        failed = sum((r.get("feasibility") or {}).get("refinement_failures", 0) for r in after)
        entry.update({"check_time_s": check, "search_time_s": search, "plan_refine_time_s": refine,
                      "check_over_search": check / search if search else None, "rejected": dict(rejected),
                      "refinements": refinements, "refinement_failures": failed})
        crows.append([f"`{a}`", fmt_s(check), fmt_s(search), fmt_pct(100 * check / search if search else None),
                      fmt_s(refine), f"{refinements} ({failed} failed)",
                      ", ".join(f"{k} {v}" for k, v in sorted(rejected.items())) or DASH])
        data[a] = entry
    lines += md_table(["method", "problems", "refined before (%)", "refined after (%)", "success before (%)",
                       "success after (%)", "gain (points)", "p"], srows)
    lines += ["Planning time (s) per n, before and after:", ""]
    lines += md_table(["method", "n", "problems", "mean before", "mean after", "median before", "median after"], trows)
    lines += ["Cost and rejections (after), summed over problems: check time is the kinematic check alone "
              "(inside the search for Level 2), search time the continuous search's (check included), "
              "refinement the full refinements the planner ran before returning a plan.", ""]
    lines += md_table(["method", "check (s)", "search (s)", "check / search (%)", "refinement (s)",
                       "refinements", "rejected (level: reason count)"], crows)
    return Section("feasibility", title, lines, data)


def section_level1(res: Results, figures: Path) -> Section:
    title = "10. Level 1: the paper's Algorithm 1 and our extensions"
    if not res.has("bilevel", "bilevel_alg1"):
        return _skipped("level1", title, "No `bilevel` and `bilevel_alg1` rows together: the Level-1 extensions "
                                         "are not compared.")
    table = compare_success(res, "bilevel_alg1", "bilevel", _by_n(res))
    rows = []
    for t, (_, keep) in zip(table, _by_n(res)):
        pairs = res.paired("bilevel_alg1", "bilevel", keep)
        for m, side in (("bilevel_alg1", 0), ("bilevel", 1)):
            rs = [pair[side] for pair in pairs]
            t[f"{m} level1_pct"] = rate_pct([r.get("level") == 1 for r in rs])
            t[f"{m} level1_success_pct"] = rate_pct([r.get("level") == 1 and r["success"] for r in rs])
            t[f"{m} level1_time_s"] = mean_std([r.get("level1_time_s") or 0.0 for r in rs])[0]
            t[f"{m} time_s"] = mean_std([r["planning_time_s"] for r in rs])[0]
            if len(res.runs) > 1:
                t[f"{m} level1 runs"] = res.per_run(rs, lambda g: rate_pct([r.get("level") == 1 for r in g]))
        rows.append([t["group"], str(t["problems"]), fmt_pct(t["bilevel_alg1"]), fmt_pct(t["bilevel"]), fmt_p(t["p"]),
                     fmt_pct(t["bilevel_alg1 level1_pct"]), fmt_pct(t["bilevel level1_pct"]),
                     fmt_pct(t["bilevel_alg1 level1_success_pct"]), fmt_pct(t["bilevel level1_success_pct"]),
                     fmt_s(t["bilevel_alg1 time_s"]), fmt_s(t["bilevel time_s"])] +
                    ([fmt_pm(t["bilevel_alg1 level1 runs"], 1), fmt_pm(t["bilevel level1 runs"], 1)]
                     if len(res.runs) > 1 else []))
    rows.append(["paper", DASH, DASH, DASH, DASH, f"≈{paper.LEVEL1_SHARE_PCT:.0f}", DASH, DASH, DASH, DASH, DASH] +
                ([DASH, DASH] if len(res.runs) > 1 else []))
    lines = ["`bilevel_alg1` is the paper's Algorithm 1 exactly; `bilevel` adds look-alike alternatives (plans "
             "through the same symbolic states, verified in one rollout after each ranked plan) and asks for a "
             "non-empty symbolic plan when X_init is not within tau of the goal although the symbols agree. "
             "Level 1 (%): problems whose plan came from a verified symbolic plan; Level-1 success (%): those that "
             "also reached the goal; times are mean planning time (s). p on paired 0/1 success." +
             _runs_note(res) + _protocol_note(res) + _backend_note(res, ("bilevel", "bilevel_alg1")), ""]
    lines += md_table(["n", "problems", "`bilevel_alg1` (%)", "`bilevel` (%)", "p", "`bilevel_alg1` Level 1 (%)",
                       "`bilevel` Level 1 (%)", "`bilevel_alg1` Level-1 success (%)", "`bilevel` Level-1 success (%)",
                       "`bilevel_alg1` time (s)", "`bilevel` time (s)"] +
                      (["`bilevel_alg1` Level 1 runs (%)", "`bilevel` Level 1 runs (%)"] if len(res.runs) > 1 else []),
                      rows)
    times = _level1_times(res)
    if times:
        lines += ["", "Level-1 time per problem (ms), median / mean, in total and per stage: symbols (the Symbolic "
                  "Model on X_init and X_goal), symbolic (sampled domains and the symbolic search), verify (rollouts "
                  "of the ranked plans and their alternatives); kinematic checks and refinement are not in it. "
                  f"The paper: {paper.LEVEL1_TIME_S['bilevel'][0] * 1000:.0f} ± "
                  f"{paper.LEVEL1_TIME_S['bilevel'][1] * 1000:.0f} ms (mean, problems solved at Level 1).", ""]
        lines += md_table(["n", "method", "problems", "Level 1", "symbols", "symbolic", "verify"],
                          [[t["group"], f"`{t['method']}`", str(t["problems"])] +
                           [_ms_pair(t.get(k)) for k in ("level1", "symbols", "symbolic", "verify")] for t in times])
    return Section("level1", title, lines, {"groups": table, "paper_level1_share_pct": paper.LEVEL1_SHARE_PCT,
                                            "times": times})


def _level1_times(res: Results) -> list[dict]:
    """Per n and Level-1 method: median and mean Level-1 time and, where rows have them, per stage (s)."""
    out = []
    for label, keep in _by_n(res):
        for m in ("bilevel_alg1", "bilevel"):
            rs = [r for r in res.rows
                  if r["method"] == m and keep(r["n"], r["k"]) and r.get("level1_time_s") is not None]
            if not rs:
                continue
            t: dict[str, Any] = {"group": label, "method": m, "problems": len(rs)}
            t["level1"] = _median_mean([r["level1_time_s"] for r in rs])
            staged = [r["level1_stages_s"] for r in rs if r.get("level1_stages_s")]
            if len(staged) == len(rs):
                for stage in ("symbols", "symbolic", "verify"):
                    t[stage] = _median_mean([st.get(stage) or 0.0 for st in staged])
            out.append(t)
    return out


def _median_mean(xs: list[float]) -> tuple[float | None, float | None]:
    return median(xs), mean_std(xs)[0]


def _ms_pair(pair: tuple[float | None, float | None] | None) -> str:
    if pair is None or pair[0] is None or pair[1] is None:
        return DASH
    return f"{pair[0] * 1000:.1f} / {pair[1] * 1000:.1f}"


def section_symbols(symbols: list[dict] | None, source: Path) -> Section:
    title = "11. Learned symbols"
    if symbols is None:
        return _skipped("symbols", title, f"No {source.name} beside the rows (written by `tamp evaluate` when a method "
                                          "plans with the Symbolic Model): the symbols are not described.")
    rows = []
    for b in symbols:
        f = b["best"]
        rows.append([b["name"], str(b["count"]), f"{b['rate']:.3f}", ("not " if b["negated"][f] else "") + f,
                     fmt_pct(100 * b["agreement"][f]), f"{b['phi'][f]:+.2f}"])
    lines = ["Each learned bit on the problem set's initial and goal scenes (`tamp symbols`): how often it is 1 and "
             "the geometric fact it agrees with best (by |phi|, the Matthews correlation; agreement is the share of "
             "objects or ordered pairs where the bit equals the fact, or its negation with 'not'). u: unary bits, "
             "r: relations r(i, j) with i != j, r(i,i): the self relation, read as a unary bit.", ""]
    lines += md_table(["bit", "read on", "rate", "best fact", "agreement (%)", "phi"], rows)
    return Section("symbols", title, lines, {"bits": symbols})


def section_scaling(res: Results, figures: Path) -> Section:
    title = "13. Scaling with the number of blocks"
    if len(res.ns) < 2:
        return _skipped("scaling", title, f"The problems have one object count (n = {res.ns[0]}): nothing to "
                                          "scale over (`tamp problems --objects 2,3,4,5,6`).")
    numbers = scaling.scaling_numbers(res.rows)
    png = plots.scaling_curves(figures / "scaling.png", numbers) if numbers["methods"] else None
    lines = scaling.scaling_lines(numbers, None if png is None else f"{png.parent.name}/{png.name}")
    lines[0] += _protocol_note(res)
    return Section("scaling", title, lines, numbers)


def section_fidelity(res: Results) -> Section:
    title = "14. Abstraction fidelity: symbolic steps realised by motion"
    numbers = refinability.fidelity_by_method(res.rows)
    if not any(f["judged"] for f in numbers):
        return _skipped("fidelity", title, "No row has an executed step judged against a learned operator (rows "
                                           "written before per-step records, or models without a Symbolic Model).")
    lines = [f"Every executed plan step read through the learned abstraction. {refinability.FIDELITY_NOTE} "
             "The last two columns relate a step that breaks the abstraction to the plan's outcome: the success "
             "rate of problems whose executed steps were all as expected, and of those with at least one that "
             "was not. Per operator: `tamp refinability` on this directory.", ""]
    lines += refinability.fidelity_lines(numbers)
    return Section("fidelity", title, lines, {"methods": numbers})


# --- the report ----------------------------------------------------------------------------------
def _json_safe(x: Any) -> Any:
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {str(k): _json_safe(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_json_safe(v) for v in x]
    return x


def build_report(res: Results, figures: Path, ablation: dict | None = None,
                 ablation_source: Path = Path("ablation.json"), source: str = "rows.jsonl",
                 symbols: list[dict] | None = None, symbols_source: Path = Path("symbols.json")) -> tuple[str, dict]:
    """The Markdown report and its numbers (a JSON-ready dict); writes the PNGs into `figures`."""
    figures.mkdir(parents=True, exist_ok=True)
    sections = [section_setup(res, figures), section_table1(ablation, ablation_source),
                section_dual_model(res, figures), section_table2(res, figures), section_verifier(res, figures),
                section_success(res, figures), section_table3(res, figures), section_replanning(res, figures),
                section_refinement(res, figures), section_level1(res, figures),
                section_symbols(symbols, symbols_source)]
    if any(res.has(a, b) for a, b in FEASIBILITY_PAIRS):  # only when run before and after (`*_nofeas`)
        sections.append(section_feasibility(res, figures))
    sections.append(section_scaling(res, figures))
    sections.append(section_fidelity(res))
    lines = ["# Evaluation report", "",
             f"From `{source}` ({len(res.rows)} rows, {len(res.cells)} problems). Ours next to the paper's "
             "numbers (Dogangun et al., quoted as printed). Success in % of problems (one decimal), times in "
             "seconds (three decimals); p from `scipy.stats.ttest_rel` on per-problem pairs, 'identical' when "
             "the two agree on every problem, '—' with fewer than two pairs.", ""]
    for s in sections:
        lines += [f"## {s.title}", ""] + s.lines
    numbers = {"source": source, "sections": {s.key: s.data for s in sections},
               "skipped": [s.key for s in sections if s.data is None]}
    return "\n".join(lines).rstrip() + "\n", _json_safe(numbers)


def write_report(results_dir: Path, ablation: Path | None = None) -> Path:
    """Write results_dir/report.md, report.json and figures/*.png from results_dir/rows.jsonl; returns report.md.

    `ablation`: the JSON of `tamp ablate-activations` (default results_dir/ablation.json, if present).
    """
    results_dir = Path(results_dir)
    rows_path = results_dir / "rows.jsonl"
    rows, dropped = _read_rows(rows_path)
    notes = [] if dropped is None else [f"Line {dropped} of {rows_path} is incomplete (an interrupted evaluation) "
                                        "and was left out."]
    errors = [r for r in rows if r["outcome"] == ERROR_OUTCOME]
    rows = [r for r in rows if r["outcome"] != ERROR_OUTCOME]
    notes += [f"Problem `{r['problem']}` with method `{r['method']}` raised an error and is left out of every "
              f"table: {r.get('error', 'no message')}" for r in errors]
    if not rows:
        raise UserError(f"{rows_path}: every row is an error row ({len(errors)}); nothing to report")
    meta_path = results_dir / "meta.json"
    meta = read_json_object(meta_path, "the evaluation's meta.json") if meta_path.is_file() else None
    if ablation is not None and not Path(ablation).is_file():
        raise UserError(f"{ablation}: no such ablation file")
    ablation_path = Path(ablation) if ablation is not None else results_dir / "ablation.json"
    ablation_data = load_ablation(ablation_path) if ablation_path.is_file() else None
    symbols_path = results_dir / "symbols.json"
    symbols = _read_symbols(symbols_path) if symbols_path.is_file() else None
    md, numbers = build_report(Results(rows, meta, notes), results_dir / "figures", ablation_data, ablation_path,
                               str(rows_path), symbols, symbols_path)
    out = results_dir / "report.md"
    atomic_write_text(results_dir / "report.json", json.dumps(numbers, indent=1, ensure_ascii=False) + "\n")
    atomic_write_text(out, md)
    return out


__all__ = ["METHOD_ORDER", "OUTCOMES", "Results", "build_report", "compare_success", "load_ablation", "load_rows",
           "write_report"]
