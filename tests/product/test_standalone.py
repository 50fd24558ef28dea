"""The repository stands alone: no machine's folder in any file, no message pointing outside the package."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TEXT_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".toml", ".json", ".txt", ".cfg", ".dbc", ".js", ".html", ""}
# outside a git checkout: what is not the repository's own (environments, caches, run outputs, npm)
SKIP_DIRS = {".git", ".venv", "__pycache__", "build", "runs", "campaigns-out", ".pytest_cache", ".hypothesis",
             "node_modules"}


def _files():
    """The repository's files: git's list in a checkout (generated files are not committed), else a walk."""
    listed = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True)
    if listed.returncode == 0 and listed.stdout:
        paths = [ROOT / p for p in listed.stdout.decode().split("\0") if p]
    else:
        paths = [p for p in ROOT.rglob("*") if not SKIP_DIRS & set(p.relative_to(ROOT).parts)
                 and not p.relative_to(ROOT).parts[0].endswith(".egg-info")]
    for path in paths:
        if path.is_file() and path.suffix in TEXT_SUFFIXES and path.stat().st_size < 5_000_000:
            yield path


def test_no_file_names_a_folder_of_this_machine():
    machine_root = "/" + "work" + "/"  # spelled in two parts so this file does not match itself
    found = [str(p.relative_to(ROOT)) for p in _files() if machine_root in p.read_text(errors="replace")]
    assert not found, found


def test_the_tests_reference_data_is_in_the_repository():
    import importlib.util

    spec = importlib.util.spec_from_file_location("_test_dynamics", ROOT / "tests" / "hil_sim" / "test_dynamics.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    REF_DIR = module.REF_DIR
    assert REF_DIR == ROOT / "tests" / "data" / "basilisk"
    for name in ("rw_reference.csv", "rw_reference_imu.csv", "rw_reference_inputs.json", "README.md"):
        assert (REF_DIR / name).is_file(), name
    assert "Basilisk 2.12.1" in (REF_DIR / "README.md").read_text()


@pytest.mark.parametrize("message", ["transport", "conftest"])
def test_vcan_hints_name_commands_not_folders(message):
    if message == "transport":
        from comms.bus.transport import vcan_hint
        text = vcan_hint("vcan0")
    else:
        import conftest
        text = conftest.VCAN_HINT
    assert "modprobe vcan" in text and "ip link add dev vcan0 type vcan" in text
    assert "../" not in text and "shared" not in text and "vcan-vm" not in text
