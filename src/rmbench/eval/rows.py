"""A results file of rows, one per key (the probes' JSON files under benchmarks/results/).

A probe run again replaces its own row and leaves the others; the file is written atomically,
so a killed probe leaves the old file or the whole new one, never half of either.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from rmbench.files import write_json


def put_row(path: Path, row: dict[str, Any], key: tuple[str, ...], field: str = "rows") -> list[dict]:
    """Write ``row`` into the list ``field`` of the JSON file at ``path``, in place of the row
    with the same values at ``key`` (appended where none has them); return the new list. A file
    that is not such a JSON object is a ValueError naming it; nothing is written then."""
    path = Path(path)
    doc: dict[str, Any] = {field: []}
    if path.exists():
        try:
            doc = json.loads(path.read_text())
            rows = doc[field]
            if not isinstance(rows, list):
                raise TypeError(f"{field!r} is not a list")
        except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError) as err:
            raise ValueError(f"{path}: not a results file of {field!r} rows ({err})") from None
    which = tuple(row[k] for k in key)
    doc[field] = [r for r in doc[field] if tuple(r.get(k) for k in key) != which] + [row]
    write_json(path, doc)
    return doc[field]
