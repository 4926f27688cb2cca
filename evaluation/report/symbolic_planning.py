"""Report sections on the learned abstraction in planning: 3. Fig. 4 (dual-model validation),
4. Table II (deterministic vs probabilistic symbolic planning), 5. the verifier (Figs. 6 and 7)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from .. import paper, plots
from ..format import DASH, fmt_p, fmt_pct, fmt_pm, fmt_ratio, md_table
from ..stats import confusion, mean_std
from .results import (
    TAUS_CM,
    Results,
    Section,
    _backend_note,
    _by_k,
    _by_n,
    _moved,
    _paper_pm,
    _protocol_note,
    _runs_note,
    _skipped,
    _success,
    compare_success,
    fmt_paper_p,
)


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
    cap = (res.meta or {}).get("config", {}).get("evaluation", {}).get("oracle_max_plans")
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
