"""Report sections on plans made motion: 9. refinement, 12. kinematics in the planning loop (before
and after), 14. abstraction fidelity (symbolic steps realised by motion)."""
from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

from .. import refinability
from ..format import DASH, fmt_p, fmt_pct, fmt_ratio, fmt_s, md_table
from ..stats import mean_std, median, paired_ttest, percentile, rate_pct
from .results import FEASIBILITY_PAIRS, Results, Section, _by_n, _skipped
from .rows import STAGES


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
                      "check_share": check / (check + search) if check + search else None,
                      "rejected": dict(rejected),
                      "refinements": refinements, "refinement_failures": failed})
        crows.append([f"`{a}`", fmt_s(check), fmt_s(search),
                      fmt_pct(100 * check / (check + search) if check + search else None),
                      fmt_s(refine), f"{refinements} ({failed} failed)",
                      ", ".join(f"{k} {v}" for k, v in sorted(rejected.items())) or DASH])
        data[a] = entry
    lines += md_table(["method", "problems", "refined before (%)", "refined after (%)", "success before (%)",
                       "success after (%)", "gain (points)", "p"], srows)
    lines += ["Planning time (s) per n, before and after:", ""]
    lines += md_table(["method", "n", "problems", "mean before", "mean after", "median before", "median after"], trows)
    lines += ["Cost and rejections (after), summed over problems: check time is the kinematic check alone "
              "(Level 1's plans and Level 2's successors), search time the continuous search's own (the check "
              "not included), refinement the full refinements the planner ran before returning a plan.", ""]
    lines += md_table(["method", "check (s)", "search (s)", "check / (check + search) (%)", "refinement (s)",
                       "refinements", "rejected (level: reason count)"], crows)
    return Section("feasibility", title, lines, data)


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
