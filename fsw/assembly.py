"""The composition root: the one place the flight software is put together.

`python -m fsw`, the campaigns' fast mode and the benches each bring their own bus, telemetry sink,
telecommand dispatcher and clock; `build_flight_software` adds the bus driver, looks up and builds the
plug-ins the configuration selects (`fsw.plugins`, ``flight_software.plugins``) and hands everything to
`fsw.app.FlightSoftware`. A plug-in is therefore installed the same way in a SIL run, a campaign and a
bench.
"""
from __future__ import annotations

import time
from typing import Any, Callable

from fsw.app import FlightSoftware
from fsw.plugins import Plugin, load


def selected_plugins(cfg: Any) -> list[Plugin]:
    """The plug-ins ``cfg.plugins`` names, built (`fsw.plugins.load`; raises `fsw.plugins.PluginError`)."""
    chosen = cfg.plugins
    return [load(kind, name, cfg) for kind, name in (("estimator", chosen.estimator), ("guidance", chosen.guidance))
            if name is not None]


def build_flight_software(cfg: Any, bus: Any = None, icd: Any = None, *, driver: Any = None, telemetry: Any = None,
                          dispatcher: Any = None, clock: Callable[[], float] = time.perf_counter) -> FlightSoftware:
    """The flight software configured by ``cfg`` (`fsw.config.FswConfig`) on ``bus`` (a python-can bus read
    through ``icd``, default the packaged ICD), or on a ready ``driver`` (a bench's or a test's).

    ``telemetry`` and ``dispatcher``: the TM sink and the TC dispatcher (None: events kept in memory, no
    telecommands); ``clock``: the executive's clock (the simulation's in fast mode, so runs reproduce)."""
    if driver is None:
        from fsw.bus import FswBusDriver
        from comms.bus import Icd

        driver = FswBusDriver(bus, icd if icd is not None else Icd(), len(cfg.spacecraft.wheels))
    return FlightSoftware(cfg, driver, telemetry, dispatcher, clock=clock, plugins=selected_plugins(cfg))


def plugin_metrics(fsw: FlightSoftware) -> dict[str, float]:
    """How much a run flew on its plug-ins: GNC cycles on the plug-in's command or estimate
    (``plugin_guidance_cycles``, ``plugin_estimator_cycles``) and plug-ins stopped by the guard
    (``plugin_stops``)."""
    out: dict[str, float] = {}
    stops = 0
    for kind, part, counter in (("guidance", fsw.guidance, "commands"), ("estimator", fsw.estimator, "updates")):
        if kind in fsw.plugins:
            out[f"plugin_{kind}_cycles"] = float(getattr(part, counter))
            stops += bool(part.stopped)
    out["plugin_stops"] = float(stops)
    return out
