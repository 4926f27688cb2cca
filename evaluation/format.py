"""Cell formatting of the evaluation's Markdown tables, shared by the report and its sections
(`scaling`, `refinability`): a missing value is a dash, never 'None' or 'nan'."""
from __future__ import annotations

import math
from typing import Iterable, Sequence

from .paper import P_BELOW
from .stats import IDENTICAL

DASH = "—"


def fmt_pct(x: float | None) -> str:
    """A percentage with one decimal."""
    return DASH if x is None else f"{x:.1f}"


def fmt_s(x: float | None) -> str:
    """Seconds with three decimals."""
    return DASH if x is None else f"{x:.3f}"


def fmt_ms(x: float | None) -> str:
    """Seconds as whole milliseconds."""
    return DASH if x is None else f"{x * 1000:.0f}"


def fmt_cm(x: float | None) -> str:
    """Centimetres with two decimals."""
    return DASH if x is None else f"{x:.2f}"


def fmt_pm(pair: tuple[float | None, float | None], digits: int = 3) -> str:
    """'mean ± std'."""
    m, s = pair
    return DASH if m is None else f"{m:.{digits}f} ± {s:.{digits}f}"


def fmt_p(p: float | str | None) -> str:
    """'identical', '—' (fewer than two pairs), '< 0.0001', else four decimals."""
    if p is None:
        return DASH
    if p == IDENTICAL:
        return IDENTICAL
    assert not isinstance(p, str)  # IDENTICAL is paired_ttest's only text
    return "< 0.0001" if p < P_BELOW else f"{p:.4f}"


def fmt_ratio(x: float | None, digits: int = 2) -> str:
    return DASH if x is None else f"{x:.{digits}f}"


def fmt_factor(x: float | None) -> str:
    """A growth factor, '2.50x'."""
    return DASH if x is None or not math.isfinite(x) else f"{x:.2f}x"


def md_table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> list[str]:
    """A Markdown table's lines, with a blank line after it."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return lines + [""]


__all__ = ["DASH", "fmt_cm", "fmt_factor", "fmt_ms", "fmt_p", "fmt_pct", "fmt_pm", "fmt_ratio", "fmt_s", "md_table"]
