"""What is in an interaction dataset: counts, why actions changed nothing, effect sizes, outcomes.

Outcome classes of a sample, decided from X, X' and the stored status alone (orientation is not
in X, so they are read off positions; all blocks are 5 cm tall):

- failures (``ik_failure``, ``motion_failure``, ``nothing_grasped``): nothing was executed.
- ``unchanged``: executed, but no object moved more than MOVE_TOL (1 cm), e.g. a block put
  back where it was.
- ``toppled``: an object that moved more than 1 cm is not *resting flat* in X': its height is
  not that of a flat stack level (z = 2.5 cm + k 5 cm, within 1 cm), or it is above the table
  with no object one level below within reach (a bar standing on end, a leaning block).
- ``stacked``: the grasped object rests flat on another object (level k >= 1) in X'.
- ``moved``: everything else that moved (placed on the table, shifted, fell off its target).

A block that rolls onto another face of the same height (a cube, or a bar about its long axis)
looks unchanged in X and is not counted as toppled.
"""
from __future__ import annotations

import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tamp.errors import UserError
from tamp.planning.vocabulary import BLOCK_SIZES, LARGE, SMALL
from tamp.records import atomic_write
from tamp.sim.world_types import STATUSES, StepStatus

MOVE_TOL = 0.01  # metres: an object moved if its centre moved more than this
LEVEL_TOL = 0.01  # metres: height tolerance of a flat stack level
HEIGHT = 0.05  # metres: every block is 5 cm tall
# Rotation-invariant reach of a footprint: half its diagonal (metres).
REACH = {t: float(np.hypot(*BLOCK_SIZES[t][:2]) / 2) for t in (SMALL, LARGE)}
CLASSES = ("moved", "stacked", "toppled", "unchanged")
SAMPLE_OUTCOMES = CLASSES + tuple(s for s in STATUSES if s != StepStatus.OK)  # of one transition


def resting_flat(X: np.ndarray, mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per object of X (..., n, 5): whether it rests flat on the table or a stack, and its level."""
    mask = np.ones(X.shape[:-1], bool) if mask is None else mask
    z = X[..., 2]
    level = np.rint((z - HEIGHT / 2) / HEIGHT).astype(int)
    on_level = (np.abs(z - HEIGHT / 2 - level * HEIGHT) < LEVEL_TOL) & (level >= 0) & mask
    reach = np.where(X[..., 4] == 1, REACH[LARGE], REACH[SMALL])
    distance = np.linalg.norm(X[..., :, None, :2] - X[..., None, :, :2], axis=-1)
    near = distance < reach[..., :, None] + reach[..., None, :]
    below = on_level[..., None, :] & (level[..., None, :] == level[..., :, None] - 1)  # [i, j]: j one level under i
    supported = (level == 0) | np.any(below & near, axis=-1)
    return on_level & supported, level


def classify_batch(X: np.ndarray, X_next: np.ndarray, mask: np.ndarray, grasped: np.ndarray,
                   status: np.ndarray) -> np.ndarray:
    """Outcome class names (S,) of padded transitions X, X' (S, n_max, 5); status as names."""
    moved = (np.linalg.norm(X_next[..., :3] - X[..., :3], axis=-1) > MOVE_TOL) & mask
    flat, level = resting_flat(X_next, mask)
    g = np.maximum(grasped, 0)[:, None]
    grasped_stacked = (grasped >= 0) & np.take_along_axis(moved & (level >= 1), g, axis=1)[:, 0]
    out = np.where(grasped_stacked, "stacked", "moved").astype(object)
    out[np.any(moved & ~flat, axis=1)] = "toppled"
    out[~moved.any(axis=1)] = "unchanged"
    failed = status != "ok"
    out[failed] = status[failed]
    return out


def classify(X: np.ndarray, X_next: np.ndarray, grasped: int, status: str) -> str:
    """Outcome class of one transition (X, X' of shape (n, 5)); see the module docstring."""
    return str(classify_batch(X[None], X_next[None], np.ones((1, len(X)), bool), np.array([grasped]),
                              np.array([status], object))[0])


@dataclass
class DatasetStats:
    directory: Path
    meta: dict
    n: np.ndarray  # (S,) object counts
    outcome: np.ndarray  # (S,) outcome names (SAMPLE_OUTCOMES)
    displacement: np.ndarray  # (S,) metres: how far the grasped object moved (NaN if none)
    others_moved: np.ndarray  # (S,) bool: an object other than the grasped one moved > 1 cm
    skipped: list[str] = field(default_factory=list)  # "name: reason" of corrupt shards
    missing: list[str] = field(default_factory=list)  # shards the meta promises but are absent
    png: Path | None = None

    def table(self) -> str:
        """Markdown tables: per n, why nothing changed, effect magnitudes, outcome classes."""
        S = len(self.n)
        lines = [f"# {self.directory}: {S} samples"]
        if self.missing:
            lines.append(f"incomplete: {len(self.missing)} shards missing ({', '.join(self.missing[:5])}"
                         + (", ..." if len(self.missing) > 5 else "") + ")")
        for s in self.skipped:
            lines.append(f"skipped corrupt shard {s}")
        nothing = np.isin(self.outcome, ("unchanged",) + tuple(s for s in STATUSES if s != "ok"))

        lines += ["", "| n | samples | changed nothing | moved | stacked | toppled |", "|---|---|---|---|---|---|"]
        def frac(mask: np.ndarray, sel: np.ndarray) -> str:
            return f"{mask[sel].mean():.1%}"

        for n in np.unique(self.n):
            sel = self.n == n
            lines.append(f"| {n} | {sel.sum()} | {frac(nothing, sel)} | {frac(self.outcome == 'moved', sel)} | "
                         f"{frac(self.outcome == 'stacked', sel)} | {frac(self.outcome == 'toppled', sel)} |")

        lines += ["", f"changed nothing: {nothing.sum()} of {S} ({nothing.mean():.1%}), why:", "",
                  "| why | samples | fraction of all |", "|---|---|---|"]
        why = {"ik_failure": "no IK solution (ik_failure)", "motion_failure": "motion blocked (motion_failure)",
               "nothing_grasped": "jaws closed on nothing (nothing_grasped)",
               "unchanged": "executed, nothing moved > 1 cm (ok)"}
        for key, text in why.items():
            count = int((self.outcome == key).sum())
            lines.append(f"| {text} | {count} | {count / S:.1%} |")

        lines += ["", "effect of executed actions (displacement of the grasped object, cm):", "",
                  "| outcome | samples | median | p90 | max | others moved |", "|---|---|---|---|---|---|"]
        for cls in CLASSES:
            sel = self.outcome == cls
            d = self.displacement[sel & np.isfinite(self.displacement)] * 100
            if not sel.any():
                lines.append(f"| {cls} | 0 | - | - | - | - |")
                continue
            stats = (f"{np.median(d):.1f} | {np.percentile(d, 90):.1f} | {d.max():.1f}" if d.size else "- | - | -")
            lines.append(f"| {cls} | {sel.sum()} | {stats} | {self.others_moved[sel].mean():.0%} |")
        executed = np.isin(self.outcome, CLASSES) & np.isfinite(self.displacement)
        if executed.any():
            d = self.displacement[executed] * 100
            lines.append(f"| all executed | {executed.sum()} | {np.median(d):.1f} | "
                         f"{np.percentile(d, 90):.1f} | {d.max():.1f} | {self.others_moved[executed].mean():.0%} |")
        return "\n".join(lines)

    def write_png(self, path: Path) -> Path:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4))
        executed = np.isin(self.outcome, CLASSES) & np.isfinite(self.displacement)
        d = self.displacement[executed] * 100
        bins = np.linspace(0, max(float(d.max()) if d.size else 1.0, 1.0), 30)
        ax1.hist([d[self.outcome[executed] == c] for c in CLASSES], bins=bins, stacked=True, label=CLASSES)
        ax1.set_xlabel("displacement of the grasped object (cm)")
        ax1.set_ylabel("samples")
        ax1.set_title("executed actions")
        ax1.legend()
        ns = np.unique(self.n)
        bottom = np.zeros(len(ns))
        for outcome in SAMPLE_OUTCOMES:
            frac = np.array([(self.outcome[self.n == n] == outcome).mean() for n in ns])
            ax2.bar([str(n) for n in ns], frac, bottom=bottom, label=outcome)
            bottom += frac
        ax2.set_xlabel("objects n")
        ax2.set_ylabel("fraction of samples")
        ax2.set_title("outcomes per object count")
        ax2.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0))
        fig.suptitle(f"{self.directory.name}: {len(self.n)} samples")
        fig.tight_layout()
        try:
            atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", dpi=100))
        finally:
            plt.close(fig)
        return path


def dataset_stats(directory: str | Path, png: str | Path | None = None) -> DatasetStats:
    """Read every valid shard of `directory` (corrupt ones are reported and skipped) and summarise.

    Writes the PNG histogram to `png` (default DIR/stats.png).
    """
    from learned.dataset import ShardError, read_meta, read_shard, shard_paths

    directory = Path(directory)
    if not directory.is_dir():
        raise UserError(f"no dataset directory {directory}")
    meta = read_meta(directory)
    codes = {int(v): k for k, v in meta["status_codes"].items()}
    parts, skipped = [], []
    for path in shard_paths(directory):
        try:
            parts.append(read_shard(path, int(meta["n_max"]), sorted(codes)))
        except ShardError as error:
            reason = str(error).split(": ", 1)[-1]
            print(f"warning: skipping corrupt shard {path.name}: {reason}", file=sys.stderr)
            skipped.append(f"{path.name}: {reason}")
    if not parts:
        raise UserError(f"{directory}: no readable shards")
    present = {p.name for p in shard_paths(directory)}
    expected = meta.get("collection", {}).get("shards")
    missing = [f"shard-{j:06d}.npz" for j in range(expected or 0) if f"shard-{j:06d}.npz" not in present]

    n = np.concatenate([p.n for p in parts])
    outcome, displacement, others = [], [], []
    for part in parts:
        X, Xn = part.X.astype(float), part.X_next.astype(float)
        status = np.array([codes[int(c)] for c in part.status], object)
        outcome.append(classify_batch(X, Xn, part.mask, part.grasped, status))
        dist = np.where(part.mask, np.linalg.norm(Xn[..., :3] - X[..., :3], axis=-1), 0.0)
        executed = (status == "ok") & (part.grasped >= 0)
        g = np.maximum(part.grasped, 0)[:, None]
        displacement.append(np.where(executed, np.take_along_axis(dist, g, axis=1)[:, 0], np.nan))
        is_grasped = (np.arange(X.shape[1])[None] == part.grasped[:, None])
        others.append(np.any((dist > MOVE_TOL) & ~is_grasped, axis=1))
    stats = DatasetStats(directory, meta, n, np.concatenate(outcome).astype(str), np.concatenate(displacement),
                         np.concatenate(others), skipped, missing)
    stats.png = stats.write_png(Path(png) if png is not None else directory / "stats.png")
    return stats
