"""Plug-ins: a user's own guidance law or attitude estimator in place of keepout's (docs/plugins.md).

A plug-in is an installed Python distribution that registers a factory under one of two entry-point
groups:

* ``keepout.guidance``: ``factory(cfg) -> GuidanceLaw``, the law that turns the attitude estimate, the
  target and the keep-out zones into a body-rate command in POINTING and QUATERNION;
* ``keepout.estimator``: ``factory(cfg) -> Estimator``, the estimator that turns the cycle's gyro samples
  and star-tracker quaternion into the attitude estimate.

``cfg`` is the flight software's `fsw.config.FswConfig`. A mission selects plug-ins by entry-point name
under ``flight_software.plugins``; with none selected the flight software runs its own code only.

A plug-in is never trusted with keep-out: keepout's guidance still computes the keep-out margins every
cycle, its rate limit still applies to the plug-in's command, its FDIR still watches the margins, and a
guard (`fsw.plugin_guard`) stops a plug-in that steers towards a zone, fails or returns nonsense, then
puts the spacecraft in SAFE. A plug-in estimate is compared every cycle with keepout's own MEKF, which
keeps running beside it.

This module only looks plug-ins up (importlib.metadata); it imports no flight code, so the configuration
can check a mission's plug-in names without loading the guidance.
"""
from __future__ import annotations

from dataclasses import dataclass
from importlib.metadata import EntryPoint, entry_points
from typing import Any, Callable, Protocol, runtime_checkable

import numpy as np

GUIDANCE_GROUP = "keepout.guidance"
ESTIMATOR_GROUP = "keepout.estimator"
GROUPS = {"guidance": GUIDANCE_GROUP, "estimator": ESTIMATOR_GROUP}


@dataclass(frozen=True)
class GuidanceInput:
    """What a guidance law sees each cycle in POINTING or QUATERNION (never in SAFE, never without an
    attitude estimate). Frames and units as everywhere in keepout: quaternions scalar first, ``q_NB``
    rotates body vectors into the inertial frame N."""

    t_s: float                 # onboard time [s]
    dt_s: float                # GNC period [s]
    mode: str                  # "POINTING" (boresight on S^2) or "QUATERNION" (attitude on S^3)
    q_NB: np.ndarray           # estimated attitude (4,)
    omega_BN_B: np.ndarray     # estimated body rate [rad/s] (3,)
    boresight_B: np.ndarray    # the instrument boresight in body axes (3,)
    target_N: np.ndarray       # POINTING target direction (3,); NaN in QUATERNION
    q_target_NB: np.ndarray    # QUATERNION target attitude (4,); NaN in POINTING
    zones: tuple               # keep-out zones inflated by law.margin_deg, as gnc.zones objects on S^2 (POINTING)
                               # or S^3 (QUATERNION): zone.signed_separation(x) > 0 outside
    sun_N: np.ndarray          # onboard Sun direction (3,)
    moon_N: np.ndarray         # onboard Moon direction (3,)
    max_rate_rad_s: float      # the rate limit keepout applies to the command afterwards [rad/s]


@runtime_checkable
class GuidanceLaw(Protocol):
    """A guidance law plug-in."""

    def command(self, state: GuidanceInput) -> np.ndarray:
        """The body-rate command ``omega_cmd_BN_B`` [rad/s], shape (3,)."""
        ...


@dataclass(frozen=True)
class EstimatorInput:
    """One cycle's sensor samples, as the bus driver delivered and checked them."""

    dt_s: float                         # GNC period [s]
    gyro_B: np.ndarray                  # (n, 3) body rates [rad/s] sampled evenly over the cycle, the last now;
                                        # n = 0 when the IMU is silent
    q_NS: np.ndarray | None             # star-tracker attitude (unit, scalar first), None when no fresh valid fix
    star_tracker_latency_s: float       # age of that fix [s]
    q_BS: np.ndarray                    # star-tracker mounting: rotates sensor vectors into the body frame


@dataclass(frozen=True)
class AttitudeEstimate:
    q_NB: np.ndarray | None             # None while the estimator has no attitude yet
    omega_BN_B: np.ndarray              # body rate [rad/s] (3,)


@runtime_checkable
class Estimator(Protocol):
    """An attitude-estimator plug-in."""

    def update(self, sample: EstimatorInput) -> AttitudeEstimate:
        ...

    def reset(self) -> None:
        """Forget the attitude (FDIR's reset_estimator action)."""
        ...


class PluginError(ValueError):
    """A plug-in cannot be found, loaded or built; the message says which and what is installed."""


def _entry_points(group: str) -> dict[str, EntryPoint]:
    return {ep.name: ep for ep in entry_points(group=group)}


def installed(kind: str) -> list[str]:
    """Names registered in the entry-point group of ``kind`` ("guidance" or "estimator"), sorted."""
    return sorted(_entry_points(GROUPS[kind]))


def unknown_name_message(kind: str, name: str) -> str:
    """Why ``name`` cannot be selected as a ``kind`` plug-in, naming what is installed."""
    names = installed(kind)
    return (f"no {kind} plug-in named {name!r} is installed (entry-point group {GROUPS[kind]}); installed: "
            + (", ".join(names) if names else "none"))


@dataclass(frozen=True)
class Plugin:
    kind: str     # "guidance" or "estimator"
    name: str     # its entry-point name
    impl: Any     # the object its factory built


def load(kind: str, name: str, cfg: Any) -> Plugin:
    """Build the ``kind`` plug-in registered as ``name`` for the flight software configured by ``cfg``."""
    ep = _entry_points(GROUPS[kind]).get(name)
    if ep is None:
        raise PluginError(unknown_name_message(kind, name))
    try:
        factory: Callable[[Any], Any] = ep.load()
        impl = factory(cfg)
    except Exception as exc:  # noqa: BLE001 - whatever a user's package raises, reported as a load error
        raise PluginError(f"{kind} plug-in {name!r} ({ep.value}) failed to load: {type(exc).__name__}: {exc}") from exc
    method = "command" if kind == "guidance" else "update"
    if not callable(getattr(impl, method, None)):
        raise PluginError(f"{kind} plug-in {name!r} ({ep.value}) built a {type(impl).__name__}, which has no "
                          f"{method}() method (see fsw.plugins)")
    return Plugin(kind, name, impl)
