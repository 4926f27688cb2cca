"""How cost and success grow with the number of blocks: the numbers of the report's scaling section.

Per method and object count n: success, median and mean planning time, the share of problems solved
at Level 1 and Level 1's time, the share of returned plans that refined, and the Dynamics Model's
effect error on the executed actions (row field `effect_error_m`). The growth factor per added block
is t(n + 1) / t(n) of the mean (and the median) planning time; over a range of counts, the geometric
mean of those steps. Plain dicts in, plain dicts out, so that a test can recompute them from rows.
"""
from __future__ import annotations

from typing import Any, Sequence

from .format import fmt_factor, fmt_ms, fmt_pct
from .stats import mean_std, median, rate_pct

SYMBOLIC_LEVEL = ("bilevel", "bilevel_alg1", "bilevel_replan")  # methods with a Level 1
# methods planning with the default Dynamics Model: their executed actions measure its effect error
DEFAULT_DYNAMICS = ("cfs", "bilevel", "bilevel_alg1", "bilevel_replan")


def _growth(a: float | None, b: float | None, steps: int) -> float | None:
    """Per-step factor from a to b over `steps` added blocks (None if either is missing or zero)."""
    if a is None or b is None or a <= 0 or b <= 0 or steps < 1:
        return None
    return (b / a) ** (1.0 / steps)


def cell(rows: Sequence[dict], method: str) -> dict[str, Any]:
    """The scaling numbers of one (method, n): `rows` are that method's rows at that n."""
    times = [r["planning_time_s"] for r in rows]
    plans = [r for r in rows if r.get("refined") is not None]
    out: dict[str, Any] = {"problems": len(rows), "success_pct": rate_pct([r["success"] for r in rows]),
                           "time_median_s": median(times), "time_mean_s": mean_std(times)[0],
                           "refined_pct": rate_pct([r["refined"] for r in plans]), "plans": len(plans)}
    if method in SYMBOLIC_LEVEL:
        level1 = [r["level1_time_s"] for r in rows if r.get("level1_time_s") is not None]
        out.update({"level1_pct": rate_pct([r.get("level") == 1 for r in rows]),
                    "level1_time_median_s": median(level1), "level1_time_mean_s": mean_std(level1)[0]})
    return out


def scaling_numbers(rows: Sequence[dict]) -> dict[str, Any]:
    """Per method and n (methods seen at two or more counts): `cell`, the growth per added block of the
    mean and median planning time, and the Dynamics Model's effect error per n."""
    ns = sorted({r["n"] for r in rows})
    methods = list(dict.fromkeys(r["method"] for r in rows))
    table: dict[str, dict[int, dict]] = {}
    for m in methods:
        by_n = {n: [r for r in rows if r["method"] == m and r["n"] == n] for n in ns}
        by_n = {n: rs for n, rs in by_n.items() if rs}
        if len(by_n) >= 2:
            table[m] = {n: cell(rs, m) for n, rs in by_n.items()}
    growth: dict[str, dict[str, Any]] = {}
    for m, cells in table.items():
        have = sorted(cells)
        g: dict[str, Any] = {"steps": {}}
        for a, b in zip(have, have[1:]):
            g["steps"][f"{a}->{b}"] = {k: _growth(cells[a][f"time_{k}_s"], cells[b][f"time_{k}_s"], b - a)
                                       for k in ("mean", "median")}
        lo, hi = have[0], have[-1]
        g["overall"] = {"from": lo, "to": hi, **{k: _growth(cells[lo][f"time_{k}_s"], cells[hi][f"time_{k}_s"], hi - lo)
                                                 for k in ("mean", "median")}}
        growth[m] = g
    effect: dict[int, dict[str, Any]] = {}
    for n in ns:
        errors = [e for r in rows if r["n"] == n and r["method"] in DEFAULT_DYNAMICS
                  for e in (r.get("effect_error_m") or []) if e is not None]
        if errors:
            effect[n] = {"actions": len(errors), "mean_m": mean_std(errors)[0], "median_m": median(errors)}
    return {"ns": ns, "methods": table, "growth": growth, "effect_error": effect}


def scaling_lines(numbers: dict[str, Any], figure: str | None) -> list[str]:
    """The section's Markdown from `scaling_numbers`."""
    lines = ["Per method and number of blocks n: success (%), planning time (ms, median / mean), the share of "
             "problems whose plan came from Level 1 and Level 1's time (ms, median / mean, symbolic methods), and "
             "refined (%): returned plans that refined completely (IK, motions, grasps).", "",
             "| method | n | problems | success (%) | planning median / mean (ms) | Level 1 (%) | "
             "Level-1 time median / mean (ms) | refined (%) |", "|---|---|---|---|---|---|---|---|"]
    for m, cells in numbers["methods"].items():
        for n, c in sorted(cells.items()):
            level1 = (fmt_pct(c.get("level1_pct")), f"{fmt_ms(c.get('level1_time_median_s'))} / "
                      f"{fmt_ms(c.get('level1_time_mean_s'))}") if "level1_pct" in c else ("—", "—")
            lines.append(f"| `{m}` | {n} | {c['problems']} | {fmt_pct(c['success_pct'])} | "
                         f"{fmt_ms(c['time_median_s'])} / {fmt_ms(c['time_mean_s'])} | {level1[0]} | {level1[1]} | "
                         f"{fmt_pct(c['refined_pct'])} |")
    lines += ["", "Growth of planning time per added block, t(n + 1) / t(n), mean and median; 'overall' is the "
              "geometric mean per block over the whole range.", "",
              "| method | step | mean | median |", "|---|---|---|---|"]
    for m, g in numbers["growth"].items():
        for step, f in g["steps"].items():
            lines.append(f"| `{m}` | {step} | {fmt_factor(f['mean'])} | {fmt_factor(f['median'])} |")
        o = g["overall"]
        lines.append(f"| `{m}` | overall {o['from']}->{o['to']} | {fmt_factor(o['mean'])} | "
                     f"{fmt_factor(o['median'])} |")
    if numbers["effect_error"]:
        lines += ["", "The Dynamics Model's effect error on the executed actions of "
                  + ", ".join(f"`{m}`" for m in DEFAULT_DYNAMICS) + " (position error of its one-step prediction "
                  "from the state before each action, mean over objects, cm):", "",
                  "| n | actions | mean (cm) | median (cm) |", "|---|---|---|---|"]
        for n, e in sorted(numbers["effect_error"].items()):
            lines.append(f"| {n} | {e['actions']} | {e['mean_m'] * 100:.2f} | {e['median_m'] * 100:.2f} |")
    if figure:
        lines += ["", f"![success and planning time against n]({figure})"]
    return lines + [""]


__all__ = ["DEFAULT_DYNAMICS", "SYMBOLIC_LEVEL", "cell", "scaling_lines", "scaling_numbers"]
