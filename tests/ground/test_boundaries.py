"""The arrows that must never exist: fsw -> ground, fsw -> hil_sim, ground -> hil_sim (read from the source)."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _imported_top_packages(package: str) -> dict[str, set[str]]:
    """Top-level package of every import in every module of ``package`` -> the modules that import it."""
    found: dict[str, set[str]] = {}
    for path in sorted((ROOT / package).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                found.setdefault(name.split(".")[0], set()).add(str(path.relative_to(ROOT)))
    return found


@pytest.mark.parametrize(("package", "forbidden"), [("fsw", "ground"), ("fsw", "hil_sim"), ("ground", "hil_sim")])
def test_package_never_imports_the_forbidden_one(package: str, forbidden: str) -> None:
    imports = _imported_top_packages(package)
    assert imports, f"no imports found under {package}/: the scan is broken"
    assert forbidden not in imports, f"{package} imports {forbidden} in {sorted(imports[forbidden])}"


def test_ground_reads_the_flight_dictionary() -> None:
    assert "fsw" in _imported_top_packages("ground")
