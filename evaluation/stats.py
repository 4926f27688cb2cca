"""The statistics of the report: rates, mean +- std, paired t-tests, the verifier's confusion matrix.

Pure numpy/scipy on plain numbers; `report.py` decides which rows go in. Percentages are 0..100.
"""
from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np
from scipy import stats as _scipy

IDENTICAL = "identical"  # the paired samples agree on every problem: no test to make


def rate_pct(flags: Sequence[bool]) -> float | None:
    """Share of true flags in percent; None for no flags."""
    return 100.0 * float(np.mean(np.asarray(flags, dtype=float))) if len(flags) else None


def mean_std(values: Sequence[float]) -> tuple[float | None, float | None]:
    """Mean and sample standard deviation (ddof 1; 0 for a single value); (None, None) if empty."""
    v = np.asarray(values, dtype=float)
    if v.size == 0:
        return None, None
    return float(v.mean()), float(v.std(ddof=1)) if v.size > 1 else 0.0


def median(values: Sequence[float]) -> float | None:
    return float(np.median(values)) if len(values) else None


def percentile(values: Sequence[float], q: float) -> float | None:
    """The q-th percentile (0..100, linear interpolation); None if empty."""
    return float(np.percentile(values, q)) if len(values) else None


def paired_ttest(a: Sequence[float], b: Sequence[float]) -> float | str | None:
    """p-value of `scipy.stats.ttest_rel(a, b)` over paired samples (per-problem 0/1 success or times).

    IDENTICAL when every difference is zero (the test is undefined, nan in scipy); None with fewer
    than two pairs. Constant non-zero differences give scipy's p = 0.
    """
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape:
        raise ValueError(f"paired samples differ in length: {x.size} and {y.size}")
    if x.size < 2:
        return None
    if np.all(x == y):
        return IDENTICAL
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # scipy warns on (near-)constant differences
        return float(_scipy.ttest_rel(x, y).pvalue)


@dataclass(frozen=True)
class Confusion:
    """The verifier as a classifier of plans: positive = verified (predicted error < tau).

    TP verified and succeeded, FP verified and failed, TN unverified and failed, FN unverified and
    succeeded (the paper's Fig. 7).
    """

    tp: int
    fp: int
    tn: int
    fn: int

    @property
    def total(self) -> int:
        return self.tp + self.fp + self.tn + self.fn

    @property
    def verified_success_pct(self) -> float | None:
        """Success rate of the verified plans (precision), percent."""
        return 100.0 * self.tp / (self.tp + self.fp) if self.tp + self.fp else None

    @property
    def unverified_failure_pct(self) -> float | None:
        """Failure rate of the unverified plans, percent."""
        return 100.0 * self.tn / (self.tn + self.fn) if self.tn + self.fn else None

    @property
    def accuracy(self) -> float | None:
        return (self.tp + self.tn) / self.total if self.total else None

    @property
    def f1(self) -> float | None:
        d = 2 * self.tp + self.fp + self.fn
        return 2 * self.tp / d if d else None

    def to_dict(self) -> dict:
        return {**asdict(self), "plans": self.total, "verified_success_pct": self.verified_success_pct,
                "unverified_failure_pct": self.unverified_failure_pct, "accuracy": self.accuracy,
                "f1": self.f1}


def confusion(predicted_error_m: Sequence[float], success: Sequence[bool], tau_m: float) -> Confusion:
    """Confusion matrix of `predicted error < tau_m` (verified, as `tamp.planning.verify`) against execution success."""
    e = np.asarray(predicted_error_m, dtype=float)
    s = np.asarray(success, dtype=bool)
    v = e < tau_m
    return Confusion(tp=int(np.sum(v & s)), fp=int(np.sum(v & ~s)), tn=int(np.sum(~v & ~s)),
                     fn=int(np.sum(~v & s)))


__all__ = ["IDENTICAL", "Confusion", "confusion", "mean_std", "median", "paired_ttest", "percentile",
           "rate_pct"]
