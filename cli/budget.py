"""``keepout budget MISSION``: the disturbance and momentum budget of ``hil_sim.world.budget``, as a table."""
from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from pathlib import Path

import hil_sim.world.budget
from cli import description_of
from hil_sim.world.budget import budget

EXIT_REJECTED = 2  # the mission was refused (as `keepout config validate`)


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser("budget", help="disturbance and momentum budget per effect over an orbit and a day",
                              description=description_of(hil_sim.world.budget.__doc__),
                              formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("mission", type=Path, help="mission YAML")
    p.add_argument("--json", type=Path, default=None, metavar="FILE", help="also write the rows as JSON")
    p.set_defaults(func=_budget)


def _budget(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from hil_sim.mission.model import load_mission_or_report

    mission = load_mission_or_report(args.mission)
    if mission is None:
        return EXIT_REJECTED
    rows = budget(mission)
    table = Table(title=f"{mission.name}: disturbance and momentum budget (attitude held inertially)")
    for col in ("effect", "span", "peak torque [N m]", "H at end, body x y z [N m s]", "peak |H| [N m s]",
                "worst wheel [% of limit]"):
        table.add_column(col, justify="left" if col in ("effect", "span") else "right")
    for r in rows:
        table.add_row(r.effect, f"{r.span} ({r.span_s:,.0f} s)", f"{r.peak_torque_Nm:.3g}",
                      " ".join(f"{h:+.3g}" for h in r.momentum_end_B_Nms), f"{r.momentum_peak_Nms:.3g}",
                      f"{100 * r.wheel_speed_fraction:.1f}")
    console = Console()
    console.print(table)
    from hil_sim.world.environment import EFFECTS, environment_effects

    off = [name for name in EFFECTS if name not in environment_effects(mission)]
    if off:
        console.print("in the truth models but off in this mission (not counted): " + ", ".join(off))
    field = mission.spacecraft.disturbance.magnetic_field.summary()
    if "residual magnetic dipole" not in off:
        console.print(f"the Earth's magnetic field: {field} (spacecraft.disturbance.magnetic_field)")
    if args.json is not None:
        args.json.write_text(json.dumps({"mission": mission.name, "rows": [asdict(r) for r in rows],
                                         "off": off, "magnetic_field": field}, indent=1) + "\n")
    return 0
