"""Which learned operators refine into motion, and how faithfully: `tamp refinability` and the report's
abstraction-fidelity summary, from the `steps` of evaluation rows (`evaluation.run`).

Per learned operator used by the planners' plans (every method's executed or attempted steps):
- uses: steps that ground their action in it;
- kinematic %: of those, the share whose action passes the planners' kinematic check on the state
  the world was in before it (grasp contact, IK on the branch, collision-free waypoints);
- refined %: the share refined into IK and collision-free motions (and, in the world, executed);
- as expected %: of the executed steps, the share whose observed symbols equal the ones the operator
  expected (the plan's effect for Level-1 steps, else its most probable effect);
- allowed %: of the executed steps, the share whose observed symbols are one of its learned effects;
- position error: the Dynamics Model's mean error on those steps (cm, mean over objects).

Abstraction fidelity, per method: the share of executed steps with an operator whose observed
symbols equal the expected ones, and how it relates to success: the success rate of problems whose
every executed step was as expected against those with at least one that was not.
Plain dicts in and out, so that a test recomputes every cell from rows.
"""
from __future__ import annotations

import csv
import io
from collections import defaultdict
from pathlib import Path
from typing import Any, Sequence

from .format import fmt_cm, fmt_pct
from .stats import rate_pct

ACCURATE_M = 0.01  # a step "went as predicted" when the Dynamics Model's mean position error on it is under 1 cm
LEAST_FAITHFUL = 10
MIN_EXECUTED = 3  # an operator enters the least-faithful list with at least this many executed steps
CSV_FIELDS = ("operator", "uses", "kinematic_pct", "refined_pct", "executed", "as_expected_pct", "allowed_pct",
              "error_cm", "methods")


def _mean(xs: Sequence[float]) -> float | None:
    return sum(xs) / len(xs) if xs else None


def _steps(rows: Sequence[dict]):
    """(row, index, step) of every step of rows that have them."""
    for r in rows:
        for i, s in enumerate(r.get("steps") or []):
            yield r, i, s


def operator_table(rows: Sequence[dict]) -> list[dict[str, Any]]:
    """One dict per operator (CSV_FIELDS and an example of a step not as expected), most used first."""
    by_op: dict[str, list[tuple[dict, int, dict]]] = defaultdict(list)
    for r, i, s in _steps(rows):
        if s["operator"] is not None:
            by_op[s["operator"]].append((r, i, s))
    table: list[dict[str, Any]] = []
    for op, uses in by_op.items():
        steps = [s for _, _, s in uses]
        executed = [s for s in steps if s["match"] is not None]
        errors = [s["error_m"] for s in executed if s.get("error_m") is not None]
        bad = next(((r, i, s) for r, i, s in uses if s["match"] is False), None)
        table.append({
            "operator": op, "uses": len(steps), "kinematic_pct": rate_pct([s["kinematic"] == "ok" for s in steps]),
            "refined_pct": rate_pct([s["refined"] for s in steps]), "executed": len(executed),
            "as_expected_pct": rate_pct([s["match"] for s in executed]),
            "allowed_pct": rate_pct([s["allowed"] for s in executed if s.get("allowed") is not None]),
            "error_cm": None if not errors else 100 * _mean(errors),  # type: ignore[operator]
            "methods": ",".join(sorted({r["method"] for r, _, _ in uses})),
            "example": None if bad is None else _example(*bad)})
    table.sort(key=lambda t: (-t["uses"], t["operator"]))
    return table


def _example(row: dict, index: int, step: dict) -> dict:
    """Where a step not as expected happened: problem, method, step number (from 1), action, bits off."""
    plan = row.get("plan") or []
    return {"problem": row["problem"], "method": row["method"], "step": index + 1,
            "action": plan[index] if index < len(plan) else None, "mismatched_bits": step["mismatched_bits"]}


def least_faithful(table: Sequence[dict], k: int = LEAST_FAITHFUL, min_executed: int = MIN_EXECUTED) -> list[dict]:
    """The k operators executed at least `min_executed` times with the lowest as-expected share
    (ties: more executed steps first)."""
    seen = [t for t in table if t["executed"] >= min_executed and t["as_expected_pct"] is not None]
    return sorted(seen, key=lambda t: (t["as_expected_pct"], -t["executed"], t["operator"]))[:k]


def fidelity_by_method(rows: Sequence[dict]) -> list[dict[str, Any]]:
    """Per method with steps: executed steps with an operator, the share as expected (and allowed),
    steps without an operator, and success of the problems whose executed steps were all as expected
    against those with a step that was not."""
    out = []
    for m in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == m and r.get("steps") is not None]
        if not mine:
            continue
        steps = [s for r in mine for s in r["steps"]]
        judged = [s for s in steps if s["match"] is not None]
        accurate = [s for s in judged if s.get("error_m") is not None and s["error_m"] < ACCURATE_M]
        faithful = [r for r in mine if r["steps"] and all(s["match"] is not False for s in r["steps"])
                    and any(s["match"] for s in r["steps"])]
        broken = [r for r in mine if any(s["match"] is False for s in r["steps"])]
        out.append({"method": m, "problems": len(mine), "steps": len(steps), "judged": len(judged),
                    "no_operator": sum(s["operator"] is None for s in steps),
                    "as_expected_pct": rate_pct([s["match"] for s in judged]),
                    "allowed_pct": rate_pct([s["allowed"] for s in judged if s.get("allowed") is not None]),
                    "accurate": len(accurate), "accurate_as_expected_pct": rate_pct([s["match"] for s in accurate]),
                    "accurate_allowed_pct": rate_pct([s["allowed"] for s in accurate if s.get("allowed") is not None]),
                    "on_plan_as_expected_pct": rate_pct([s["match"] for s in judged if s.get("on_plan")]),
                    "off_plan_as_expected_pct": rate_pct([s["match"] for s in judged if not s.get("on_plan")]),
                    "faithful_problems": len(faithful),
                    "faithful_success_pct": rate_pct([r["success"] for r in faithful]),
                    "broken_problems": len(broken), "broken_success_pct": rate_pct([r["success"] for r in broken])})
    return out


def fidelity_lines(fidelity: Sequence[dict]) -> list[str]:
    """The Markdown table of `fidelity_by_method`."""
    lines = ["| method | problems | executed steps (with an operator) | as expected (%) | allowed (%) | "
             "steps within 1 cm of the prediction: as expected / allowed (%) | "
             "Level-1 plan steps as expected (%) | other steps as expected (%) | no operator | success, all "
             "steps as expected (%) | success, a step not as expected (%) |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for f in fidelity:
        lines.append(f"| {f['method']} | {f['problems']} | {f['judged']} | {fmt_pct(f['as_expected_pct'])} | "
                     f"{fmt_pct(f['allowed_pct'])} | {fmt_pct(f['accurate_as_expected_pct'])} / "
                     f"{fmt_pct(f['accurate_allowed_pct'])} (of {f['accurate']}) | "
                     f"{fmt_pct(f['on_plan_as_expected_pct'])} | "
                     f"{fmt_pct(f['off_plan_as_expected_pct'])} | {f['no_operator']} | "
                     f"{fmt_pct(f['faithful_success_pct'])} (of {f['faithful_problems']}) | "
                     f"{fmt_pct(f['broken_success_pct'])} (of {f['broken_problems']}) |")
    return lines


FIDELITY_NOTE = ("A step is *as expected* when the symbols the Symbolic Model reads on the state after it equal "
                 "those its learned operator expected (the effect a Level-1 plan counted on, else the most probable "
                 "one), *allowed* when they are one of the operator's learned effects. Steps that were not "
                 "executed (refinement failed) are not judged. Steps within 1 cm of the prediction: those whose "
                 "objects the Dynamics Model placed within 1 cm on average, where the motion did what was "
                 "expected and only the symbols can be at fault.")


def markdown(rows: Sequence[dict], figure: str | None = None, min_executed: int = MIN_EXECUTED,
             table: Sequence[dict] | None = None) -> str:
    """The refinability report: fidelity per method, the operator table (the 30 most used; all in the
    CSV), the least faithful operators with an example each. `table`: `operator_table(rows)`, if known."""
    table = operator_table(rows) if table is None else list(table)
    lines = ["# Refinability of the learned operators", "",
             f"From {len(rows)} evaluation rows; {sum(t['uses'] for t in table)} steps grounded in "
             f"{len(table)} learned operators. {FIDELITY_NOTE}", "", "## Abstraction fidelity per method", ""]
    lines += fidelity_lines(fidelity_by_method(rows))
    lines += ["", "## Operators, most used first", ""]
    if figure:
        lines += [f"![as expected and refined per operator]({figure})", ""]
    lines += ["| operator | uses | kinematic check passed (%) | refined (%) | executed | as expected (%) | "
              "allowed (%) | position error (cm) | methods |", "|---|---|---|---|---|---|---|---|---|"]
    for t in table[:30]:
        lines.append(f"| {t['operator']} | {t['uses']} | {fmt_pct(t['kinematic_pct'])} | {fmt_pct(t['refined_pct'])} | "
                     f"{t['executed']} | {fmt_pct(t['as_expected_pct'])} | {fmt_pct(t['allowed_pct'])} | "
                     f"{fmt_cm(t['error_cm'])} | {t['methods']} |")
    if len(table) > 30:
        lines += ["", f"{len(table) - 30} more operators in refinability.csv."]
    worst = least_faithful(table, min_executed=min_executed)
    lines += ["", f"## The {len(worst)} least faithful operators (at least {min_executed} executed steps)", ""]
    if not worst:
        lines.append(f"No operator was executed {min_executed} times or more.")
    else:
        lines += ["| operator | executed | as expected (%) | allowed (%) | example: problem, method, step, action, "
                  "bits off |", "|---|---|---|---|---|"]
        for t in worst:
            e = t["example"]
            example = "—" if e is None else \
                f"{e['problem']}, {e['method']}, step {e['step']}, {e['action']}, {e['mismatched_bits']}"
            lines.append(f"| {t['operator']} | {t['executed']} | {fmt_pct(t['as_expected_pct'])} | "
                         f"{fmt_pct(t['allowed_pct'])} | {example} |")
    return "\n".join(lines) + "\n"


def csv_text(table: Sequence[dict]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, CSV_FIELDS, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for t in table:
        writer.writerow({k: ("" if t[k] is None else round(t[k], 3) if isinstance(t[k], float) else t[k])
                         for k in CSV_FIELDS})
    return buffer.getvalue()


def write(rows: Sequence[dict], out_dir: Path, min_executed: int = MIN_EXECUTED) -> list[Path]:
    """refinability.md, refinability.csv and figures/refinability.png in out_dir."""
    from tamp.records import atomic_write_text

    from .plots import refinability_scatter

    table = operator_table(rows)
    png = refinability_scatter(Path(out_dir) / "figures" / "refinability.png", table) if table else None
    md = atomic_write_text(Path(out_dir) / "refinability.md",
                           markdown(rows, None if png is None else f"figures/{png.name}", min_executed, table))
    out = [md, atomic_write_text(Path(out_dir) / "refinability.csv", csv_text(table))]
    return out + ([png] if png is not None else [])
