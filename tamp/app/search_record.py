"""Search record files (`tamp plan --search`): read back through the guarded reader and `SCHEMA`, so that the
search view (`tamp view --search`) and other tools get a checked, version-1 record or a one-line error."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from guarded import Schema, read_json
from tamp.errors import UserError
from tamp.inputs import ACTION, SCENE

FORMAT, VERSION = "tamp-search-record", 1
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
    "replay": {"type": "string"}}})  # the Meshcat replay of the run, which the search view links


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
