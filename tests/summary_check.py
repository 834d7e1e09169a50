"""Every ``summary.json`` a test's study produces, checked against the published JSON Schema
(``docs/summary.schema.json``, with the ``jsonschema`` library) and read back by the one reader
(:func:`roboisf.decompose.summary.read_summary`), whose serialiser must give the same bytes."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jsonschema

from roboisf.decompose.summary import dumps, read_summary

SCHEMA_FILE = Path(__file__).resolve().parents[1] / "docs" / "summary.schema.json"


def schema() -> dict[str, Any]:
    return json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))


def validated(path: Path) -> dict[str, Any]:
    """``path`` (a summary.json or its results folder) as a dict, after checking that it
    validates against the schema and that reading and writing it again gives the same text."""
    path = Path(path)
    if path.is_dir():
        path = path / "summary.json"
    text = path.read_text(encoding="utf-8")
    data = json.loads(text)
    jsonschema.Draft202012Validator(schema()).validate(data)
    assert dumps(read_summary(path)) == text, f"{path}: read and written again differs"
    return data
