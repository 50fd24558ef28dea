"""``keepout init DIR``: a starter mission project for a user's own spacecraft.

DIR gets the layout of the package's own ``config/``, so the schema modelines (``$schema=../schema/...``)
of the copied files point at the schema files written beside them:

    DIR/missions/my-mission.yaml      the pointing demo, renamed: edit it for your spacecraft
    DIR/campaigns/my-campaign.yaml    its dispersed campaign (the release regression, renamed)
    DIR/schema/mission.schema.json    editor schemas (yaml-language-server), from the models
    DIR/schema/campaign.schema.json
    DIR/docs/missions.md              the mission-file reference: every key, its unit, range and default
    DIR/README.md                     the commands to check, run and disperse it, and where the keys are
"""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

MISSION_NAME = "my-mission"
CAMPAIGN_NAME = "my-campaign"
EXIT_BAD_DIR = 2  # as a rejected mission: the user's input (DIR) is not usable
REFERENCE = "missions.md"  # docs/missions.md, shipped in the wheel as keepout_docs/missions.md

README = f"""# A keepout mission project

- `missions/{MISSION_NAME}.yaml`: the mission (truth, flight software, timeline, requirements). An editor with
  the YAML language server completes and checks it against `schema/mission.schema.json`.
- `campaigns/{CAMPAIGN_NAME}.yaml`: dispersed runs of that mission.
- `docs/missions.md`: the mission-file reference (every key with its unit, range and default, and a worked
  example), the copy shipped with this keepout; `keepout config docs --out -` prints it again.

    keepout config check missions/{MISSION_NAME}.yaml        # validation and the physics checks
    keepout sil run missions/{MISSION_NAME}.yaml             # one SIL run, judged (runs/<id>/summary.json)
    keepout campaign run campaigns/{CAMPAIGN_NAME}.yaml --runs 4
"""


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    init = subparsers.add_parser(
        "init", help="write a starter mission project (mission, campaign, schemas) into a new folder",
        description="Write a starter mission project into DIR (which must not exist or be empty): a mission, "
                    "a campaign of it, and the JSON schemas their modelines point at.")
    init.add_argument("dir", type=Path, metavar="DIR")
    init.set_defaults(func=_init)


def _init(args: argparse.Namespace) -> int:
    target: Path = args.dir
    if target.exists() and (not target.is_dir() or any(target.iterdir())):
        what = "is not a folder" if not target.is_dir() else "is not empty"
        print(f"keepout init: {target} {what}: give a new or empty folder (nothing was written)", file=sys.stderr)
        return EXIT_BAD_DIR
    try:
        written = write_project(target)
    except OSError as exc:
        print(f"keepout init: {target}: cannot write: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_BAD_DIR
    for path in written:
        print(f"wrote {path}")
    return 0


def write_project(target: Path) -> list[Path]:
    """Write the starter project into ``target`` (created); returns the files written."""
    from hil_sim.campaign.spec import write_json_schema as write_campaign_schema
    from hil_sim.mission.model import write_json_schema as write_mission_schema
    from keepout_config import config_path

    mission = _renamed(config_path("missions", "demo-pointing.yaml").read_text(encoding="utf-8"), MISSION_NAME)
    campaign = _renamed(config_path("campaigns", "regression.yaml").read_text(encoding="utf-8"), CAMPAIGN_NAME)
    campaign = re.sub(r"(?m)^base_mission: .*$", f"base_mission: ../missions/{MISSION_NAME}.yaml", campaign)
    files = {target / "missions" / f"{MISSION_NAME}.yaml": mission,
             target / "campaigns" / f"{CAMPAIGN_NAME}.yaml": campaign,
             target / "README.md": README,
             target / "docs" / REFERENCE: docs_path(REFERENCE).read_text(encoding="utf-8")}
    written = []
    for path, text in files.items():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        written.append(path)
    written.append(write_mission_schema(target / "schema" / "mission.schema.json"))
    written.append(write_campaign_schema(target / "schema" / "campaign.schema.json"))
    return written


def _renamed(text: str, name: str) -> str:
    """The file with its top-level ``name:`` replaced (the modeline and comments kept)."""
    return re.sub(r"(?m)^name: .*$", f"name: {name}", text, count=1)


def docs_path(name: str) -> Path:
    """A file of the user documentation: the wheel's copy (package ``keepout_docs``, pyproject.toml), or
    ``docs/`` of a checkout that was never installed with it."""
    from importlib.resources import files

    try:
        # (iterdir, not joinpath: an editable install makes keepout_docs a namespace package, whose
        # MultiplexedPath refuses joinpath to a file on Python 3.11)
        installed = next((Path(str(p)) for p in files("keepout_docs").iterdir() if p.name == name), None)
    except (ModuleNotFoundError, OSError, ValueError):
        installed = None
    if installed is not None and installed.is_file():
        return installed
    return Path(__file__).resolve().parent.parent / "docs" / name
