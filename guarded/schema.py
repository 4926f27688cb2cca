"""Typed checks of a parsed file's structure: JSON Schema, compiled to Python by fastjsonschema.

Draft 4, because there an "integer" is an int (draft 6 on also takes 2.0), and neither counts true
or false as a number. The schema says what JSON can say (field types, required fields, ranges,
lengths, known names); what depends on other fields (indices against the scene's blocks, one-hot
types, times against segments) the reader checks after it. fastjsonschema rather than the
reference `jsonschema` package: the same standard, 30 times faster (0.2 s instead of 6.5 s on the
bundled 21,000-operator domain).
"""
from __future__ import annotations

import json
from typing import Any, Callable

import fastjsonschema

from guarded.read import InputError

DRAFT = "http://json-schema.org/draft-04/schema#"
KINDS = {"integer": "an integer", "number": "a number", "string": "a string", "boolean": "true or false",
         "array": "a list", "object": "an object", "null": "null"}


def _short(value: Any, keep: int = 40) -> str:
    try:
        text = json.dumps(value)
    except (TypeError, ValueError, RecursionError):
        text = type(value).__name__
    return text if len(text) <= keep else text[:keep - 3] + "..."


def _problem(error: fastjsonschema.JsonSchemaValueException) -> str:
    """What is wrong, in the words of the project's other messages."""
    rule, need, value = error.rule, error.rule_definition, error.value
    if rule == "required" and isinstance(value, dict):
        return f"missing field {next(str(k) for k in need if k not in value)!r}"
    if rule == "additionalProperties" and isinstance(value, dict) and isinstance(error.definition, dict):
        known = error.definition.get("properties", {})
        return f"unknown field {next(k for k in value if k not in known)!r} (expected {', '.join(known)})"
    if rule == "type":
        kinds = [str(k) for k in (need if isinstance(need, list) else [need])]
        return f"expected {' or '.join(KINDS.get(k, k) for k in kinds)}, got {_short(value)}"
    if rule == "enum":
        return f"expected one of {', '.join(map(_short, need))}, got {_short(value)}"
    if rule in ("minimum", "maximum"):
        return f"expected a value {'>=' if rule == 'minimum' else '<='} {need}, got {_short(value)}"
    if rule in ("minItems", "maxItems") and isinstance(value, list):
        return f"expected {'at least' if rule == 'minItems' else 'at most'} {need} items, got {len(value)}"
    return "must " + error.message.split(" must ", 1)[1] if " must " in error.message else error.message


class Schema:
    """A JSON Schema for one kind of file (or line of one), compiled on first use."""

    def __init__(self, definition: dict[str, Any]) -> None:
        self.definition = {"$schema": DRAFT, **definition}
        self._validate: Callable[[Any], Any] | None = None

    def check(self, value: Any, where: str) -> None:
        """InputError naming `where` (the file, or its line) and the field when `value` does not fit:
        "p.json: X_init[0]: expected 5 items, got 4"."""
        if self._validate is None:
            self._validate = fastjsonschema.compile(self.definition)
        try:
            self._validate(value)
        except fastjsonschema.JsonSchemaValueException as error:
            name = error.name or "data"
            field = name[len("data"):].lstrip(".") if name.startswith("data") else name
            raise InputError(f"{where}: {field + ': ' if field else ''}{_problem(error)}") from None
