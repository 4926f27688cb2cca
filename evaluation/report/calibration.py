"""Report section 16: the Dynamics Model where the planner acts. Every executed step's miss (the block
farthest from its predicted place) against 2 and 5 cm, and against the model's own 95 % bound
(`tamp.planning.calibration`): a calibrated model's miss exceeds its bound in about 5 % of steps, for
every number of blocks and action class; and by the scene each step starts from (blocks on the table, a stack,
a leaning block) where the rows record it."""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import Any

from tamp.planning.calibration import SCENES

from ..format import fmt_cm, fmt_pct, md_table
from ..stats import median
from .results import Results, Section, _skipped

MISS_THRESHOLDS_M = (0.02, 0.05)


def step_figures(predictions: list[dict]) -> dict[str, Any]:
    """Steps, shares (%) missing by 2 and 5 cm or more and beyond their bound, the median miss and bound (m)."""
    steps = len(predictions)
    if not steps:
        return {"steps": 0}
    misses = [p["miss_m"] for p in predictions]
    out: dict[str, Any] = {"steps": steps}
    for t in MISS_THRESHOLDS_M:
        out[f"miss_ge_{round(100 * t)}cm_pct"] = 100.0 * sum(m >= t for m in misses) / steps
    bounded = [p for p in predictions if p.get("bound_m")]
    out["exceeded_pct"] = 100.0 * sum(p["miss_m"] > p["bound_m"] for p in bounded) / len(bounded) if bounded else None
    out["median_miss_m"], out["median_bound_m"] = median(misses), median([p["bound_m"] for p in bounded])
    return out


def _predictions(rows: list[dict]) -> list[dict]:
    return [p for r in rows for p in (r.get("predictions") or [])]


def section_calibration(res: Results, figures: Path) -> Section:
    title = "16. The Dynamics Model where the planner acts: misses and calibration"
    if not any(r.get("predictions") for r in res.rows):
        return _skipped("calibration", title, "No row records the Dynamics Model's predictions of its executed steps "
                        "(rows written before `predictions`, or no action executed).")
    lines = ["Every executed step, predicted from the state the world was in before it: the miss is the distance "
             "of the block farthest from its predicted place; the bound is the model's own 95 % bound of that "
             "distance (an ensemble's members and their spread; a single network without a spread head gives none). "
             "A calibrated model's miss exceeds its bound in about 5 % of steps.", ""]
    data: dict[str, Any] = {"methods": {}, "classes": {}, "scenes": {}}
    rows_out = []
    for m in res.methods:
        rs = res.select(m)
        for label, keep in [(str(n), n) for n in res.ns] + [("all", None)]:
            f = step_figures(_predictions([r for r in rs if keep is None or r["n"] == keep]))
            data["methods"].setdefault(m, {})[label] = f
            if f["steps"]:
                rows_out.append(_row(f"`{m}`", label, f))
    lines += md_table(["method", "n", "steps", ">= 2 cm (%)", ">= 5 cm (%)", "beyond the 95 % bound (%)",
                       "median miss (cm)", "median bound (cm)"], rows_out)
    by_class: dict[str, list[dict]] = defaultdict(list)
    by_scene: dict[str | None, list[dict]] = defaultdict(list)  # None: rows made before the split
    for p in _predictions(res.rows):
        by_class[p["class"]].append(p)
        by_scene[p.get("scene")].append(p)
    class_rows = []
    for name in sorted(by_class, key=lambda c: -len(by_class[c])):
        f = step_figures(by_class[name])
        data["classes"][name] = f
        class_rows.append(_row(name, "all", f))
    lines += ["", "By action class, every method's steps together:", ""]
    lines += md_table(["action", "n", "steps", ">= 2 cm (%)", ">= 5 cm (%)", "beyond the 95 % bound (%)",
                       "median miss (cm)", "median bound (cm)"], class_rows)
    scene_rows = []
    for name in SCENES:
        if by_scene.get(name):
            data["scenes"][name] = f = step_figures(by_scene[name])
            scene_rows.append(_row(name, "all", f))
    if scene_rows:
        lines += ["", "By the scene the step starts from (a leaning block: a centre between the heights an upright "
                  "block rests at; X holds no tilt), every method's steps together:", ""]
        lines += md_table(["the step starts from", "n", "steps", ">= 2 cm (%)", ">= 5 cm (%)",
                           "beyond the 95 % bound (%)", "median miss (cm)", "median bound (cm)"], scene_rows)
    return Section("calibration", title, lines, data)


def _row(name: str, n: str, f: dict[str, Any]) -> list[str]:
    return [name, n, str(f["steps"]), fmt_pct(f["miss_ge_2cm_pct"]), fmt_pct(f["miss_ge_5cm_pct"]),
            fmt_pct(f["exceeded_pct"]), fmt_cm(_cm(f["median_miss_m"])), fmt_cm(_cm(f["median_bound_m"]))]


def _cm(metres: float | None) -> float | None:
    return None if metres is None else 100 * metres
