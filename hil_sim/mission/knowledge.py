"""The flight software's knowledge where a mission file does not give it: the truth written in the same file.

A mission writes each fact once. What the flight software believes of the spacecraft (epoch, inertia,
wheels, star-tracker mounting, boresight, orbit) defaults to the truth the file gives, with the truth's
key names; this module is the one place those names meet the flight software's. The flight software
itself never reads them: it gets its configuration resolved (`hil_sim.mission.flight`).
"""
from __future__ import annotations

import copy
import datetime as _dt
import math
from collections.abc import Callable
from typing import Any

# Where each piece of the flight software's knowledge comes from when the mission file does not give it under
# flight_software (`knowledge_from_truth` fills it in): knowledge key -> the truth key written once. The
# validator reports an error in such a copy at its truth key (hil_sim.mission.model); docs/missions.md lists the
# source as the key's default.
KNOWLEDGE_SOURCES: dict[tuple[str, ...], tuple[str, ...]] = {
    ("flight_software", "epoch_utc"): ("epoch_utc",),
    ("flight_software", "spacecraft", "inertia_B_kgm2"): ("spacecraft", "inertia_B_kgm2"),
    ("flight_software", "spacecraft", "wheels"): ("spacecraft", "wheels"),
    ("flight_software", "spacecraft", "star_tracker_q_BS"): ("spacecraft", "star_tracker", "q_BS"),
    ("flight_software", "spacecraft", "star_tracker_max_rate_deg_s"): ("spacecraft", "star_tracker", "max_rate_deg_s"),
    ("flight_software", "spacecraft", "imu_range_rad_s"): ("spacecraft", "imu", "saturation_rad_s"),
    ("flight_software", "pointing", "boresight_B"): ("spacecraft", "instrument_boresight_B"),
    ("flight_software", "pointing", "target_N"): ("initial_state", "ra_dec_deg"),
    ("flight_software", "orbit", "radius_km"): ("orbit", "semi_major_axis_km"),
    ("flight_software", "orbit", "inclination_deg"): ("orbit", "inclination_deg"),
    ("flight_software", "orbit", "raan_deg"): ("orbit", "raan_deg"),
    ("flight_software", "orbit", "arg_latitude_at_epoch_deg"): ("orbit", "arg_perigee_deg"),
    ("flight_software", "door", "close_time_s"): ("spacecraft", "door", "close_time_s"),
    ("flight_software", "door", "open_time_s"): ("spacecraft", "door", "open_time_s"),
    ("flight_software", "momentum_management", "magnetometer_q_BS"): ("spacecraft", "magnetometer", "q_BS"),
    ("flight_software", "momentum_management", "rod_axes_B"): ("spacecraft", "magnetorquers", "axes_B"),
    ("flight_software", "momentum_management", "max_dipole_Am2"): ("spacecraft", "magnetorquers", "max_dipole_Am2"),
    ("flight_software", "detumble", "magnetometer_q_BS"): ("spacecraft", "magnetometer", "q_BS"),
    ("flight_software", "detumble", "rod_axes_B"): ("spacecraft", "magnetorquers", "axes_B"),
    ("flight_software", "detumble", "max_dipole_Am2"): ("spacecraft", "magnetorquers", "max_dipole_Am2"),
    ("flight_software", "coarse_attitude", "normals_B"): ("spacecraft", "sun_sensors", "normals_B"),
    ("flight_software", "coarse_attitude", "full_scale_mA"): ("spacecraft", "sun_sensors", "full_scale_mA"),
    ("flight_software", "coarse_attitude", "field_of_view_half_angle_deg"): ("spacecraft", "sun_sensors",
                                                                            "field_of_view_half_angle_deg"),
    ("flight_software", "coarse_attitude", "magnetometer_q_BS"): ("spacecraft", "magnetometer", "q_BS"),
    ("flight_software", "coarse_attitude", "field_degree"): ("spacecraft", "disturbance", "magnetic_field"),
    ("flight_software", "coarse_attitude", "geomagnetic_gauss_T"): ("epoch_utc",),
}
# the sources that are not a plain copy of their truth key, as the docs say them
_KNOWLEDGE_NOTES = {
    ("flight_software", "spacecraft", "wheels"): "spacecraft.wheels (axis_B, max_torque_Nm, max_speed_rad_s, "
                                                 "spin_inertia_kgm2)",
    ("flight_software", "pointing", "target_N"): "initial_state.ra_dec_deg, when the initial attitude is given so",
    ("flight_software", "orbit", "arg_latitude_at_epoch_deg"): "orbit.arg_perigee_deg + orbit.mean_anomaly_deg",
    ("flight_software", "coarse_attitude", "field_degree"): "the truth's: 1 for spacecraft.disturbance."
                                                            "magnetic_field.model dipole, else its degree",
    ("flight_software", "coarse_attitude", "geomagnetic_gauss_T"): "IGRF-14's at epoch_utc to field_degree, when "
                                                                   "field_sigma_deg is given",
}
KNOWLEDGE_DEFAULTS = {".".join(k): _KNOWLEDGE_NOTES.get(k, ".".join(v)) for k, v in KNOWLEDGE_SOURCES.items()}
WHEEL_KNOWLEDGE_KEYS = ("axis_B", "max_torque_Nm", "max_speed_rad_s", "spin_inertia_kgm2")


def knowledge_from_truth(mission: dict) -> dict:
    """A copy of a mission file's data whose ``flight_software`` section holds, for every piece of
    knowledge the file does not give there, the truth the file gives (`KNOWLEDGE_DEFAULTS`): each fact is
    written once. The orbit knowledge is circular: radius = semi-major axis, argument of latitude =
    argument of perigee + mean anomaly. Keys given under ``flight_software`` are kept; values of the
    wrong kind are copied as they are, for validation to report."""
    out = copy.deepcopy(mission)
    fsw, sc, orbit, state = (out.get(k) for k in ("flight_software", "spacecraft", "orbit", "initial_state"))
    if not isinstance(fsw, dict):
        return out

    def fill(target: dict | None, key: str, value) -> None:
        if isinstance(target, dict) and key not in target and value is not None:
            target[key] = copy.deepcopy(value)

    def child(key: str) -> dict | None:
        value = fsw.setdefault(key, {})
        return value if isinstance(value, dict) else None

    fill(fsw, "epoch_utc", out.get("epoch_utc"))
    if isinstance(sc, dict):
        known = child("spacecraft")
        fill(known, "inertia_B_kgm2", sc.get("inertia_B_kgm2"))
        wheels = sc.get("wheels")
        if isinstance(wheels, list) and all(isinstance(w, dict) for w in wheels):
            renamed = [{**w, "spin_inertia_kgm2": w.get("spin_inertia_kgm2", w.get("Js_kgm2"))} for w in wheels]
            fill(known, "wheels", [{k: w[k] for k in WHEEL_KNOWLEDGE_KEYS if w.get(k) is not None} for w in renamed])
        if isinstance(sc.get("star_tracker"), dict):
            fill(known, "star_tracker_q_BS", sc["star_tracker"].get("q_BS"))
            fill(known, "star_tracker_max_rate_deg_s", sc["star_tracker"].get("max_rate_deg_s"))
        if isinstance(sc.get("imu"), dict):
            fill(known, "imu_range_rad_s", sc["imu"].get("saturation_rad_s"))
        fill(child("pointing"), "boresight_B", sc.get("instrument_boresight_B"))
        door = sc.get("door")
        if isinstance(door, dict) and fsw.get("door", {}) is not None:
            known_door = child("door")
            fill(known_door, "close_time_s", door.get("close_time_s"))
            fill(known_door, "open_time_s", door.get("open_time_s"))
        fitted = [k for k in ("magnetometer", "sun_sensors", "magnetorquers") if isinstance(sc.get(k), dict)]
        if fitted and fsw.get("magnetic_devices", {}) is not None:
            known_devices = child("magnetic_devices")
            for key in fitted:
                fill(known_devices, key, True)
        if isinstance(sc.get("magnetometer"), dict) and isinstance(sc.get("magnetorquers"), dict):
            # what the laws on the rods need of the devices, when both are fitted (detumble only when configured)
            laws = ["momentum_management"] + (["detumble"] if isinstance(fsw.get("detumble"), dict) else [])
            for law in laws:
                known_rods = child(law)
                fill(known_rods, "magnetometer_q_BS", sc["magnetometer"].get("q_BS"))
                fill(known_rods, "rod_axes_B", sc["magnetorquers"].get("axes_B"))
                fill(known_rods, "max_dipole_Am2", sc["magnetorquers"].get("max_dipole_Am2"))
        if isinstance(fsw.get("coarse_attitude"), dict):
            _coarse_attitude_knowledge(child("coarse_attitude"), sc, out.get("epoch_utc"), fill)
    if isinstance(state, dict) and "q_NB" not in state and _is_ra_dec(state.get("ra_dec_deg")):
        ra, dec = (math.radians(float(a)) for a in state["ra_dec_deg"])
        # hold the initial pointing until the first SET_TARGET
        fill(child("pointing"), "target_N", [math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])
    if isinstance(orbit, dict):
        known_orbit = child("orbit")
        fill(known_orbit, "radius_km", orbit.get("semi_major_axis_km"))
        fill(known_orbit, "inclination_deg", orbit.get("inclination_deg"))
        fill(known_orbit, "raan_deg", orbit.get("raan_deg"))
        omega, anomaly = orbit.get("arg_perigee_deg", 0.0), orbit.get("mean_anomaly_deg", 0.0)
        if _finite(omega) and _finite(anomaly):
            fill(known_orbit, "arg_latitude_at_epoch_deg", (float(omega) + float(anomaly)) % 360.0)
    return out


def _coarse_attitude_knowledge(known: dict, sc: dict, epoch: Any, fill: Callable[..., None]) -> None:
    """What the coarse attitude knows of the cells and the magnetometer (the spacecraft's as built) and of the
    field (IGRF-14's at the epoch to the truth's degree, when it uses the magnetometer)."""
    css = sc.get("sun_sensors")
    if isinstance(css, dict):
        for key in ("normals_B", "full_scale_mA", "field_of_view_half_angle_deg"):
            fill(known, key, css.get(key))
    mag = sc.get("magnetometer")
    if isinstance(mag, dict):
        fill(known, "magnetometer_q_BS", mag.get("q_BS"))
    field = (sc.get("disturbance") or {}).get("magnetic_field") if isinstance(sc.get("disturbance"), dict) else None
    if isinstance(field, dict):
        fill(known, "field_degree", 1 if field.get("model", "dipole") == "dipole" else field.get("degree", 13))
    degree = known.get("field_degree", 1)
    if known.get("field_sigma_deg") is not None and "geomagnetic_gauss_T" not in known and isinstance(degree, int):
        when = _epoch(epoch)
        if when is not None and 1 <= degree <= 13:
            from hil_sim.world.geomagnetic import gauss_coefficients_T

            fill(known, "geomagnetic_gauss_T", [list(pair) for pair in gauss_coefficients_T(when, degree)])


def _epoch(value: Any) -> _dt.datetime | None:
    """The mission's epoch as a UTC datetime (None when it is not one: the schema reports it)."""
    if isinstance(value, _dt.datetime):
        return value if value.tzinfo else value.replace(tzinfo=_dt.timezone.utc)
    try:
        parsed = _dt.datetime.fromisoformat(str(value).replace("Z", "+00:00"))
    except ValueError:
        return None
    return parsed if parsed.tzinfo else parsed.replace(tzinfo=_dt.timezone.utc)


def _finite(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_ra_dec(value) -> bool:
    return (isinstance(value, (list, tuple)) and len(value) == 2 and all(_finite(v) for v in value)
            and 0.0 <= value[0] <= 360.0 and -90.0 <= value[1] <= 90.0)
