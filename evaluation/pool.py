"""Several evaluations as one results directory with one run per problem set (`tamp pool`).

A held-out claim is steadier over several problem sets (seeds) than over one, but each
`tamp evaluate` writes its own directory, and problem names (n5-k1-000, ...) repeat across sets.
`pool` renumbers the runs, source by source in the order given (a source's own runs keep their
order), and names each problem `r{run}-NAME` as `tamp problems --runs` does; `tamp report` then
gives every table over all sets with mean ± std over runs, and `tamp compare` pairs two pooled
directories made from the same problem sets in the same order. The sources must have been evaluated
with the same models and settings (their meta.json say so), else pooling them is refused.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

from guarded import atomic_write_json, dumps
from tamp.errors import UserError
from tamp.records import atomic_write_text, output_dir

from .compare import load_rows
from .report import read_json_object
from .run import META_NAME, ROWS_NAME

SAME = ("model_files", "config")  # meta.json fields every pooled source must share
_RUN_PREFIX = re.compile(r"^r\d+-")


@dataclass
class PoolReport:
    out: Path
    rows: int
    runs: list[dict[str, Any]]  # per source: {"source", "runs": {old run: new run}, "rows"}


def _meta(directory: Path) -> dict:
    path = directory / META_NAME
    if not path.is_file():
        raise UserError(f"{directory}: no {META_NAME} (pooling checks that every evaluation used the same models "
                        "and settings; give the --out directories of `tamp evaluate`)")
    return read_json_object(path, "the evaluation's meta.json")


def pool(out: str | Path, sources: Sequence[str | Path]) -> PoolReport:
    """Write OUT/rows.jsonl and OUT/meta.json from the evaluations in `sources` (see the module doc).
    UserError when fewer than two sources are given, one is given twice, they differ in models or
    settings, or OUT already holds rows (nothing is overwritten)."""
    out, dirs = Path(out), [Path(s) for s in sources]
    if len(dirs) < 2:
        raise UserError("give at least two results directories to pool")
    seen: dict[Path, Path] = {}
    for d in dirs:
        if not d.is_dir():
            raise UserError(f"no results directory at {d} (the --out directory of `tamp evaluate`)")
        if d.resolve() in seen:
            raise UserError(f"{d} is given twice (as {seen[d.resolve()]}): each problem set once")
        seen[d.resolve()] = d
    if (out / ROWS_NAME).exists() or (out / META_NAME).exists():
        raise UserError(f"{out} already holds {ROWS_NAME} or {META_NAME}: pool into a new directory")
    metas = [_meta(d) for d in dirs]
    for key in SAME:
        for d, meta in zip(dirs[1:], metas[1:]):
            if meta.get(key) != metas[0].get(key):
                raise UserError(f"{dirs[0]} and {d} differ in meta.json '{key}' (other models or settings): "
                                "pool only evaluations made with the same ones")
    rows, record, next_run = [], [], 0
    for d in dirs:
        mine = load_rows(d)
        if not mine:
            raise UserError(f"{d}: no rows to pool")
        runs = {r: next_run + i for i, r in enumerate(sorted({int(row.get("run") or 0) for row in mine}))}
        next_run += len(runs)
        for row in mine:
            old = int(row.get("run") or 0)
            name = str(row["problem"])
            if name.startswith(f"r{old}-"):
                name = _RUN_PREFIX.sub("", name, count=1)
            rows.append({**row, "run": runs[old], "problem": f"r{runs[old]}-{name}"})
        record.append({"source": str(d), "runs": {str(k): v for k, v in runs.items()}, "rows": len(mine)})
    methods: list[str] = []
    for meta in metas:
        methods += [m for m in meta.get("methods", []) if m not in methods]
    meta = {**metas[0], "methods": methods,
            "problems": [m.get("problems") for m in metas],
            "problems_sha256": [m.get("problems_sha256") for m in metas],
            "n_problems": sum(int(m.get("n_problems") or 0) for m in metas),
            "pooled": [{**r, "started": m.get("started")} for r, m in zip(record, metas)]}
    meta.pop("runs", None)  # each source's evaluation runs (workers, times) stay in its own meta.json
    with output_dir(out, "OUT", own=(ROWS_NAME, META_NAME)):  # a failed write leaves no folder behind
        atomic_write_text(out / ROWS_NAME, "".join(dumps(r, str(out / ROWS_NAME)) + "\n" for r in rows))
        atomic_write_json(out / META_NAME, meta, indent=2)
    return PoolReport(out, len(rows), record)


__all__ = ["PoolReport", "pool"]
