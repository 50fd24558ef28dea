"""The arrows that must never exist (read from the source): fsw -> ground, fsw -> hil_sim, ground -> hil_sim,
the contract (comms) -> any of its ends, any library package -> the command line (cli) but an entry shim; the library packages
that parse no arguments (argparse lives in cli); and what ground and the simulator may still take from the
flight software besides the contract, each named with its reason."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _imports(package: str):
    """(imported module as written, importing file) of every absolute import in ``package``; ``from fsw
    import config`` counts as ``fsw.config``."""
    for path in sorted((ROOT / package).rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module] if "." in node.module else [f"{node.module}.{a.name}" for a in node.names]
            else:
                continue
            for name in names:
                yield name, str(path.relative_to(ROOT))


def _imported_top_packages(package: str) -> dict[str, set[str]]:
    """Top-level package of every import in every module of ``package`` -> the modules that import it."""
    found: dict[str, set[str]] = {}
    for name, where in _imports(package):
        found.setdefault(name.split(".")[0], set()).add(where)
    return found


# The only imports of cli a library package may hold, each with its reason: an entry shim, nothing else in it.
ENTRY_SHIMS = {
    ("cli.fsw", "fsw/__main__.py"): "python -m fsw is the flight process the SIL launches; its arguments are the "
                                    "flight software's command line, which lives in cli like every other",
}


@pytest.mark.parametrize(("package", "forbidden"), [
    ("fsw", "ground"), ("fsw", "hil_sim"), ("ground", "hil_sim"),
    # the command line sits on top: no library package holds or reaches for it
    ("gnc", "cli"), ("comms", "cli"), ("fsw", "cli"), ("ground", "cli"), ("hil_sim", "cli"),
])
def test_package_never_imports_the_forbidden_one(package: str, forbidden: str) -> None:
    found = [(name, where) for name, where in _imports(package) if (name, where) not in ENTRY_SHIMS]
    assert found, f"no imports found under {package}/: the scan is broken"
    stray = sorted(where for name, where in found if name.split(".")[0] == forbidden)
    assert not stray, f"{package} imports {forbidden} in {stray}"


@pytest.mark.parametrize(("module", "where"), list(ENTRY_SHIMS))
def test_an_entry_shim_only_hands_over_to_the_command_line(module: str, where: str) -> None:
    """A shim (ENTRY_SHIMS) imports its cli module and calls its main, and holds nothing else."""
    tree = ast.parse((ROOT / where).read_text(encoding="utf-8"))
    body = [node for node in tree.body if not (isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant))]
    assert len(body) == 2, f"{where}: a shim is an import and a call, got {len(body)} statements"
    imported, call = body
    assert isinstance(imported, ast.ImportFrom) and imported.module == module
    assert [a.name for a in imported.names] == ["main"]
    assert "main()" in ast.unparse(call)


@pytest.mark.parametrize("package", ["gnc", "comms", "fsw", "ground", "hil_sim"])
def test_library_package_parses_no_arguments(package: str) -> None:
    imports = _imported_top_packages(package)
    assert imports, f"no imports found under {package}/: the scan is broken"
    assert "argparse" not in imports, (
        f"{package} imports argparse in {sorted(imports['argparse'])}: its command line belongs in cli/")


def _imported_modules(package: str, top: str) -> dict[str, set[str]]:
    """Every module of package ``top`` that ``package`` imports (as written) -> the files importing it."""
    found: dict[str, set[str]] = {}
    for name, where in _imports(package):
        if name.split(".")[0] == top:
            found.setdefault(name, set()).add(where)
    return found


# What ground and the simulator may still take from the flight software, each for one reason. The contract
# they share (bus ICD and codec, TM/TC codecs, dictionary, link security) is comms; nothing else of fsw.
GROUND_FROM_FSW = {
    "fsw.config": "type annotations only (TYPE_CHECKING): the command line hands the console the run's flight "
                  "configuration, whose zones and wheels name its series",
}
SIMULATOR_FROM_FSW = {
    "fsw.config": "the mission's flight-software section is validated by the flight's own models",
    "fsw.guidance": "the mission validator applies the flight's own zone, edge and slew rules",
    "fsw.assembly": "the composition root: the fast mode and the SIL build the flight software through it",
    "fsw.lifetime": "a child process dies with its parent (the same rule for every process keepout starts)",
    "fsw.safe_yaml": "one YAML reader (limits on size, depth, aliases) for every mission file",
    "fsw.telecommand": "the fast mode feeds telecommands to the in-process flight software's dispatcher",
}


@pytest.mark.parametrize("forbidden", ["fsw", "ground", "hil_sim"])
def test_the_contract_depends_on_no_end(forbidden: str) -> None:
    imports = _imported_top_packages("comms")
    assert "comms" in imports, "no imports found under comms/: the scan is broken"
    assert forbidden not in imports, f"comms imports {forbidden} in {sorted(imports[forbidden])}"


@pytest.mark.parametrize(("package", "allowed"), [("ground", GROUND_FROM_FSW), ("hil_sim", SIMULATOR_FROM_FSW)])
def test_ground_and_simulator_take_only_the_contract_and_named_parts_of_fsw(package: str, allowed: dict[str, str]) -> None:
    used = _imported_modules(package, "fsw")
    stray = {m: sorted(files) for m, files in used.items()
             if not any(m == a or m.startswith(a + ".") for a in allowed)}
    assert not stray, f"{package} reaches into flight internals: {stray}"
    assert _imported_modules(package, "comms"), f"{package} takes nothing from comms: the scan is broken"


def _runtime_imports_of(package: str, prefix: str) -> list[str]:
    """Files of ``package`` that import ``prefix`` when they run (imports under ``if TYPE_CHECKING:`` left out)."""
    found = []
    for path in sorted((ROOT / package).rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        typing_only = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                       and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
        for node in ast.walk(tree):
            if id(node) in typing_only:
                continue
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module] if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module else [])
            if any(n == prefix or n.startswith(prefix + ".") for n in names):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    return found


def test_the_ground_runs_without_the_flight_software() -> None:
    assert not _runtime_imports_of("ground", "fsw"), _runtime_imports_of("ground", "fsw")
    assert _runtime_imports_of("hil_sim", "fsw"), "the simulator builds the flight software: the scan is broken"
