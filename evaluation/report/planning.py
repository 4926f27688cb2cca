"""Report sections on the planners: 6. success per (n, k) (Fig. 5), 7. Table III (planning time),
8. replanning (Table IV), 10. Level 1 (Algorithm 1 and our extensions), 13. scaling with n."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from tamp.planning.vocabulary import OUTCOMES

from .. import paper, plots, scaling
from ..format import DASH, fmt_p, fmt_pct, fmt_pm, fmt_ratio, fmt_s, md_table
from ..stats import mean_std, median, paired_ttest, rate_pct
from .results import (
    Results,
    Section,
    _backend_note,
    _by_k,
    _by_n,
    _cell_is,
    _everything,
    _n_is,
    _paper_pm,
    _protocol_note,
    _runs_note,
    _skipped,
    compare_success,
    fmt_paper_p,
)


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
    lines = ["`bilevel_alg1` is the paper's Algorithm 1 exactly; `bilevel` adds our extensions "
             "(docs/beyond-the-paper.md). "
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
                  "of the ranked plans); kinematic checks and refinement are not in it. "
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
