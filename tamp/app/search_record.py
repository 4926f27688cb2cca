"""Search record files (`tamp plan --search`, `tamp demo --search`; docs/search-record.md): written atomically,
read back through the guarded reader and `SCHEMA`, so that other tools (the HTML view) can use them.

`SearchRecording` collects a run's rounds while it plans (a `Recorder` active around the run; each round built
when the planner hands it over, its executed step when the loop acts) and writes the file; the rounds
themselves are `tamp.planning.search_record`'s.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from guarded import Schema, atomic_write_text, dumps, read_json
from tamp.errors import UserError
from tamp.inputs import ACTION, SCENE
from tamp.planning.results import PlanResult
from tamp.planning.search_record import FORMAT, VERSION, Facts, executed_record, round_record, symbol_names
from tamp.planning.search_trace import Recorder

if TYPE_CHECKING:  # `learned` loads torch: a reader of record files does without it
    from learned.interpret import BitNames

_NUMBER, _INT = {"type": "number"}, {"type": "integer"}
_MAYBE_NUMBER, _MAYBE_INT, _MAYBE_STR = {"type": ["number", "null"]}, {"type": ["integer", "null"]}, \
    {"type": ["string", "null"]}
def _nullable(schema: dict) -> dict:
    """`schema` or null, one schema (not anyOf), so that a wrong field inside it is named in the message."""
    return {**schema, "type": [schema["type"], "null"]}


_POSITIONS = {"type": "array", "items": {"type": "array", "minItems": 3, "maxItems": 3, "items": _NUMBER}}
_PLAN = {"type": "array", "items": ACTION}
_STRINGS = {"type": "array", "items": {"type": "string"}}
_CANDIDATE = {"type": "object", "required": ["rank", "actions", "count", "probability", "error_m", "verified", "chosen",
                                             "facts", "predicted", "kinematics"], "properties": {
    "rank": {"type": "integer", "minimum": 1}, "actions": _PLAN, "count": {"type": "integer", "minimum": 0},
    "probability": _NUMBER, "error_m": _MAYBE_NUMBER, "verified": {"type": ["boolean", "null"]},
    "chosen": {"type": "boolean"}, "facts": {"type": "array", "items": _STRINGS},
    "predicted": {"type": ["array", "null"], "items": _POSITIONS},
    "kinematics": {"type": "array", "items": {"type": "object", "required": ["verdict"],
                                              "properties": {"verdict": {"type": "string"}}}},
    "stages": {"type": ["array", "null"], "items": _INT}}}
_NODE = {"type": "object", "required": ["id", "parent", "order", "action", "g", "h", "X", "verdict", "reason"],
         "properties": {"id": {"type": "integer", "minimum": 0}, "parent": _MAYBE_INT, "order": _MAYBE_INT,
                        "action": _nullable(ACTION), "g": _NUMBER, "h": _NUMBER, "X": _nullable(_POSITIONS),
                        "verdict": {"type": "string"},
                        "reason": _MAYBE_STR, "duplicates": {"type": "integer", "minimum": 0}}}
_LEVEL2 = {"type": "object", "required": ["status", "expanded", "generated", "truncated", "nodes", "path"],
           "properties": {"status": {"type": "string"}, "reason": {"type": "string"},
                          "expanded": {"type": "integer", "minimum": 0}, "generated": {"type": "integer", "minimum": 0},
                          "truncated": {"type": "boolean"}, "searches": _INT, "omitted": _INT,
                          "nodes": {"type": "array", "items": _NODE}, "path": {"type": "array", "items": _INT},
                          "closest": {"type": "array", "items": _INT}}}
_REFINEMENT = {"type": "object", "required": ["level", "plan", "outcome", "actions"], "properties": {
    "level": {"enum": [1, 2]}, "plan": _PLAN, "outcome": {"type": "string"}, "failed_action": _MAYBE_INT,
    "actions": {"type": "array", "items": {"type": "object", "required": ["ik_branch", "planner", "time_s", "failure"],
                                           "properties": {"ik_branch": _MAYBE_STR, "planner": _MAYBE_STR,
                                                          "time_s": _MAYBE_NUMBER, "failure": _MAYBE_STR}}}}}
_EXECUTED = {"type": "object", "required": ["action", "predicted", "observed", "miss_m"], "properties": {
    "action": ACTION, "predicted": _POSITIONS, "observed": _POSITIONS, "miss_m": _NUMBER}}
ORIGINS = ["planned", "kept on course", "kept by rollout", "widened search", "toward the closest state"]
_ROUND = {"type": "object", "required": ["index", "X_observed", "origin", "why", "method", "level", "plan", "timings_s",
                                         "reasons", "level1", "level2", "refinements", "executed"], "properties": {
    "index": {"type": "integer", "minimum": 0}, "X_observed": SCENE, "origin": {"enum": ORIGINS},
    "why": {"type": "string"}, "method": {"type": "string"}, "level": {"enum": [1, 2, None]},
    "plan": _nullable(_PLAN), "predicted_error_m": _MAYBE_NUMBER,
    "timings_s": {"type": "object", "additionalProperties": _NUMBER}, "reasons": _STRINGS,
    "level1": {"type": "object", "required": ["candidates", "stats"], "properties": {
        "candidates": {"type": "array", "items": _CANDIDATE}, "stats": {"type": "object"}}},
    "level2": _nullable(_LEVEL2), "rejected": {"type": ["object", "null"]},
    "refinements": {"type": "array", "items": _REFINEMENT}, "executed": _nullable(_EXECUTED)}}
# a version-1 record, checked after its format and version
SCHEMA = Schema({"type": "object", "required": ["format", "version", "config", "problem", "symbols", "rounds"],
                 "properties": {
    "format": {"enum": [FORMAT]}, "version": {"enum": [VERSION]}, "config": {"type": "object"},
    "problem": {"type": "object", "required": ["name", "X_init", "X_goal"], "properties": {
        "name": _MAYBE_STR, "X_init": SCENE, "X_goal": SCENE, "source": {"type": "string"}}},
    "symbols": {"type": "object", "required": ["names"], "properties": {
        "names": {"type": "object", "additionalProperties": {"type": "string"}}}},
    "rounds": {"type": "array", "items": _ROUND},
    "replay": {"type": "string"}}})  # the Meshcat replay of the run (`--replay`), which the search view links


def check_search_record(doc: Any, where: str) -> dict:
    """`doc` as a version-1 search record (format, version, then `SCHEMA`); UserError or InputError (one line)."""
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise UserError(f"{where}: not a tamp search record (no \"format\": \"{FORMAT}\")")
    if doc.get("version") != VERSION:
        raise UserError(f"{where}: search record version {str(doc.get('version'))[:20]}; this tamp reads "
                        f"version {VERSION}")
    SCHEMA.check(doc, where)
    return doc


def read_search_record(path: Path) -> dict:
    """A search record file read through the guarded reader and checked (`check_search_record`)."""
    return check_search_record(read_json(path, "search record"), str(path))


def write_search_record(record: dict, path: Path) -> None:
    """Write `record` (checked as it will read back) atomically, as compact JSON."""
    check_search_record(record, f"{path} (being written)")
    atomic_write_text(path, dumps(record, str(path), separators=(",", ":")) + "\n")


@dataclass
class SearchRecording:
    """A run's search record while it runs: `recorder` is made active around its planning calls, `planned` and
    `executed` are called as the run's rounds plan and act."""

    problem: dict  # name, X_init, X_goal (and source: the command that made the run)
    config: dict  # the resolved configuration (`settings_record`)
    names: BitNames
    facts: Facts | None = None
    recorder: Recorder = field(default_factory=Recorder)
    rounds: list[dict] = field(default_factory=list)
    _results: list[PlanResult] = field(default_factory=list)
    _X: np.ndarray | None = None  # the state the next round plans from
    replay: Path | None = None  # the run's Meshcat replay, if it writes one: the view links each step to it

    def planned(self, result: PlanResult, X_observed: np.ndarray | None = None) -> None:
        """A round's planning call returned `result` (from the state observed last, or `X_observed`)."""
        X = X_observed if X_observed is not None else self._X if self._X is not None else self.problem["X_init"]
        self.rounds.append(round_record(len(self.rounds), result, self.recorder, np.asarray(X), self.facts))
        self._results.append(result)
        self.recorder.reset()

    def executed(self, action, X_after: np.ndarray) -> None:
        """The loop executed `action` and observed `X_after`: the last round's first step, if it is."""
        self._X = np.asarray(X_after, dtype=float)
        if self.rounds and self.rounds[-1]["executed"] is None:
            self.rounds[-1]["executed"] = executed_record(self._results[-1], action, X_after)

    def document(self) -> dict:
        problem = {k: (np.asarray(v, dtype=float).round(6).tolist() if k.startswith("X_") else v)
                   for k, v in self.problem.items()}
        return {"format": FORMAT, "version": VERSION, "config": self.config, "problem": problem,
                "symbols": {"names": symbol_names(self.names)}, "rounds": self.rounds,
                **({} if self.replay is None else {"replay": str(self.replay)})}

    def write(self, path: Path) -> None:
        """The record at `path` and its view beside it (`path` with .html; `tamp view --search` writes it again)."""
        from tamp.app.search_view import write_search_view

        document = self.document()
        write_search_record(document, path)
        view = write_search_view(document, view_path(path))
        print(f"search record written to {path} ({len(self.rounds)} round(s), {path.stat().st_size / 1e3:.0f} kB), "
              f"its view to {view}")


def view_path(record: Path) -> Path:
    """Where the view of the search record at `record` goes by default: beside it, .json (.gz) replaced by .html."""
    stem = record.name.removesuffix(".gz").removesuffix(".json")
    return record.with_name(stem + ".html")


__all__ = ["SCHEMA", "SearchRecording", "check_search_record", "read_search_record", "view_path",
           "write_search_record"]
