"""The project speaks to its users only: README, docs, code and configs name no folder outside the repository
and tell history by date or commit, never by work period or internal issue number (CI's own script, .ci/run,
may use the tools beside the checkout)."""
from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PATTERNS = {
    "a folder outside the repository": re.compile(r"\.\./shared"),
    "an internal issue number": re.compile(r"\b[Ii]ssues? \d+"),
    "a work period": re.compile(r"\b(first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|"
                                r"this|last|next|earlier|previous) session\b", re.I),
}
SUFFIXES = {".py", ".md", ".yaml", ".yml", ".toml", ".js", ".html", ".json", ".cfg", ".txt"}
SKIP_TOP = {".git", ".venv", "build", "dist", "runs", "campaigns", ".ci"}  # outputs, tools, CI's own script
SKIP_ANY = {"node_modules", "__pycache__"}


def _files() -> list[Path]:
    out = [ROOT / "Makefile"]
    for path in ROOT.rglob("*"):
        rel = path.relative_to(ROOT)
        if path.is_file() and path.suffix in SUFFIXES and rel.parts[0] not in SKIP_TOP \
                and not SKIP_ANY.intersection(rel.parts) and path != Path(__file__).resolve():
            out.append(path)
    return out


def test_no_outside_folder_work_period_or_issue_number() -> None:
    found = []
    files = _files()
    assert any(p.name == "README.md" for p in files) and len(files) > 100  # the scan saw the tree
    for path in files:
        for n, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            for what, pattern in PATTERNS.items():
                if pattern.search(line):
                    found.append(f"{path.relative_to(ROOT)}:{n}: {what}: {line.strip()[:100]}")
    assert not found, "\n".join(found)
