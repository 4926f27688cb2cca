"""Before and after: two evaluations of the same problems, paired per (problem, run, method).

`tamp compare BEFORE AFTER` answers "did my change help?": per method and number of blocks n, on the
problems both results directories hold, the success rate before and after with a paired t-test, the
planning time (median / mean) before and after, and the problems gained and lost. A results
directory's rows may be `rows.jsonl` or the shipped `rows.jsonl.gz`. Plain dicts in, plain dicts out,
so that a test can recompute every cell from rows.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

from guarded import LARGE, Schema, read_jsonl
from tamp.errors import UserError

from .format import fmt_ms, fmt_p, fmt_pct, md_table
from .stats import mean_std, median, paired_ttest, rate_pct

MAX_NAMED = 8  # problems named per gained / lost cell


# the fields of a row a comparison reads
ROW_SCHEMA = Schema({"type": "object", "required": ["problem", "method", "n", "success", "planning_time_s"],
                     "properties": {"problem": {"type": "string"}, "method": {"type": "string"},
                                    "run": {"type": ["integer", "null"], "minimum": 0},
                                    "n": {"type": "integer", "minimum": 1}, "success": {"type": "boolean"},
                                    "planning_time_s": {"type": "number"}, "outcome": {"type": "string"}}})


def load_rows(directory: Path) -> list[dict]:
    """The rows of a results directory: rows.jsonl, else rows.jsonl.gz (a last line cut short by a
    kill is left out), each checked against `ROW_SCHEMA`."""
    plain, packed = directory / "rows.jsonl", directory / "rows.jsonl.gz"
    if plain.is_file() or packed.is_file():
        path = plain if plain.is_file() else packed
        lines = read_jsonl(path, "rows file", LARGE, unfinished=True)
        for number, row in lines.values:
            ROW_SCHEMA.check(row, f"{path} line {number}")
        return [row for _, row in lines.values]
    raise UserError(f"no rows.jsonl or rows.jsonl.gz in {directory} (the --out directory of `tamp evaluate`)")


def _key(row: dict) -> tuple:
    return row["problem"], row.get("run"), row["method"]


def compare_numbers(before: Sequence[dict], after: Sequence[dict]) -> dict[str, Any]:
    """Per method (in the after rows' order) and n (then 'all'): the paired cells over the
    (problem, run) both sides hold for that method. A pair with an error row on either side (the
    evaluation crashed there, `tamp evaluate` says where) is counted and left out, as the report does."""
    from .row import ERROR_OUTCOME

    old = {_key(r): r for r in before}
    matched = [(old[_key(r)], r) for r in after if _key(r) in old]
    pairs = [(a, b) for a, b in matched if ERROR_OUTCOME not in (a.get("outcome"), b.get("outcome"))]
    methods = list(dict.fromkeys(r["method"] for _, r in pairs))
    out: dict[str, Any] = {"pairs": len(pairs), "errors": len(matched) - len(pairs),
                           "only_before": len(old) - len(matched), "only_after": len(after) - len(matched),
                           "methods": {}}
    for m in methods:
        mine = [(a, b) for a, b in pairs if b["method"] == m]
        cells = {}
        for n in sorted({b["n"] for _, b in mine}) + ["all"]:
            group = [(a, b) for a, b in mine if n == "all" or b["n"] == n]
            cells[n] = _cell(group)
        out["methods"][m] = cells
    return out


def _cell(group: Sequence[tuple[dict, dict]]) -> dict[str, Any]:
    ok_a, ok_b = [bool(a["success"]) for a, _ in group], [bool(b["success"]) for _, b in group]
    t_a, t_b = [a["planning_time_s"] for a, _ in group], [b["planning_time_s"] for _, b in group]
    p = paired_ttest([float(x) for x in ok_a], [float(x) for x in ok_b])
    return {"problems": len(group), "success_before_pct": rate_pct(ok_a), "success_after_pct": rate_pct(ok_b),
            "p": p, "time_before_median_s": median(t_a), "time_after_median_s": median(t_b),
            "time_before_mean_s": mean_std(t_a)[0], "time_after_mean_s": mean_std(t_b)[0],
            "gained": sorted(b["problem"] for a, b in group if b["success"] and not a["success"]),
            "lost": sorted(b["problem"] for a, b in group if a["success"] and not b["success"])}


def _names(names: Sequence[str]) -> str:
    if not names:
        return "—"
    shown = ", ".join(names[:MAX_NAMED])
    return f"{len(names)}: {shown}" + (f" and {len(names) - MAX_NAMED} more" if len(names) > MAX_NAMED else "")


def compare_markdown(numbers: dict[str, Any], before: str, after: str) -> str:
    """The comparison as Markdown (`compare_numbers`' output)."""
    lines = [f"# Before and after: `{before}` -> `{after}`", "",
             f"{numbers['pairs']} (problem, run, method) rows paired; {numbers['only_before']} only before, "
             f"{numbers['only_after']} only after, {numbers['errors']} with an error row on a side (not compared). "
             "Success (%) before -> after with the paired t-test's p over the same problems; planning time (ms) "
             "median / mean before -> after.", ""]
    rows = []
    for m, cells in numbers["methods"].items():
        for n, c in cells.items():
            rows.append([f"`{m}`", n, c["problems"],
                         f"{fmt_pct(c['success_before_pct'])} -> {fmt_pct(c['success_after_pct'])}", fmt_p(c["p"]),
                         f"{fmt_ms(c['time_before_median_s'])} / {fmt_ms(c['time_before_mean_s'])} -> "
                         f"{fmt_ms(c['time_after_median_s'])} / {fmt_ms(c['time_after_mean_s'])}",
                         _names(c["gained"]), _names(c["lost"])])
    lines += md_table(["method", "n", "problems", "success (%)", "p", "planning ms (median / mean)", "gained",
                       "lost"], rows)
    return "\n".join(lines)


__all__ = ["compare_markdown", "compare_numbers", "load_rows"]
