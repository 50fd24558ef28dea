"""The flight software's telecommands: NOOP, RESET_COUNTERS, SET_MODE, SET_TARGET, SET_GAINS.

`CommandHandlers.register` puts them on the dispatcher (`fsw.telecommand.CommandDispatcher`), which decodes,
authenticates and acknowledges each command; a handler acts on the flight software (`fsw.app.FlightSoftware`)
or refuses with `comms.telecommand.CommandValidationError`, whose code the rejection carries.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from comms.dictionary import MODES
from comms.telecommand import CommandValidationError, ground_target_of

_BODY_CODES = {"sun": "SUN", "moon": "MOON", "earth": "EARTH", "inertial": "INERTIAL"}


class CommandHandlers:
    """The handlers of ``fsw``'s telecommands."""

    def __init__(self, fsw: Any) -> None:
        self.fsw = fsw

    def register(self, dispatcher: Any) -> None:
        dispatcher.register("NOOP", self.noop)
        dispatcher.register("RESET_COUNTERS", self.reset_counters)
        dispatcher.register("SET_MODE", self.set_mode)
        dispatcher.register("SET_TARGET", self.set_target)
        dispatcher.register("SET_GAINS", self.set_gains)

    def noop(self) -> None:
        return None

    def reset_counters(self) -> None:
        fsw = self.fsw
        fsw.executive.reset_counters()
        fsw.fdir.reset_counters()
        if hasattr(fsw.telemetry, "reset_counters"):
            fsw.telemetry.reset_counters()
        if fsw.dispatcher is not None:
            fsw.dispatcher.reset_counters()
        fsw.event("COUNTERS_RESET")

    def set_mode(self, mode: Any) -> None:
        mode = str(mode)
        if mode not in MODES:
            raise CommandValidationError(f"SET_MODE: unknown mode {mode!r}")
        if mode == "DETUMBLE" and self.fsw.detumble is None:
            raise CommandValidationError("SET_MODE: DETUMBLE is not configured on board (flight_software.detumble)")
        self.fsw.set_mode(mode, "TELECOMMAND")

    def set_target(self, kind: Any, c0: float, c1: float, c2: float, c3: float = 0.0) -> None:
        """A unit direction (POINTING) or quaternion (QUATERNION); refused when not unit or inside a keep-out
        zone (TARGET_REJECTED names the zone and its body)."""
        fsw = self.fsw
        guidance = fsw.guidance
        kind = str(kind)
        if kind in ("NADIR", "GROUND"):
            self._set_target_on_earth(kind, c0, c1, c2, c3)
            return
        if kind == "DIRECTION":
            v = np.array([c0, c1, c2], dtype=float)
        else:
            v = np.array([c0, c1, c2, c3], dtype=float)
        n = float(np.linalg.norm(v))
        if not math.isfinite(n) or abs(n - 1.0) > 1e-3:
            raise CommandValidationError(f"SET_TARGET: {kind} must be a unit vector (norm {n:.6f})",
                                         "TARGET_NOT_UNIT")
        v = v / n
        self._refuse_in_zone(kind, v)
        if kind == "DIRECTION":
            guidance.set_target_direction(v)
        else:
            guidance.set_target_quaternion(v)
        fsw.restart_target_watch()
        c = list(v) + [0.0] * (4 - len(v))
        fsw.event("TARGET_SET", kind=kind, c0=c[0], c1=c[1], c2=c[2], c3=c[3])

    def _refuse_in_zone(self, kind: str, v: np.ndarray, on_earth: bool = False) -> None:
        """TARGET_REJECTED and a refusal when the target ``v`` lies inside a keep-out zone (``on_earth``: one
        that guards a target on the Earth)."""
        hit = self.fsw.guidance.target_violation(kind, v, on_earth)
        if hit is not None:
            zone, margin = hit
            bodies = self._zone_bodies(kind)
            self.fsw.event("TARGET_REJECTED", zone=zone, body=bodies[zone] if zone < len(bodies) else "INERTIAL",
                           margin_deg=margin)
            raise CommandValidationError(f"SET_TARGET: target inside keep-out zone {zone} (margin {margin:.3f} deg)",
                                         "TARGET_IN_KEEP_OUT")

    def _set_target_on_earth(self, kind: str, c0: float, c1: float, c2: float, c3: float) -> None:
        """NADIR, or a GROUND point (`comms.telecommand.ground_target_args`): followed every GNC cycle
        (`PointingGuidance.set_target_on_earth`); refused as a direction is when it lies in a zone now."""
        from fsw.config import GroundTargetConfig

        fsw, guidance = self.fsw, self.fsw.guidance
        ground = None
        if kind == "GROUND":
            lat, lon, alt = ground_target_of(c0, c1, c2, c3)
            if not -500.0 <= alt <= 9000.0:
                raise CommandValidationError(f"SET_TARGET: GROUND height {alt:.0f} m outside -500..9000 m",
                                             "ARG_OUT_OF_RANGE")
            ground = GroundTargetConfig(latitude_deg=lat, longitude_deg=lon, altitude_m=alt)
        self._refuse_in_zone("DIRECTION", guidance.target_on_earth_N(kind.lower(), ground), on_earth=True)
        guidance.set_target_on_earth(kind.lower(), ground)
        fsw.restart_target_watch()
        fsw.event("TARGET_SET", kind=kind, c0=c0, c1=c1, c2=c2, c3=c3)

    def _zone_bodies(self, kind: str) -> list[str]:
        guidance = self.fsw.guidance
        if kind == "DIRECTION":
            return [_BODY_CODES[s.body] for s in guidance.slots]
        return ["ATTITUDE"] * len(guidance.s3_law_zones)

    def set_gains(self, k1: float, kappa: float, eps: float, rate_limit_deg_s: float) -> None:
        """The law's gains; ``eps`` 0 lets the guidance choose it ("auto")."""
        try:
            self.fsw.guidance.set_gains(k1, kappa, "auto" if eps == 0 else eps, rate_limit_deg_s)
        except ValueError as exc:  # GainsRefused says why in its code; anything else is inadmissible gains
            raise CommandValidationError(f"SET_GAINS: {exc}", getattr(exc, "code", "GAINS_INADMISSIBLE")) from None
        self.fsw.event("GAINS_SET", k1=k1, kappa=kappa, eps=eps, rate_limit_deg_s=rate_limit_deg_s)
