"""The file formats page's tables, read from the package's JSON Schemas (``jaxlimb/schemas/*.schema.json``).

A page asks for a schema with ``<!-- schema: NAME -->`` (``camera``, ``hints``, ``result``); :func:`render` returns a
table of its keys (required or not, type and range, meaning) followed by the schema itself, folded.  The keys,
types and ranges of the page are the ones the readers validate against: no second copy is typed by hand.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "jaxlimb" / "schemas"

_NAMES = {"number": "number", "integer": "integer", "string": "string", "object": "object", "array": "list",
          "boolean": "boolean"}


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() and abs(x) < 1e16 else f"{x:g}"


def _range(s: dict[str, Any]) -> str:
    lo = ("> " if "exclusiveMinimum" in s else "≥ ") if ("exclusiveMinimum" in s or "minimum" in s) else ""
    hi = ("< " if "exclusiveMaximum" in s else "≤ ") if ("exclusiveMaximum" in s or "maximum" in s) else ""
    lo_v, hi_v = s.get("exclusiveMinimum", s.get("minimum")), s.get("exclusiveMaximum", s.get("maximum"))
    if lo and hi:
        return f" in {'(' if lo == '> ' else '['}{_num(lo_v)}, {_num(hi_v)}{')' if hi == '< ' else ']'}"
    return f" {lo}{_num(lo_v)}" if lo else f" {hi}{_num(hi_v)}" if hi else ""


def type_text(s: dict[str, Any], root: dict[str, Any]) -> str:
    """``number > 0``, ``list of 2 numbers``, ``3 × 3 numbers``, ``string or null`` ... of a (sub)schema."""
    if "$ref" in s:
        s = {**root["$defs"][s["$ref"].rsplit("/", 1)[1]], **{k: v for k, v in s.items() if k != "$ref"}}
    if "const" in s:
        return f"`{json.dumps(s['const'])}`"
    types = s.get("type", "any")
    types = types if isinstance(types, list) else [types]
    out = []
    for t in types:
        if t == "null":
            continue
        if t == "array":
            items = s.get("items", {})
            n = s.get("minItems") if s.get("minItems") == s.get("maxItems") else None
            inner = type_text(items, root) if items else "any"
            if inner.startswith("list of") and n is not None:
                out.append(f"{n} × {inner.removeprefix('list of ')}")
            else:
                base, _, rng = inner.partition(" ")
                each = f", each {rng}" if rng else ""
                out.append(f"list of {n} {base}s{each}" if n is not None else f"list of {base}s{each}")
        else:
            out.append(_NAMES.get(t, t) + (_range(s) if t in ("number", "integer") else ""))
    return " or ".join(out) + (", or null" if "null" in types else "")


def render(name: str) -> str:
    """The key table of schema ``name`` and the schema file, folded (MkDocs Material ``???`` admonition)."""
    path = SCHEMAS / f"{name}.schema.json"
    text = path.read_text(encoding="utf-8")
    schema = json.loads(text)
    root = schema
    if "oneOf" in schema:  # the result: the success record's keys (the error object is described on the page)
        schema = root["$defs"]["ok"]
    required = set(schema.get("required", ()))
    rows = ["| key | required | type | meaning |", "|---|---|---|---|"]
    for key, sub in schema["properties"].items():
        meaning = " ".join(sub.get("description", "").split()).replace("|", "\\|")
        rows.append(f"| `{key}` | {'yes' if key in required else 'no'} | {type_text(sub, root)} | {meaning} |")
    if "oneOf" in root:
        rows += ["", "A record holds no other key."]
    elif schema.get("additionalProperties", True) is False:
        rows += ["", "Any other key is an error (exit 2) that names the key it most likely misspells."]
    else:
        rows += ["", "Other keys are ignored; one that resembles a key above is named in a warning."]
    body = "\n".join("    " + ln for ln in text.rstrip().splitlines())
    rows += ["", f'??? note "The schema: `jaxlimb/schemas/{name}.schema.json` (JSON Schema 2020-12)"', "",
             "    ```json", body, "    ```", ""]
    return "\n".join(rows)


def names() -> list[str]:
    return sorted(p.name.removesuffix(".schema.json") for p in SCHEMAS.glob("*.schema.json"))
