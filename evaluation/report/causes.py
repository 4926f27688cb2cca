"""Report section 15: why the failed problems failed, per method and number of blocks.

Each cause is recomputed from the row's own fields (`evaluation.run.row_cause`, the classification of
`tamp.planning.causes`), so a report of older rows gives them too, as far as those rows tell."""
from __future__ import annotations

from collections import Counter
from pathlib import Path

from tamp.planning.causes import Cause

from ..format import md_table
from ..row import row_cause
from .results import Results, Section, _skipped

CAUSE_INFO = {
    Cause.MODEL_MISS: "a step landed 2 cm or more from the Dynamics Model's prediction",
    Cause.AIMED_NEAR_TOLERANCE: "no step missed; the plan was predicted 2 cm or more from the goal",
    Cause.SMALL_ERRORS: "every step within 2 cm of its prediction; the errors added up",
    Cause.SEARCH_BUDGET: "no plan: the continuous search reached its node or time limit",
    Cause.PRUNED: "no plan: the search ran out of actions (pruning, depth)",
    Cause.KINEMATICS: "no plan: what was found was rejected by the kinematic check or refinement",
    Cause.NO_SYMBOLIC_PLAN: "no plan from the symbolic planner alone",
    Cause.EMPTY_PLAN: "the planner returned no action while a block was off its goal",
    Cause.EXECUTION: "an action could not be carried out at execution (IK, motion, grasp)",
    Cause.OUT_OF_ROUNDS: "a closed loop used up its rounds or its action budget",
}


def causes_by_method(res: Results) -> dict[str, dict[str, dict[str, int]]]:
    """{method: {n: {cause: failed problems}}} (n "all" for every n), recomputed from the rows."""
    out: dict[str, dict[str, dict[str, int]]] = {}
    for m in res.methods:
        rows = res.select(m)
        for label, keep in [(str(n), n) for n in res.ns] + [("all", None)]:
            counts = Counter(c[0] for r in rows if (keep is None or r["n"] == keep)
                             for c in [row_cause(r)] if c is not None)
            out.setdefault(m, {})[label] = {str(cause): counts.get(str(cause), 0) for cause in Cause}
    return out


def section_causes(res: Results, figures: Path) -> Section:
    title = "15. Why problems failed"
    data = causes_by_method(res)
    used = [c for c in Cause if any(d[str(c)] for m in data.values() for d in m.values())]
    if not used:
        return _skipped("causes", title, "No method failed a problem.")
    lines = ["Failed problems per cause, method and number of blocks (`tamp.planning.causes`; recomputed from "
             "each row's fields). " + "; ".join(f"`{c}`: {CAUSE_INFO[c]}" for c in used) + ".", ""]
    rows = [[f"`{m}`", n] + [str(counts[str(c)]) for c in used] + [str(sum(counts.values()))]
            for m, by_n in data.items() for n, counts in by_n.items() if n == "all" or len(res.ns) > 1]
    lines += md_table(["method", "n"] + [f"`{c}`" for c in used] + ["failed"], rows)
    return Section("causes", title, lines, data)
