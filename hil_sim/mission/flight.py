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

from fsw.config import BusConfig, FswConfig, FswRunConfig
from hil_sim.mission.model import Mission, load_mission


def flight_config(mission: Mission, *, bus_spec: str | None = None,
                  flight_software: dict[str, Any] | None = None) -> FswRunConfig:
    """The flight software's resolved configuration for ``mission``: its bus (``bus_spec``: the concrete
    spec the run opened, default the mission's) and its ``flight_software`` section (``flight_software``:
    that section as the caller adjusted it, e.g. the SIL's ports and clock, default the mission's)."""
    bus = BusConfig(spec=bus_spec if bus_spec is not None else mission.bus, bitrate_bps=mission.bus_bitrate_bps,
                    authentication=mission.bus_authentication)
    known = (mission.flight_software if flight_software is None
             else FswConfig.model_validate(flight_software))
    return FswRunConfig(bus=bus, flight_software=known)


def load_flight_config(path: str | Path) -> FswRunConfig:
    """The flight software's resolved configuration of the mission file ``path``; raises
    `hil_sim.mission.loader.ConfigError` listing every problem of the mission at its place."""
    return flight_config(load_mission(path))


def write_flight_config(path: Path, config: FswRunConfig, header: str = "") -> None:
    """Write ``config`` as the YAML file `fsw.config.load_fsw_run_config` reads (``header``: comment lines)."""
    text = yaml.safe_dump(config.model_dump(mode="json"), sort_keys=False, default_flow_style=None, width=110)
    path.write_text(header + text, encoding="utf-8")
