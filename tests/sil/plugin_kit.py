"""Plug-ins for the tests, made visible to `importlib.metadata` the way an installed distribution is: a
``*.dist-info`` folder with METADATA and entry_points.txt beside the package, on the path (``sys.path`` in
this process, PYTHONPATH for the SIL's and the campaign's processes). The example package's entry points
are read from its own pyproject.toml, so the test flies what a ``pip install`` would register."""
from __future__ import annotations

import os
import sys
import tomllib
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "keepout-example-plugin"


def write_distribution(site: Path, name: str, entry_points: dict[str, dict[str, str]]) -> Path:
    """A ``name`` distribution in ``site`` registering ``entry_points`` ({group: {name: "module:attr"}})."""
    dist = site / f"{name.replace('-', '_')}-0.1.0.dist-info"
    dist.mkdir(parents=True, exist_ok=True)
    (dist / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 0.1.0\n")
    (dist / "entry_points.txt").write_text("".join(
        f"[{group}]\n" + "".join(f"{k} = {v}\n" for k, v in eps.items()) + "\n" for group, eps in entry_points.items()))
    return site


def example_site(site: Path) -> list[Path]:
    """The example package registered in ``site``: the path entries that make it importable."""
    project = tomllib.loads((EXAMPLE / "pyproject.toml").read_text())["project"]
    write_distribution(site, project["name"], project["entry-points"])
    return [site, EXAMPLE]


def use_paths(monkeypatch, paths: list[Path]) -> None:
    """``paths`` on this process's path and on PYTHONPATH for the processes it starts."""
    for p in reversed(paths):
        monkeypatch.syspath_prepend(str(p))
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(p) for p in paths] + [os.environ.get("PYTHONPATH", "")]))


def short_mission(path: Path, duration_s: float, target_ra_dec: list[float] | None = None, **plugins: str) -> Path:
    """demo-pointing shortened to ``duration_s``, with one slew (clear of the zones along its great circle)
    and the ``plugins`` selected; written to ``path``."""
    data = yaml.safe_load((ROOT / "config" / "missions" / "demo-pointing.yaml").read_text())
    data["duration_s"] = duration_s
    data["timeline"] = [{"t_s": 10.0, "command": "SET_TARGET", "ra_dec_deg": target_ra_dec or [310.0, -25.0]}]
    if plugins:
        data["flight_software"]["plugins"] = plugins
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def loaded_plugin_modules() -> None:
    """Forget plug-in modules imported by an earlier test (each test registers its own)."""
    for name in [m for m in sys.modules if m.startswith(("keepout_example_plugin", "bad_plugins"))]:
        del sys.modules[name]
