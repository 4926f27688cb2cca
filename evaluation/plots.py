"""The report's figures (PNG, matplotlib's Agg canvas; no pyplot, so no global state or display).

Each function takes numbers the report has already computed and writes one PNG atomically.
Success is in percent, times in seconds; None values are drawn as missing bars.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from tamp.records import atomic_write

from .stats import Confusion

COLORS = {"deterministic": "#7f7f7f", "probabilistic": "#ff7f0e", "cfs": "#1f77b4", "bilevel": "#2ca02c",
          "bilevel_replan": "#9467bd",
          "bilevel_alg1": "#8c564b", "symbolic_sigmoid": "#bcbd22", "cfs_gumbel": "#17becf"}


def _save(fig: Figure, path: Path) -> Path:
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight"))


def _values(xs: Sequence[float | None]) -> np.ndarray:
    return np.array([np.nan if x is None else x for x in xs], dtype=float)


def grouped_bars(path: Path, title: str, groups: Sequence[str], series: Mapping[str, Sequence[float | None]],
                 ylabel: str = "success (%)", errors: Mapping[str, Sequence[float | None]] | None = None,
                 colors: Mapping[str, str] | None = None, ylim: tuple[float, float] | None = (0, 100)) -> Path:
    """One group of bars per entry of `groups`, one bar per series (optional error bars)."""
    fig = Figure(figsize=(max(5.0, 1.2 * len(groups) * max(1, len(series)) / 2), 3.6))
    ax = fig.add_subplot()
    x = np.arange(len(groups))
    width = 0.8 / max(1, len(series))
    for i, (name, vals) in enumerate(series.items()):
        err = _values(errors[name]) if errors and name in errors else None
        ax.bar(x + (i - (len(series) - 1) / 2) * width, _values(vals), width, yerr=err, capsize=2,
               label=name, color=(colors or {}).get(name))
    ax.set_xticks(x, list(groups))
    ax.set_ylabel(ylabel)
    if ylim:
        ax.set_ylim(*ylim)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, ncols=min(4, max(1, len(series))), loc="upper center", bbox_to_anchor=(0.5, -0.1))
    ax.grid(axis="y", alpha=0.3)
    return _save(fig, path)


def success_by_nk(path: Path, ns: Sequence[int], ks: Sequence[int],
                  success: Mapping[str, Mapping[tuple[int, int], float | None]],
                  bilevel_levels: Mapping[tuple[int, int], tuple[float | None, float | None]] | None) -> Path:
    """The paper's Fig. 5: success per k, one panel per n; the bilevel bar split into Level 1 (hatched) and 2."""
    fig = Figure(figsize=(4.2 * len(ns), 3.6))
    axes = fig.subplots(1, len(ns), squeeze=False)[0]
    methods = list(success)
    width = 0.8 / max(1, len(methods))
    x = np.arange(len(ks))
    for ax, n in zip(axes, ns):
        for i, m in enumerate(methods):
            xs = x + (i - (len(methods) - 1) / 2) * width
            if m == "bilevel" and bilevel_levels is not None:
                l1 = _values([bilevel_levels.get((n, k), (None, None))[0] for k in ks])
                l2 = _values([bilevel_levels.get((n, k), (None, None))[1] for k in ks])
                ax.bar(xs, l1, width, color=COLORS["probabilistic"], hatch="//", edgecolor="white",
                       label="bilevel, Level 1")
                ax.bar(xs, l2, width, bottom=np.nan_to_num(l1), color=COLORS["cfs"], hatch="//",
                       edgecolor="white", label="bilevel, Level 2")
            else:
                ax.bar(xs, _values([success[m].get((n, k)) for k in ks]), width, label=m, color=COLORS.get(m))
        ax.set_xticks(x, [f"k={k}" for k in ks])
        ax.set_ylim(0, 100)
        ax.set_title(f"n = {n}", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("success (%)")
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, ncols=4, loc="upper center", bbox_to_anchor=(0.5, 0.0))
    return _save(fig, path)


def verifier_sweep(path: Path, taus_cm: Sequence[float], curves: Mapping[str, Mapping[str, Sequence[float | None]]],
                   chosen_cm: float) -> Path:
    """The paper's Fig. 6: accuracy and F1 of the verifier against tau_verify, one line per group."""
    fig = Figure(figsize=(9, 3.4))
    axes = fig.subplots(1, 2)
    for ax, metric in zip(axes, ("f1", "accuracy")):
        for group, values in curves.items():
            ax.plot(taus_cm, _values(values[metric]), marker="o", markersize=3, label=group)
        ax.axvline(chosen_cm, color="k", linestyle=":", linewidth=1)
        ax.set_xlabel("tau_verify (cm)")
        ax.set_ylabel("F1" if metric == "f1" else "accuracy")
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    return _save(fig, path)


def confusion_bars(path: Path, groups: Sequence[str], confusions: Sequence[Confusion], tau_cm: float) -> Path:
    """The paper's Fig. 7: TP / FP / TN / FN counts of the verifier per group, stacked."""
    fig = Figure(figsize=(max(4.0, 1.3 * len(groups)), 3.6))
    ax = fig.add_subplot()
    x = np.arange(len(groups))
    bottom = np.zeros(len(groups))
    for name, color in (("tp", "#2ca02c"), ("fp", "#d62728"), ("tn", "#1f77b4"), ("fn", "#ff7f0e")):
        vals = np.array([getattr(c, name) for c in confusions], dtype=float)
        ax.bar(x, vals, 0.6, bottom=bottom, label=name.upper(), color=color)
        bottom += vals
    ax.set_xticks(x, list(groups))
    ax.set_ylabel("plans")
    ax.set_title(f"verifier at tau_verify = {tau_cm:g} cm", fontsize=10)
    ax.legend(fontsize=8)
    return _save(fig, path)


def scaling_curves(path: Path, numbers: Mapping) -> Path:
    """Success (%) and planning time (s, log scale: median solid, mean dashed) against the number of
    blocks, one line per method (`evaluation.scaling.scaling_numbers`)."""
    fig = Figure(figsize=(9, 3.4), layout="constrained")
    ax_s, ax_t = fig.subplots(1, 2)
    for m, cells in numbers["methods"].items():
        ns = sorted(cells)
        color = COLORS.get(m)
        ax_s.plot(ns, _values([cells[n]["success_pct"] for n in ns]), marker="o", markersize=3, label=m, color=color)
        ax_t.plot(ns, _values([cells[n]["time_median_s"] for n in ns]), marker="o", markersize=3, label=m,
                  color=color)
        ax_t.plot(ns, _values([cells[n]["time_mean_s"] for n in ns]), linestyle="--", color=color or "k",
                  linewidth=1)
    ax_s.set_ylim(0, 100)
    ax_s.set_ylabel("success (%)")
    ax_t.set_yscale("log")
    ax_t.set_ylabel("planning time (s)\nmedian; mean dashed")
    for ax in (ax_s, ax_t):
        ax.set_xlabel("blocks n")
        ax.set_xticks(numbers["ns"])
        ax.grid(alpha=0.3)
    ax_s.legend(fontsize=7)
    return _save(fig, path)


def refinability_scatter(path: Path, table: Sequence[Mapping]) -> Path:
    """Per learned operator (`evaluation.refinability.operator_table`): the share of its executed steps
    whose symbols came out as expected against how often it was used (log scale), the marker's
    colour the share of its steps that refined."""
    rows = [t for t in table if t["as_expected_pct"] is not None]
    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.add_subplot()
    if rows:
        points = ax.scatter([t["uses"] for t in rows], [t["as_expected_pct"] for t in rows],
                            c=_values([t["refined_pct"] for t in rows]), cmap="viridis", vmin=0, vmax=100,
                            s=[10 + 4 * t["executed"] for t in rows], alpha=0.75, edgecolors="k", linewidths=0.3)
        fig.colorbar(points, ax=ax, label="refined (%)")
    ax.set_xscale("log")
    ax.set_ylim(-3, 103)
    ax.set_xlabel("steps that used the operator (log scale)")
    ax.set_ylabel("executed steps as expected (%)")
    ax.set_title("Learned operators: symbolic effect realised by motion (marker size: executed steps)", fontsize=9)
    ax.grid(alpha=0.3)
    return _save(fig, path)


__all__ = ["confusion_bars", "grouped_bars", "refinability_scatter", "scaling_curves", "success_by_nk",
           "verifier_sweep"]
