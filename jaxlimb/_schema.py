"""The JSON Schemas of the files that cross the package's boundary, and validation against them.

``jaxlimb/schemas/{camera,hints,result}.schema.json`` (JSON Schema draft 2020-12, shipped with the package) are
the one statement of the keys, types and ranges of the camera file, the hints file and the record ``jaxlimb
locate --json`` prints; the readers (:meth:`jaxlimb.geometry.camera.Camera.from_dict`,
:meth:`jaxlimb.geometry.hints.Hints.from_dict`) hold a file to them, and the constructors also check what a schema
cannot say (finite numbers, a non-zero Sun direction, a proper rotation, a distortion that does not fold over).

A failure is one :class:`~jaxlimb.errors.ConfigError` line naming the key path (``camera `principal_point_rc[1]`
must be a number, got str '3'``); a key the schema does not know is named with the known key it most likely
misspells (:func:`jaxlimb._validate.near_key`).

Start-up.  Importing the ``jsonschema`` library costs 0.08-0.17 s of CPU in a process that has imported the pipeline
(measured on a loaded 2-core machine), far more than reading both files and building the objects, and ``jaxlimb
locate`` reads a camera and a hints file on every call.  So a reader checks a file in two steps: :func:`check_keys`
applies the schema's key rules (unknown and required keys, read from the schema file), then the constructor checks
every value; only when the constructor refuses one does :func:`explain` run the ``jsonschema`` validator, whose
message (the key path, the type or range the schema asks for) replaces the constructor's.  The constructors are at
least as strict as the schemas (``tests/cli/test_schemas.py`` checks it on generated values), so a file they accept
is valid against its schema.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path
from typing import Any, NoReturn

from ._validate import Range, near_key
from .errors import ConfigError

#: The schemas shipped in ``jaxlimb/schemas/`` (package data, beside this module).
SCHEMA_NAMES = ("camera", "hints", "result")
SCHEMA_DIR = Path(__file__).with_name("schemas")


@functools.cache
def _schema_text(name: str) -> str:
    if name not in SCHEMA_NAMES:
        raise ValueError(f"no schema {name!r}; known: {SCHEMA_NAMES}")
    return (SCHEMA_DIR / f"{name}.schema.json").read_text(encoding="utf-8")


def load_schema(name: str) -> dict[str, Any]:
    """The schema ``name`` (``"camera"``, ``"hints"`` or ``"result"``) as a new dictionary."""
    return json.loads(_schema_text(name))


@functools.cache
def schema_keys(name: str) -> tuple[str, ...]:
    """The top-level keys schema ``name`` describes, in its order."""
    return tuple(load_schema(name).get("properties", {}))


@functools.cache
def _validator(name: str) -> Any:
    from jsonschema import Draft202012Validator  # imported here: see the module docstring

    schema = load_schema(name)
    Draft202012Validator.check_schema(schema)
    return Draft202012Validator(schema)


def validate(instance: Any, name: str, what: str) -> None:
    """Check ``instance`` against schema ``name`` with ``jsonschema``; ``what`` names the file in the message.

    Raises
    ------
    ConfigError
        One line: unknown keys (with the key each most likely misspells), missing required keys, or the most
        relevant wrong type or range with its key path.
    """
    errors = list(_validator(name).iter_errors(instance))
    if errors:
        raise ConfigError(describe(errors, what))


def check_keys(instance: dict[str, Any], name: str, what: str) -> None:
    """The top-level key rules of schema ``name`` without importing ``jsonschema`` (module docstring): an unknown
    key when the schema admits no other (``additionalProperties: false``), a missing ``required`` key.

    Raises
    ------
    ConfigError
        Naming the unknown keys (with the known key each most likely misspells) or the missing ones.
    """
    schema = json.loads(_schema_text(name))
    known = list(schema.get("properties", {}))
    if schema.get("additionalProperties", True) is False and set(instance) - set(known):
        raise ConfigError(unknown_keys_message(instance, known, what))
    missing = [k for k in schema.get("required", ()) if k not in instance]
    if missing:
        raise ConfigError(f"{what} is missing keys {missing}")


def explain(instance: Any, name: str, what: str, error: ConfigError) -> NoReturn:
    """After a constructor refused ``instance`` with ``error``: raise the schema's message when ``instance`` is not
    valid against schema ``name`` (it names the key path), else ``error`` itself."""
    errors = list(_validator(name).iter_errors(instance))
    if errors:
        raise ConfigError(describe(errors, what)) from None
    raise error


def describe(errors: list[Any], what: str) -> str:
    """The one-line message of ``jsonschema`` ``errors``: unknown keys first, then missing keys, then the most
    relevant other error (:func:`jsonschema.exceptions.best_match`)."""
    from jsonschema.exceptions import best_match

    by_kind: dict[str, list[Any]] = {}
    for e in errors:
        by_kind.setdefault(e.validator, []).append(e)
    if "additionalProperties" in by_kind:
        e = by_kind["additionalProperties"][0]
        return unknown_keys_message(e.instance, list(e.schema.get("properties", {})), _where(what, e.absolute_path))
    if "required" in by_kind:
        e = by_kind["required"][0]
        missing = [k for k in e.validator_value if k not in e.instance]
        return f"{_where(what, e.absolute_path)} is missing keys {missing}"
    return _one(best_match(errors), what)


def unknown_keys_message(instance: dict[str, Any], known: list[str], what: str) -> str:
    """The message of unknown keys: ``camera has unknown keys ['focal_length'] ('focal_length': did you mean
    'focal_length_mm'?); allowed: [...]``."""
    unknown = sorted((k for k in instance if k not in known), key=str)
    near = {k: near_key(k, known) for k in unknown}
    hint = "; ".join(f"{k!r}: did you mean {v!r}?" for k, v in near.items() if v)
    return f"{what} has unknown keys {unknown}" + (f" ({hint})" if hint else "") + f"; allowed: {known}"


def _where(what: str, path: Any) -> str:
    """``camera`` or ``camera `principal_point_rc[1]```."""
    parts = list(path)
    if not parts:
        return what
    return f"{what} `{parts[0]}" + "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in parts[1:]) + "`"


_KINDS = {"number": "a number", "integer": "an integer", "string": "a string", "array": "a list",
          "object": "a JSON object", "boolean": "true or false", "null": "null"}


def _got(value: Any) -> str:
    if value is None:
        return "null"
    text = f"{type(value).__name__} {value!r}" if isinstance(value, (bool, str)) else repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _one(e: Any, what: str) -> str:
    where, v, s = _where(what, e.absolute_path), e.instance, e.schema
    kind = e.validator
    if kind == "type":
        types = s["type"] if isinstance(s["type"], list) else [s["type"]]
        return f"{where} must be {' or '.join(_KINDS.get(t, t) for t in types)}, got {_got(v)}"
    if kind in ("minimum", "exclusiveMinimum", "maximum", "exclusiveMaximum"):
        lo = s.get("exclusiveMinimum", s.get("minimum"))
        hi = s.get("exclusiveMaximum", s.get("maximum"))
        rng = Range(lo, hi, lo_open="exclusiveMinimum" in s, hi_open="exclusiveMaximum" in s)
        return f"{where} must be {'an integer' if 'integer' in str(s.get('type')) else 'a number'} {rng}, got {_got(v)}"
    if kind in ("minItems", "maxItems"):
        lo, hi = s.get("minItems"), s.get("maxItems")
        n = str(lo) if lo == hi else f"{lo or 0} to {hi}" if hi is not None else f"at least {lo}"
        return f"{where} must be a list of {n} items, got {_got(v)}"
    if kind == "pattern" and s["pattern"] == "\\S":
        return f"{where} must be a non-blank string, got {_got(v)}"
    if kind in ("const", "enum"):
        allowed = [s["const"]] if kind == "const" else s["enum"]
        return f"{where} must be {' or '.join(map(repr, allowed))}, got {_got(v)}"
    return f"{where}: {' '.join(str(e.message).split())[:200]}"


__all__ = ["SCHEMA_DIR", "SCHEMA_NAMES", "check_keys", "describe", "explain", "load_schema", "schema_keys",
           "unknown_keys_message", "validate"]
