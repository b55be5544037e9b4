"""Format documentation and JSON Schemas of the suite's on-disk formats.

``schema(name)`` loads ``schemas/NAME.schema.json``; ``schema_problem(name, obj)`` validates an
object and returns the first problem as one line (``"where: what"``), or ``None``.
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path

import jsonschema
from referencing import Registry, Resource

SCHEMA_DIR = Path(__file__).resolve().parent / "schemas"


@lru_cache(maxsize=None)
def schema(name: str) -> dict:
    return json.loads((SCHEMA_DIR / f"{name}.schema.json").read_text())


@lru_cache(maxsize=None)
def _validator(name: str) -> jsonschema.Draft202012Validator:
    resources = [(s["$id"], Resource.from_contents(s))
                 for s in (schema(p.name.removesuffix(".schema.json")) for p in SCHEMA_DIR.glob("*.schema.json"))]
    return jsonschema.Draft202012Validator(schema(name), registry=Registry().with_resources(resources))


def schema_problem(name: str, obj) -> str | None:
    """First schema violation of ``obj`` against schema ``name`` as ``"field.path: message"``."""
    error = jsonschema.exceptions.best_match(_validator(name).iter_errors(obj))
    if error is None:
        return None
    at = error.json_path.replace("$.", "") if error.json_path != "$" else "top level"
    return f"{at}: {error.message}"
