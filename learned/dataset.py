"""Transition datasets (X, a, X') on disk: a directory of ``.npz`` shards plus ``meta.json``.

Layout (format ``tamp-transitions/1``)::

    DIR/meta.json            {"format", "n_max", "world_config", "seed", "versions",
                              "status_codes": {name: int}, "shard_size", ...extra}
    DIR/shard-000000.npz     S samples each:
        X       float32 (S, n_max, 5)  state before, zero-padded beyond n
        X_next  float32 (S, n_max, 5)  state after
        mask    bool    (S, n_max)     True for real objects (first n rows)
        action  int64   (S, 4)         (pick, grasp_offset, place, release_offset)
        n       int64   (S,)           object count
        grasped int64   (S,)           index of the object actually carried, -1 if none
        status  int64   (S,)           outcome code, a value of meta["status_codes"]

Shards are written atomically (temp file in the same directory, fsync, ``os.replace``), so a
crash leaves either a whole shard or none; a writer reopened on the same directory resumes
after the last shard. The reader validates every shard (zip CRC, keys, dtypes, shapes, padding,
index ranges, status codes) and raises ``ShardError`` naming the file, or, with
``skip_corrupt=True``, skips it with a warning and lists it in ``Transitions.skipped``.
"""
from __future__ import annotations

import json
import os
import re
import warnings
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from guarded import Schema, output, read_json

from .effects import STATE_DIM, as_action_array

FORMAT = "tamp-transitions/1"
META_NAME = "meta.json"
SHARD_RE = re.compile(r"^shard-(\d{6})\.npz$")
KEYS = ("X", "X_next", "mask", "action", "n", "grasped", "status")
_DTYPES = {"X": np.float32, "X_next": np.float32, "mask": np.bool_, "action": np.int64,
           "n": np.int64, "grasped": np.int64, "status": np.int64}


class ShardError(ValueError):
    """A shard that cannot be read or fails validation; ``path`` names the file."""

    def __init__(self, path: Path | str, reason: str):
        self.path = Path(path)
        super().__init__(f"{self.path}: {reason}")


@dataclass
class Transitions:
    """In-memory transitions, padded to ``n_max`` objects (arrays as in the shard layout)."""
    X: np.ndarray
    X_next: np.ndarray
    mask: np.ndarray
    action: np.ndarray
    n: np.ndarray
    grasped: np.ndarray
    status: np.ndarray
    meta: dict[str, Any] = field(default_factory=dict)
    skipped: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.n.shape[0])

    @property
    def n_max(self) -> int:
        return int(self.X.shape[1])

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in KEYS}

    def subset(self, idx: np.ndarray) -> "Transitions":
        return Transitions(**{k: v[idx] for k, v in self.arrays().items()}, meta=self.meta)

    def tensors(self) -> dict[str, torch.Tensor]:
        """All arrays as torch tensors (shared memory with numpy where possible)."""
        return {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in self.arrays().items()}

    def padded(self, n_max: int) -> "Transitions":
        """The same transitions padded with absent objects to ``n_max`` (at least this one's)."""
        if n_max < self.n_max:
            raise ValueError(f"cannot pad transitions of {self.n_max} objects down to {n_max}")
        extra = ((0, 0), (0, n_max - self.n_max))
        return Transitions(X=np.pad(self.X, extra + ((0, 0),)), X_next=np.pad(self.X_next, extra + ((0, 0),)),
                           mask=np.pad(self.mask, extra), action=self.action, n=self.n, grasped=self.grasped,
                           status=self.status, meta={**self.meta, "n_max": n_max}, skipped=list(self.skipped))

    @staticmethod
    def concatenate(parts: Sequence["Transitions"], meta: dict | None = None) -> "Transitions":
        if not parts:
            raise ValueError("no transitions to concatenate")
        arrays: dict[str, Any] = {k: np.concatenate([getattr(p, k) for p in parts]) for k in KEYS}
        return Transitions(**arrays, meta=dict(meta or parts[0].meta))


class TransitionDataset(torch.utils.data.Dataset):
    """torch Dataset over transitions; items are dicts of tensors with a padding ``mask``."""

    def __init__(self, source: "str | Path | Transitions", skip_corrupt: bool = False):
        self.data = source if isinstance(source, Transitions) else load_transitions(
            source, skip_corrupt=skip_corrupt)
        self._t = self.data.tensors()

    def __len__(self) -> int:
        return len(self.data)

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        return {k: v[i] for k, v in self._t.items()}

    def tensors(self) -> dict[str, torch.Tensor]:
        return self._t


# ----------------------------------------------------------------------------- validation

def validate_arrays(a: Mapping[str, np.ndarray], n_max: int | None = None,
                    status_values: Sequence[int] | None = None) -> str | None:
    """Reason why the shard arrays are invalid, or None if they are consistent."""
    missing = [k for k in KEYS if k not in a]
    if missing:
        return f"missing arrays {missing}"
    for k, dt in _DTYPES.items():
        if a[k].dtype != dt:
            return f"array {k} has dtype {a[k].dtype}, expected {np.dtype(dt)}"
    X, Xn, mask, act, n = a["X"], a["X_next"], a["mask"], a["action"], a["n"]
    if X.ndim != 3 or X.shape[2] != STATE_DIM:
        return f"X has shape {X.shape}, expected (S, n_max, {STATE_DIM})"
    S, N = X.shape[:2]
    if n_max is not None and N != n_max:
        return f"n_max {N} differs from meta.json n_max {n_max}"
    shapes = {"X_next": (S, N, STATE_DIM), "mask": (S, N), "action": (S, 4), "n": (S,),
              "grasped": (S,), "status": (S,)}
    for k, shp in shapes.items():
        if a[k].shape != shp:
            return f"{k} has shape {a[k].shape}, expected {shp}"
    if S == 0:
        return "empty shard"
    if np.any(n < 1) or np.any(n > N):
        return f"object counts outside [1, {N}]"
    if not np.array_equal(mask, np.arange(N)[None] < n[:, None]):
        return "mask inconsistent with n"
    if not (np.isfinite(X).all() and np.isfinite(Xn).all()):
        return "non-finite values in X or X_next"
    if np.any(X[~mask] != 0) or np.any(Xn[~mask] != 0):
        return "padded rows are not zero"
    types = X[mask][:, 3:]
    if not (np.isin(types, (0.0, 1.0)).all() and np.all(types.sum(1) == 1)):
        return "object types are not one-hot"
    if not np.array_equal(types, Xn[mask][:, 3:]):
        return "object types differ between X and X_next"
    if (np.any(act[:, [0, 2]] < 0) or np.any(act[:, 0] >= n) or np.any(act[:, 2] >= n)
            or np.any(np.abs(act[:, [1, 3]]) > 1)):
        return "action indices or offsets out of range"
    if np.any(a["grasped"] < -1) or np.any(a["grasped"] >= n):
        return "grasped index out of range"
    if status_values is not None and not np.isin(a["status"], list(status_values)).all():
        bad = sorted(set(a["status"].tolist()) - set(status_values))
        return f"status codes {bad} not in meta.json status_codes"
    return None


def pack_samples(samples: Sequence[Mapping[str, Any]], n_max: int) -> dict[str, np.ndarray]:
    """Pad a list of per-sample dicts (X (n,5), action, X_next (n,5), grasped, status)."""
    S = len(samples)
    out = {"X": np.zeros((S, n_max, STATE_DIM), np.float32),
           "X_next": np.zeros((S, n_max, STATE_DIM), np.float32),
           "mask": np.zeros((S, n_max), bool), "action": np.zeros((S, 4), np.int64),
           "n": np.zeros(S, np.int64), "grasped": np.zeros(S, np.int64),
           "status": np.zeros(S, np.int64)}
    for s, smp in enumerate(samples):
        X = np.asarray(smp["X"], np.float32)
        Xn = np.asarray(smp["X_next"], np.float32)
        n = X.shape[0]
        if X.shape != (n, STATE_DIM) or Xn.shape != X.shape or not 1 <= n <= n_max:
            raise ValueError(f"sample {s}: X {X.shape} / X_next {Xn.shape} invalid for n_max={n_max}")
        out["X"][s, :n] = X
        out["X_next"][s, :n] = Xn
        out["mask"][s, :n] = True
        out["action"][s] = as_action_array(smp["action"])[0]
        out["n"][s] = n
        out["grasped"][s] = int(smp["grasped"])
        out["status"][s] = int(smp["status"])
    return out


# ----------------------------------------------------------------------------- writing

def atomic_write_bytes(path: Path, write) -> None:
    """Call ``write(fileobj)`` on a temp file next to ``path``, fsync, then rename over ``path`` (``guarded.output``:
    a full disk or read-only folder is one OutputError naming ``path``, nothing left behind)."""
    def to_file(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())

    output.atomic_write(path, to_file)


def write_meta(directory: Path, meta: Mapping[str, Any]) -> None:
    data = (json.dumps(meta, indent=2, sort_keys=True) + "\n").encode()
    atomic_write_bytes(Path(directory) / META_NAME, lambda f: f.write(data))


def write_shard(path: Path, arrays: Mapping[str, np.ndarray], n_max: int | None = None,
                status_values: Sequence[int] | None = None) -> None:
    """Validate and atomically write one shard file."""
    packed: dict[str, Any] = {k: np.ascontiguousarray(arrays[k], dtype=_DTYPES[k]) for k in KEYS}
    reason = validate_arrays(packed, n_max, status_values)
    if reason:
        raise ValueError(f"refusing to write invalid shard {path}: {reason}")
    atomic_write_bytes(Path(path), lambda f: np.savez(f, **packed))


def shard_paths(directory: str | Path) -> list[Path]:
    """Shard files of a dataset directory in index order."""
    return sorted(p for p in Path(directory).iterdir() if SHARD_RE.match(p.name))


class DatasetWriter:
    """Append transitions to a dataset directory, one atomic shard per ``shard_size`` samples.

    Reopening an existing directory resumes it (numbering continues after the last shard); the
    meta fields that define the data (format, n_max, world_config, seed, status_codes) must match.
    Use as a context manager, or call ``close()``, so the last partial shard is written.
    """

    def __init__(self, directory: str | Path, *, n_max: int, world_config: Mapping[str, Any],
                 seed: int, status_codes: Mapping[str, int], versions: Mapping[str, str] | None = None,
                 shard_size: int = 1000, extra_meta: Mapping[str, Any] | None = None):
        self.directory = Path(directory)
        output.make_dirs(self.directory)
        self.n_max, self.shard_size = int(n_max), int(shard_size)
        codes = {str(k): int(v) for k, v in status_codes.items()}
        if len(set(codes.values())) != len(codes):
            raise ValueError(f"status codes must be distinct: {codes}")
        self.status_values = sorted(codes.values())
        meta = {"format": FORMAT, "n_max": self.n_max, "world_config": dict(world_config),
                "seed": int(seed), "status_codes": codes, "shard_size": self.shard_size,
                "versions": {"numpy": np.__version__, **dict(versions or {})},
                **dict(extra_meta or {})}
        meta = json.loads(json.dumps(meta))  # JSON-able, normalised (tuples -> lists)
        meta_path = self.directory / META_NAME
        if meta_path.exists():
            old = read_meta(self.directory)
            for k in ("format", "n_max", "world_config", "seed", "status_codes"):
                if old.get(k) != meta[k]:
                    raise ValueError(f"{meta_path}: existing {k}={old.get(k)!r} differs from "
                                     f"{meta[k]!r}; use a new directory")
            self.meta = old
        else:
            write_meta(self.directory, meta)
            self.meta = meta
        for stale in self.directory.glob(".shard-*.tmp-*"):
            stale.unlink()
        existing = shard_paths(self.directory)
        last = SHARD_RE.match(existing[-1].name) if existing else None
        self._next = int(last.group(1)) + 1 if last is not None else 0
        self._stored = sum(len(read_shard(p, self.n_max, self.status_values)) for p in existing)
        self._buffer: list[dict[str, Any]] = []

    @property
    def num_samples(self) -> int:
        """Samples on disk plus buffered ones."""
        return self._stored + len(self._buffer)

    def add(self, X: np.ndarray, action: Sequence[int], X_next: np.ndarray, grasped: int,
            status: int) -> None:
        """Validate and buffer one transition (X, X_next: (n, 5), metres and one-hot type);
        writes a shard when ``shard_size`` samples are buffered. Raises ValueError if invalid."""
        sample = pack_samples([{"X": X, "action": action, "X_next": X_next, "grasped": grasped,
                                "status": status}], self.n_max)
        reason = validate_arrays(sample, self.n_max, self.status_values)
        if reason:
            raise ValueError(f"invalid transition (sample {self.num_samples}): {reason}")
        self._buffer.append(sample)
        if len(self._buffer) >= self.shard_size:
            self.flush()

    def flush(self) -> Path | None:
        """Write buffered samples as the next shard; returns its path (None if nothing buffered)."""
        if not self._buffer:
            return None
        arrays = {k: np.concatenate([b[k] for b in self._buffer]) for k in KEYS}
        path = self.directory / f"shard-{self._next:06d}.npz"
        write_shard(path, arrays, self.n_max, self.status_values)
        self._next += 1
        self._stored += len(self._buffer)
        self._buffer = []
        return path

    def close(self) -> None:
        self.flush()

    def __enter__(self) -> "DatasetWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()  # also on error: the buffered samples are complete and valid


# ----------------------------------------------------------------------------- reading

META_SCHEMA = Schema({
    "type": "object", "required": ["format", "n_max", "status_codes", "world_config"],
    "properties": {"format": {"enum": [FORMAT]}, "n_max": {"type": "integer", "minimum": 1, "maximum": 64},
                   "world_config": {"type": "object"}, "seed": {"type": "integer", "minimum": 0},
                   "status_codes": {"type": "object", "additionalProperties": {"type": "integer"}},
                   "collection": {"type": "object", "properties": {
                       "objects": {"type": "array", "items": {"type": "integer", "minimum": 1}},
                       "shards": {"type": "integer", "minimum": 0}}}}})


def read_meta(directory: str | Path) -> dict[str, Any]:
    """A dataset's meta.json, through the guarded reader and `META_SCHEMA`; ValueError naming it otherwise."""
    path = Path(directory) / META_NAME
    meta = read_json(path, "dataset meta file (meta.json)")
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        got = meta.get("format") if isinstance(meta, dict) else type(meta).__name__
        raise ValueError(f"{path}: format {str(got)[:40]!r}, expected {FORMAT!r}")
    META_SCHEMA.check(meta, str(path))
    return meta


def read_shard(path: str | Path, n_max: int | None = None,
               status_values: Sequence[int] | None = None) -> Transitions:
    """Load and validate one shard; raises ShardError naming the file."""
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, KeyError) as e:
        raise ShardError(path, f"unreadable shard ({type(e).__name__}: {e})") from e
    reason = validate_arrays(arrays, n_max, status_values)
    if reason:
        raise ShardError(path, reason)
    return Transitions(**{k: arrays[k] for k in KEYS})


PATH_SETTINGS = ("simplify_paths",)
"""World settings that shape the arm's collision-free paths, not where blocks come to rest: datasets that differ
in them alone combine (the steps `tamp practice` records were executed with simplified paths)."""


def _defining(key: str, value: Any) -> Any:
    """A meta field as far as it decides whether two datasets are of one world."""
    if key == "world_config" and isinstance(value, dict):
        return {k: v for k, v in value.items() if k not in PATH_SETTINGS}
    return value


def load_transitions(source: "str | Path | Sequence[str | Path]", skip_corrupt: bool = False) -> Transitions:
    """Read and validate every shard of a dataset directory, or of several.

    Several directories (datasets of one world collected apart, e.g. with other ``--objects``) are
    concatenated in the order given and padded to the largest ``n_max``; their world (but for
    `PATH_SETTINGS`) and outcome codes must agree, and ``meta["sources"]`` lists each one's path, seed,
    object counts and size.
    A bad shard raises ShardError (a ValueError naming the file); with ``skip_corrupt`` it is
    skipped with a warning and listed in ``.skipped`` instead.
    """
    if isinstance(source, (str, Path)):
        return _load_directory(Path(source), skip_corrupt)
    directories = [Path(d) for d in source]
    if not directories:
        raise ValueError("no dataset directory given")
    if len(directories) == 1:
        return _load_directory(directories[0], skip_corrupt)
    if len({d.resolve() for d in directories}) < len(directories):
        raise ValueError(f"a dataset directory is given twice: {', '.join(map(str, directories))}")
    parts = [_load_directory(d, skip_corrupt) for d in directories]
    for d, part in zip(directories[1:], parts[1:]):
        for key in ("format", "world_config", "status_codes"):
            if _defining(key, part.meta.get(key)) != _defining(key, parts[0].meta.get(key)):
                raise ValueError(f"{d}: its {key} differs from {directories[0]}'s: datasets of different "
                                 "worlds cannot be combined")
    n_max = max(p.n_max for p in parts)
    sources = [{"path": str(d), "seed": p.meta.get("seed"), "n_max": p.n_max, "samples": len(p),
                "objects": p.meta.get("collection", {}).get("objects")} for d, p in zip(directories, parts)]
    meta = {k: v for k, v in parts[0].meta.items() if k not in ("collection", "seed")}
    out = Transitions.concatenate([p.padded(n_max) for p in parts], {**meta, "n_max": n_max, "sources": sources})
    out.skipped = [s for p in parts for s in p.skipped]
    return out


def _load_directory(directory: Path, skip_corrupt: bool) -> Transitions:
    """The transitions of one dataset directory (see `load_transitions`)."""
    meta = read_meta(directory)
    status_values = sorted(meta["status_codes"].values())
    parts, skipped = [], []
    for p in shard_paths(directory):
        try:
            parts.append(read_shard(p, int(meta["n_max"]), status_values))
        except ShardError as e:
            if not skip_corrupt:
                raise
            warnings.warn(f"skipping corrupt shard: {e}", stacklevel=2)
            skipped.append(str(p))
    if not parts:
        raise ValueError(f"{directory}: no readable shards")
    out = Transitions.concatenate(parts, meta)
    out.skipped = skipped
    return out
