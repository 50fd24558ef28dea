"""Where a bench leaves its figures: one JSON file under bench/results (or wherever the bench says).

Shared by the bench scripts that run with bench/ on sys.path (python bench/NAME.py); bench/fsw.py and
bench/soak.py take bench/ off sys.path, since bench/fsw.py would shadow the fsw package, and keep their own.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def write_result(dest: Path, result: dict[str, Any], indent: int = 2) -> Path:
    """Write ``result`` as indented JSON with a final newline to ``dest`` (its folder created); returns
    ``dest`` so that the bench can say where it went."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(result, indent=indent) + "\n")
    return dest
