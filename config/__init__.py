"""The project's data files (missions, campaigns, ICD, schemas, telemetry dictionary) as a package.

The folder ``config/`` of the repository is installed as the importable package ``keepout_config``
(``pyproject.toml``: ``package-dir``), so a wheel installed anywhere carries its default mission and
ICD. `config_path` is the one place the code finds these files; it lives here, not in ``fsw`` or
``hil_sim``, so that every package can use it (``fsw`` never imports ``hil_sim``).
"""
from __future__ import annotations

from importlib.resources import files
from pathlib import Path


def config_path(*parts: str) -> Path:
    """The installed file ``config/<parts...>`` (a real file: the package is never zipped)."""
    return Path(str(files(__name__).joinpath(*parts)))
