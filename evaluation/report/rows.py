"""Reading an evaluation's files: the rows (`tamp evaluate`'s rows.jsonl), meta.json, symbols.json and
the Table I ablation; every malformed input is a UserError naming the file, line and field."""
from __future__ import annotations

from pathlib import Path

from guarded import LARGE, InputError, Schema, parse_json, read_json, read_jsonl
from tamp.errors import UserError
from tamp.planning.calibration import SCENES
from tamp.planning.vocabulary import OUTCOMES, Outcome

ERROR_OUTCOME = Outcome.ERROR.value  # a (problem, method) that raised (evaluation.run): listed, left out of the tables
STAGES = ("ik", "motion", "grasp")
_NUMBER = {"type": ["number", "null"]}
# the fields of a row the report reads (rows hold more; evaluation.run.ROW_KEYS lists them all)
ROW_SCHEMA = Schema({
    "type": "object",
    "required": ["problem", "method", "n", "k", "solved", "success", "outcome", "planning_time_s"],
    "properties": {
        "problem": {"type": "string"}, "method": {"type": "string"},
        "n": {"type": "integer", "minimum": 1}, "k": {"type": "integer", "minimum": 1},
        "solved": {"type": "boolean"}, "success": {"type": "boolean"},
        "outcome": {"enum": list(OUTCOMES + (ERROR_OUTCOME,))}, "planning_time_s": {"type": "number"},
        **{name: _NUMBER for name in ("level", "predicted_error_m", "executed_actions", "rounds", "eps_m",
                                      "tau_verify_m", "level1_time_s", "final_error_m", "run", "moved",
                                      "executed_plans")},
        "refined": {"type": ["boolean", "null"]},
        "refine_failure": {"type": ["object", "null"], "required": ["stage"],
                           "properties": {"stage": {"enum": list(STAGES)}}},
        "refine_time_s": {"type": ["array", "null"], "items": {"type": "number"}},
        "predictions": {"type": ["array", "null"], "items": {
            "type": "object", "required": ["class", "miss_m"],
            "properties": {"class": {"type": "string"}, "miss_m": {"type": "number"}, "bound_m": _NUMBER,
                           "scene": {"enum": list(SCENES)}}}}}})


def load_rows(path: Path) -> list[dict]:
    """The result rows of `path` (JSONL, plain or gzip); a ValueError names the file, line and field of
    any malformed row (`ROW_SCHEMA`). A last line cut short by an interrupted evaluation (no newline,
    not JSON) is left out, as the runner does when it resumes.
    """
    return _read_rows(Path(path))[0]


def _read_rows(path: Path) -> tuple[list[dict], int | None]:
    """(rows, number of an incomplete last line that was left out, or None)."""
    lines = read_jsonl(path, "rows file (the JSONL written by `tamp evaluate`)", LARGE, unfinished=True)
    values, dropped = list(lines.values), None
    if lines.tail.strip():
        number = lines.tail_line
        try:
            values.append((number, parse_json(lines.tail, f"{path} line {number}", LARGE)))
        except InputError:  # no newline after it: an append cut short
            dropped = number
    seen: dict[tuple[str, str], int] = {}  # (problem, method) -> line
    cells: dict[str, tuple[int, int, int]] = {}  # problem -> (n, k, line)
    rows = []
    for i, row in values:
        ROW_SCHEMA.check(row, f"{path} line {i}")
        key = (row["problem"], row["method"])
        if key in seen:
            raise UserError(f"{path} line {i}: problem {key[0]!r} with method {key[1]!r} already on "
                             f"line {seen[key]}")
        seen[key] = i
        cell = cells.setdefault(row["problem"], (row["n"], row["k"], i))
        if cell[:2] != (row["n"], row["k"]):
            raise UserError(f"{path} line {i}: problem {row['problem']!r} has n={row['n']}, k={row['k']} "
                             f"but n={cell[0]}, k={cell[1]} on line {cell[2]}")
        rows.append(row)
    if not rows:
        raise UserError(f"{path}: no rows")
    return rows, dropped


def read_json_object(path: Path, what: str) -> dict:
    """The JSON object in `path` (`what` it should be, for the error), through the guarded reader."""
    data = read_json(path, what, LARGE)
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object ({what})")
    return data


def _read_symbols(path: Path) -> list[dict]:
    """OUT/symbols.json (`learned.interpret.read_symbols`); a ValueError names the file and the bit."""
    from learned.interpret import read_symbols

    return read_symbols(path)


ABLATION_SCHEMA = Schema({"type": "object", "required": ["activations"], "properties": {"activations": {
    "type": "object", "minProperties": 1, "additionalProperties": {
        "type": "object", "required": ["mean_cm", "std_cm"],
        "properties": {"mean_cm": {"type": "number"}, "std_cm": {"type": "number"}}}}}})


def load_ablation(path: Path) -> dict:
    """The JSON of `tamp ablate-activations` (`learned.ablation`); a ValueError names the file and field."""
    data = read_json(path, "Table I JSON of `tamp ablate-activations`")
    ABLATION_SCHEMA.check(data, str(path))
    return data
