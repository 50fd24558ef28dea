"""keepout as a product: what the wheel declares and ships, and the commands a new user runs first."""
from __future__ import annotations

import ast
import importlib.metadata
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from cli import main as cli

ROOT = Path(__file__).resolve().parents[2]
CODE_PACKAGES = ("cli", "gnc", "comms", "fsw", "ground", "hil_sim")
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())


def _declared() -> set[str]:
    return {re.split(r"[<>=!~\[; ]", d, maxsplit=1)[0].lower().replace("_", "-")
            for d in PYPROJECT["project"]["dependencies"]}


def _third_party_imports() -> dict[str, Path]:
    """Top-level modules imported anywhere in the code packages (module -> one file importing it)."""
    out: dict[str, Path] = {}
    for package in CODE_PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                names = []
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module]
                for name in names:
                    top = name.split(".")[0]
                    if top not in sys.stdlib_module_names and top not in (*CODE_PACKAGES, "keepout_config"):
                        out.setdefault(top, path)
    return out


def test_every_code_package_is_in_the_wheel():
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for package in CODE_PACKAGES
             for p in (ROOT / package).rglob("__init__.py")}
    found |= {".".join(("keepout_config", *p.relative_to(ROOT / "config").parts)) for p in
              (ROOT / "config").rglob("*") if p.is_dir() and p.name != "__pycache__"}
    assert found <= listed, f"packages missing from pyproject.toml [tool.setuptools] packages: {found - listed}"
    assert PYPROJECT["tool"]["setuptools"]["package-dir"]["keepout_config"] == "config"


def test_every_runtime_import_is_a_declared_dependency():
    """A wheel installed without extras must have every module the commands import; the optional parts
    (the Dask extra) are imported only inside the functions that need them."""
    distributions = importlib.metadata.packages_distributions()
    optional = {d.split(">")[0] for d in PYPROJECT["project"]["optional-dependencies"]["dask"]}
    declared = _declared()
    undeclared = {}
    for module, path in _third_party_imports().items():
        names = {n.lower().replace("_", "-") for n in distributions.get(module, [module])}
        if not names & declared and not names & optional:
            undeclared[module] = str(path.relative_to(ROOT))
    assert not undeclared, f"imported but not in [project] dependencies: {undeclared}"


def test_the_default_bus_needs_no_extra():
    """python-can's udp_multicast bus (the default where there is no vcan0) needs msgpack: a dependency."""
    assert "msgpack" in _declared()


def test_config_files_are_found_through_the_package():
    from comms.bus.icd import DEFAULT_DBC_PATH
    from hil_sim.campaign.spec import SCHEMA_PATH as CAMPAIGN_SCHEMA
    from hil_sim.mission.model import SCHEMA_PATH as MISSION_SCHEMA
    from hil_sim.sil.orchestrator import DEFAULT_MISSION
    from keepout_config import config_path

    for path in (DEFAULT_DBC_PATH, CAMPAIGN_SCHEMA, MISSION_SCHEMA, DEFAULT_MISSION,
                 config_path("telemetry_dictionary.json")):
        assert path.is_file(), path
        assert path.is_relative_to(config_path()), path


def test_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        cli.main(["--version"])
    assert exit_.value.code == 0
    assert capsys.readouterr().out.strip() == f"keepout {importlib.metadata.version('keepout')}"


def test_a_missing_optional_part_is_one_line_and_exit_3(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "distributed", None)  # as if the dask extra were not installed
    code = cli.main(["campaign", "run", str(ROOT / "config" / "campaigns" / "regression.yaml"), "--runs", "1",
                     "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path / "c"), "--no-report"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3
    assert err[-1] == ("keepout: this command needs the Python package 'distributed', which is not installed "
                       "(pip install 'keepout[dask]')")
    assert not any("Traceback" in line for line in err)


def test_init_writes_a_project_that_validates(tmp_path):
    import yaml

    from hil_sim.campaign.spec import load_campaign
    from hil_sim.mission.model import load_mission

    project = tmp_path / "sat"
    assert cli.main(["init", str(project)]) == 0
    mission = project / "missions" / "my-mission.yaml"
    campaign = project / "campaigns" / "my-campaign.yaml"
    assert load_mission(mission).name == "my-mission"
    load_campaign(campaign)
    assert yaml.safe_load(campaign.read_text())["base_mission"] == "../missions/my-mission.yaml"
    for path in (mission, campaign):  # each modeline names a schema file that init wrote
        schema = re.match(r"# yaml-language-server: \$schema=(\S+)", path.read_text()).group(1)
        assert (path.parent / schema).resolve().is_file(), (path, schema)


def test_init_refuses_a_non_empty_folder(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("mine")
    assert cli.main(["init", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"{tmp_path} is not empty" in err and "nothing was written" in err
    assert [p.name for p in tmp_path.iterdir()] == ["notes.txt"]


def _copy_source(dest: Path) -> Path:
    import shutil

    for name in (*CODE_PACKAGES, "config"):
        shutil.copytree(ROOT / name, dest / name, ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "node_modules"))
    (dest / "docs").mkdir()
    for doc in (ROOT / "docs").glob("*.md"):  # the wheel's keepout_docs
        shutil.copy(doc, dest / "docs" / doc.name)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, dest / name)
    return dest


@pytest.mark.slow
def test_the_built_wheel_runs_from_an_empty_folder(tmp_path):
    """Build the wheel, install it (no extras) into a fresh venv, and use it from an empty folder.

    The venv sees this environment's third-party packages through a .pth line (installing numpy, scipy,
    astropy ... again would take minutes; CI does the full install, .ci/run) but not its editable keepout:
    the keepout that runs is the wheel's, with the data files it carries."""
    import sysconfig
    import venv

    source = _copy_source(tmp_path / "src")
    build = subprocess.run([sys.executable, "-m", "pip", "wheel", "-v", "--no-deps", "-w", str(tmp_path / "dist"),
                            str(source)], check=True, timeout=600, capture_output=True, text=True)
    assert "Package would be ignored" not in build.stdout + build.stderr  # setuptools' data-folder warnings
    wheel = next((tmp_path / "dist").glob("keepout-*.whl"))
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=False)
    py = env_dir / "bin" / "python"
    site = subprocess.run([py, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    (Path(site) / "keepout-test-deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps", str(wheel)],
                   check=True, timeout=600)
    empty = tmp_path / "empty"
    empty.mkdir()
    keepout = env_dir / "bin" / "keepout"

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run([str(a) for a in args], cwd=empty, capture_output=True, text=True, timeout=300)

    version = run(keepout, "--version")
    assert version.returncode == 0 and version.stdout.strip() == "keepout 0.1.0", version
    where = run(py, "-c", "import hil_sim.sil.orchestrator as s, comms.bus.icd as i; print(s.DEFAULT_MISSION); "
                          "print(i.DEFAULT_DBC_PATH)")
    for line in where.stdout.split():
        assert Path(line).is_file() and Path(line).is_relative_to(env_dir), where
    installed = Path(run(py, "-c", "import keepout_config; print(keepout_config.config_path())").stdout.strip())
    shipped = {p.relative_to(source / "config") for p in (source / "config").rglob("*") if p.is_file()}
    missing = {p for p in shipped if not (installed / p).is_file() and p.suffix != ".pyc"}
    assert not missing, f"config files not in the wheel: {missing}"
    init = run(keepout, "init", "proj")
    assert init.returncode == 0, init
    # the mission-file reference, from the wheel's keepout_docs
    assert (empty / "proj" / "docs" / "missions.md").read_text() == (ROOT / "docs" / "missions.md").read_text()
    check = run(keepout, "config", "validate", "proj/missions/my-mission.yaml")
    assert check.returncode == 0 and "valid" in check.stdout, check
