"""Files from outside are untrusted: one guarded reader for JSON, JSON Lines and gzip, and typed
schema checks, for every package (`tamp`, `learned`, `symbolic`, `evaluation`).

A problem file, a plan, a trajectory for a real arm, a models directory downloaded from someone else,
a results directory: each is read by `read_json` or `read_jsonl` (size, gzip, UTF-8, nesting and
number limits; see `Limits`), then checked by a `Schema` (JSON Schema, draft 4) before any work. Every
failure is an `InputError`, a ValueError whose message is one line naming the file and where in it
(line and column, or the field). This package imports nothing of the project, so the packages that
may not import `tamp` (`learned`, `symbolic`) use it too. The writers' side is `guarded.output`: atomic
files, strict JSON, and a disk's failure as one `OutputError` naming the path.
"""
from guarded.output import (
    MARKER,
    OutputError,
    append_line,
    atomic_write,
    atomic_write_bytes,
    atomic_write_json,
    atomic_write_text,
    dumps,
    make_dirs,
    remove_made,
)
from guarded.read import LARGE, InputError, JsonLines, Limits, parse_json, read_bytes, read_json, read_jsonl
from guarded.schema import Schema

__all__ = ["LARGE", "MARKER", "InputError", "JsonLines", "Limits", "OutputError", "Schema", "append_line",
           "atomic_write", "atomic_write_bytes", "atomic_write_json", "atomic_write_text", "dumps", "make_dirs",
           "parse_json", "read_bytes", "read_json", "read_jsonl", "remove_made"]
