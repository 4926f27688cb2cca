"""Reading an evaluation's files: the rows (`tamp evaluate`'s rows.jsonl), meta.json, symbols.json and
the Table I ablation; every malformed input is a UserError naming the file, line and field."""
from __future__ import annotations

import json
from pathlib import Path

from tamp.errors import UserError
from tamp.planning.structs import OUTCOMES, Outcome

ERROR_OUTCOME = Outcome.ERROR.value  # a (problem, method) that raised (evaluation.run): listed, left out of the tables
STAGES = ("ik", "motion", "grasp")
_NUMBER = (int, float)


def _check(path: Path, line: int, row: dict, name: str, types: tuple, nullable: bool, what: str) -> None:
    value = row.get(name)
    if name not in row and not nullable:
        raise UserError(f"{path}, line {line}: missing field {name!r}")
    if value is None and nullable:
        return
    if (isinstance(value, bool) and bool not in types) or not isinstance(value, types):
        raise UserError(f"{path}, line {line}: field {name!r} must be {what}, got {value!r}")


def load_rows(path: Path) -> list[dict]:
    """The result rows of `path` (JSONL); a ValueError names the file and line of any malformed row.

    Fields used: problem, n, k, method, solved, success, outcome, planning_time_s (required);
    level, plan, predicted_error_m, refined, refine_failure, refine_time_s, executed_actions,
    executed_plans, rounds, eps_m, tau_verify_m, fidelity, run, protocol, moved, symbolic_backend
    (may be null or absent; a row without `run` belongs to run 0). A last line cut short by an interrupted
    evaluation (no newline, not JSON) is left out, as the runner does when it resumes.
    """
    return _read_rows(Path(path))[0]


def _read_rows(path: Path) -> tuple[list[dict], int | None]:
    """(rows, number of an incomplete last line that was left out, or None)."""
    if not path.is_file():
        raise UserError(f"{path}: no rows file (expected the JSONL written by `tamp evaluate`)")
    seen: dict[tuple[str, str], int] = {}  # (problem, method) -> line
    cells: dict[str, tuple[int, int, int]] = {}  # problem -> (n, k, line)
    rows, dropped = [], None
    try:
        lines = path.read_text().split("\n")
    except UnicodeDecodeError as error:
        raise UserError(f"{path}: not a text file ({error.reason} at byte {error.start})") from None
    for i, text in enumerate(lines, start=1):
        if not text.strip():
            continue
        try:
            row = json.loads(text)
        except json.JSONDecodeError as error:
            if i == len(lines):  # no newline after it: an append cut short
                dropped = i
                break
            raise UserError(f"{path}, line {i}: not valid JSON ({error.msg})") from None
        if not isinstance(row, dict):
            raise UserError(f"{path}, line {i}: expected a JSON object, got {type(row).__name__}")
        _check_row(path, i, row)
        key = (row["problem"], row["method"])
        if key in seen:
            raise UserError(f"{path}, line {i}: problem {key[0]!r} with method {key[1]!r} already on "
                             f"line {seen[key]}")
        seen[key] = i
        cell = cells.setdefault(row["problem"], (row["n"], row["k"], i))
        if cell[:2] != (row["n"], row["k"]):
            raise UserError(f"{path}, line {i}: problem {row['problem']!r} has n={row['n']}, k={row['k']} "
                             f"but n={cell[0]}, k={cell[1]} on line {cell[2]}")
        rows.append(row)
    if not rows:
        raise UserError(f"{path}: no rows")
    return rows, dropped


def _check_row(path: Path, i: int, row: dict) -> None:
    for name, types, what in (("problem", (str,), "a string"), ("method", (str,), "a string"),
                              ("n", (int,), "an integer"), ("k", (int,), "an integer"),
                              ("solved", (bool,), "true or false"), ("success", (bool,), "true or false"),
                              ("outcome", (str,), "a string"), ("planning_time_s", _NUMBER, "a number")):
        _check(path, i, row, name, types, False, what)
    for name in ("level", "predicted_error_m", "executed_actions", "rounds", "eps_m", "tau_verify_m",
                 "level1_time_s", "final_error_m", "run", "moved", "executed_plans"):
        _check(path, i, row, name, _NUMBER, True, "a number or null")
    _check(path, i, row, "refined", (bool,), True, "true, false or null")
    _check(path, i, row, "refine_failure", (dict,), True, "an object or null")
    _check(path, i, row, "refine_time_s", (list,), True, "a list of seconds or null")
    if row["outcome"] not in OUTCOMES + (ERROR_OUTCOME,):
        raise UserError(f"{path}, line {i}: field 'outcome' must be one of {', '.join(OUTCOMES + (ERROR_OUTCOME,))}, "
                         f"got {row['outcome']!r}")
    if isinstance(row.get("refine_failure"), dict) and row["refine_failure"].get("stage") not in STAGES:
        raise UserError(f"{path}, line {i}: field 'refine_failure.stage' must be one of "
                         f"{', '.join(STAGES)}, got {row['refine_failure'].get('stage')!r}")
    if not all(isinstance(t, _NUMBER) and not isinstance(t, bool) for t in row.get("refine_time_s") or []):
        raise UserError(f"{path}, line {i}: field 'refine_time_s' must be a list of seconds")


def read_json_object(path: Path, what: str) -> dict:
    """The JSON object in `path` (`what` it should be, for the error); UserError when it is not one."""
    try:
        data = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise UserError(f"{path}: not valid JSON ({error.msg}, line {error.lineno}); expected {what}") from None
    if not isinstance(data, dict):
        raise UserError(f"{path}: expected a JSON object ({what})")
    return data


def _read_symbols(path: Path) -> list[dict]:
    """OUT/symbols.json (`learned.interpret.read_symbols`); a ValueError names the file and the bit."""
    from learned.interpret import read_symbols

    return read_symbols(path)


def load_ablation(path: Path) -> dict:
    """The JSON of `tamp ablate-activations` (`learned.ablation`); a ValueError names the file and field."""
    data = read_json_object(path, "the output of `tamp ablate-activations`")
    acts = data.get("activations")
    if not isinstance(acts, dict) or not acts:
        raise UserError(f"{path}: field 'activations' must be an object of activation -> results")
    for name, r in acts.items():
        for f in ("mean_cm", "std_cm"):
            if not isinstance(r, dict) or not isinstance(r.get(f), _NUMBER):
                raise UserError(f"{path}: field 'activations.{name}.{f}' must be a number")
    return data
