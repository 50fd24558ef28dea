"""The flight software's configuration, resolved from a mission: what `python -m fsw` is given.

The flight software cannot know it is simulated: it never reads a mission file, the truth's keys or their
defaults. The mission reader (`hil_sim.mission.model.load_mission`, every problem at file:line:col) has
already filled its knowledge in from the truth written in the file (`hil_sim.mission.knowledge`); here the
mission's bus keys join it, and the result is the flight software's own file (`fsw.config.FswRunConfig`),
which the SIL writes into the run folder and ``keepout fsw MISSION`` hands over in memory.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

from fsw.config import BusConfig, FswRunConfig
from hil_sim.mission.model import Mission, load_mission


def bus_config(mission: Mission, bus_spec: str | None = None) -> BusConfig:
    """The bus the flight software opens: ``bus_spec`` (the concrete spec a run opened) or the mission's,
    at the mission's bit rate and authentication."""
    return BusConfig(spec=bus_spec if bus_spec is not None else mission.bus, bitrate_bps=mission.bus_bitrate_bps,
                     authentication=mission.bus_authentication)


def flight_config(mission: Mission, bus_spec: str | None = None) -> FswRunConfig:
    """The flight software's resolved configuration for ``mission`` (its bus: `bus_config`)."""
    return FswRunConfig(bus=bus_config(mission, bus_spec), flight_software=mission.flight_software)


def load_flight_config(path: str | Path) -> FswRunConfig:
    """The flight software's resolved configuration of the mission file ``path``; raises
    `hil_sim.mission.loader.ConfigError` listing every problem of the mission at its place."""
    return flight_config(load_mission(path))


def write_flight_config(path: Path, bus: BusConfig, flight_software: dict[str, Any], header: str = "") -> None:
    """Write the YAML file `fsw.config.load_fsw_run_config` reads (``header``: comment lines).

    ``flight_software`` is a validated section as plain data (``model_dump(mode="json")``, adjusted as the
    caller needs), written as it is: validating it again here would normalise its unit vectors a second
    time, and the flight software must read exactly the numbers of the config used."""
    data = {"bus": bus.model_dump(mode="json"), "flight_software": flight_software}
    path.write_text(header + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=110),
                    encoding="utf-8")
