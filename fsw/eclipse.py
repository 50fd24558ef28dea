"""Onboard eclipse knowledge: whether the spacecraft is in the Earth's shadow, from the flight software's
own ephemeris and orbit (`gnc.sky_ephemeris.SkyEphemeris.sunlit_fraction`: the truth's conical umbra and
penumbra, `gnc.eclipse`, on the onboard Sun and circular orbit). The housekeeping rate group updates it:
the HK packet carries the state and the sunlit fraction, and ECLIPSE_ENTRY / ECLIPSE_EXIT mark the shadow's
edges (at most one housekeeping period late).

Only a flight software that knows its orbit has it: a configuration that gives ``orbit`` (every mission's
does, from the truth's elements). Without one the state is UNKNOWN, the fraction NaN and no event is raised.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

from comms.dictionary import ECLIPSE_STATES
from gnc.sky_ephemeris import SkyEphemeris


def shadow_state(fraction: float) -> str:
    """The ECLIPSE_STATES name of a sunlit fraction: SUNLIT at 1 (the whole disc), UMBRA at 0, else PENUMBRA;
    UNKNOWN for NaN (no orbit)."""
    if fraction != fraction:
        return ECLIPSE_STATES[0]
    if fraction >= 1.0:
        return "SUNLIT"
    return "UMBRA" if fraction <= 0.0 else "PENUMBRA"


class EclipseMonitor:
    """The Earth's shadow as the flight software knows it; `update` once per housekeeping period."""

    def __init__(self, cfg: Any, event: Callable[..., None], ephem: SkyEphemeris | None = None) -> None:
        """``ephem``: the flight software's onboard ephemeris (the guidance's), so the shadow and the zones
        come from one Sun and one orbit; built from ``cfg`` when not given."""
        knows_orbit = "orbit" in cfg.model_fields_set
        self.ephem = (ephem if ephem is not None else SkyEphemeris(cfg)) if knows_orbit else None
        self.event = event
        self.state = ECLIPSE_STATES[0]
        self.fraction = math.nan
        self._entered_t: float | None = None  # when the shadow began (None: in full Sun, or not known)
        self._least = math.nan  # the least sunlit fraction since then

    def update(self, t_s: float) -> None:
        """The state at onboard time ``t_s``, and ECLIPSE_ENTRY / ECLIPSE_EXIT when it crosses the shadow's
        outer edge (the penumbra's). Starting in the shadow counts as entering it."""
        if self.ephem is None:
            return
        fraction = self.ephem.sunlit_fraction(t_s)
        self.fraction, self.state = fraction, shadow_state(fraction)
        if fraction < 1.0:
            if self._entered_t is None:
                self._entered_t, self._least = t_s, fraction
                self.event("ECLIPSE_ENTRY", sunlit_fraction=fraction)
            self._least = min(self._least, fraction)
        elif self._entered_t is not None:
            self.event("ECLIPSE_EXIT", duration_s=t_s - self._entered_t, least_sunlit_fraction=self._least)
            self._entered_t = None

    def values(self) -> dict[str, Any]:
        """The HK packet's eclipse channels."""
        return {"eclipse_state": self.state, "sunlit_fraction": self.fraction}
