"""Report sections on what was run: 1. Setup, 2. Table I (effect error per bottleneck activation),
11. the learned symbols."""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from .. import paper
from ..format import DASH, fmt_pct, md_table
from .results import METHOD_INFO, Results, Section, _moved, _paper_pm, _skipped


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
