"""The mission file: everything one SIL run needs, as pydantic v2 models.

A mission YAML holds the TRUTH (the spacecraft as built, its orbit, the epoch, the initial state, the
faults to inject), how to run it (bus, duration, seed, rates), the ground's timeline of telecommands,
the requirements a run is judged against, and, under ``flight_software:``, the flight software's own
configuration (``fsw.config.FswConfig``: what the spacecraft *believes*, its zones, laws and limits).
The flight software reads only that key, resolved (`hil_sim.mission.flight`; it never imports hil_sim).

Conventions: quaternions scalar first [eta, q1, q2, q3], ``q_NB`` rotates body vectors into the
inertial frame N (GCRS/J2000 equatorial); ``omega_BN_B`` is the body rate relative to N in body
components. Every physical key carries its unit in its name (``_deg``, ``_s``, ``_Nm``, ...).
"""
from __future__ import annotations

import math
import sys
from datetime import datetime, timezone
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, ClassVar, Literal, Union

import numpy as np
from pydantic import AfterValidator, AliasChoices, BaseModel, ConfigDict, Field, field_validator, model_validator

from comms.bus.transport import CAN_BITRATE_RANGE_BPS
from comms.dictionary import MAX_WHEELS
from fsw.config import FswConfig, GroundTargetConfig
from comms.dictionary import FDIR_MONITORS
from gnc.ephemeris import EARTH_RADIUS_KM
from hil_sim.devices.faults import DOOR_MESSAGES, WHEEL_MESSAGE
from hil_sim.mission.knowledge import KNOWLEDGE_SOURCES, knowledge_from_truth
from hil_sim.world.sun_sensors import CUBE_FACES_B
from keepout_config import config_path

if TYPE_CHECKING:
    from hil_sim.world.params import WorldParams
    from hil_sim.mission.loader import Marked

SCHEMA_VERSION = 1

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]


def bounded_vec3(limit: float) -> Any:
    """A 3-vector whose components lie in [-limit, limit] (a physical range: NaN, inf and 1e300 are refused)."""
    return Annotated[list[Annotated[float, Field(ge=-limit, le=limit)]], Field(min_length=3, max_length=3)]


RaDec = Annotated[tuple[Annotated[float, Field(ge=0, le=360)], Annotated[float, Field(ge=-90, le=90)]],
                  Field(description="[right ascension in [0, 360], declination in [-90, 90]] [deg]")]
MAX_INERTIA_KGM2 = 1e9  # the ISS is ~1e8 kg m^2
Matrix3 = Annotated[list[bounded_vec3(MAX_INERTIA_KGM2)], Field(min_length=3, max_length=3)]
UnitVec3 = Annotated[list[float], Field(min_length=3, max_length=3,
                                        description="direction (normalised on load)"),
                     AfterValidator(lambda v: _unit_vector(v))]
UnitQuat = Annotated[list[float], Field(min_length=4, max_length=4,
                                        description="unit quaternion, scalar first [eta, q1, q2, q3]"),
                     AfterValidator(lambda v: _unit_quaternion(v))]

FdirMonitor = Literal[FDIR_MONITORS]  # type: ignore[valid-type]  (the telemetry dictionary's monitors)
# auto, the loopback transports, or any python-can interface as INTERFACE:CHANNEL[,KEY=VALUE...] (checked
# further by comms.bus.transport.resolve_spec when the run starts)
BUS_PATTERN = (r"^(auto|socketcan(:[A-Za-z0-9_]+)?|udp_multicast(:[0-9a-fA-F.:]+:[0-9]+)?|virtual(:[A-Za-z0-9_]+)?"
               r"|[a-z0-9_]+:[^\s,]+(,[A-Za-z_][A-Za-z0-9_]*=[^\s,]+)*)$")


class _Model(BaseModel):
    # allow_inf_nan=False: NaN and inf never reach the truth models (they would crash a run mid-way)
    model_config = ConfigDict(extra="forbid", validate_default=True, allow_inf_nan=False)


def _unit_vector(values: list[float], what: str = "a direction") -> list[float]:
    norm = math.sqrt(sum(v * v for v in values))
    if not norm > 1e-9 or not math.isfinite(norm):
        raise ValueError(f"{what} must be a non-zero finite vector")
    return [v / norm for v in values]


def _unit_quaternion(values: list[float]) -> list[float]:
    norm = math.sqrt(sum(v * v for v in values))
    if not math.isfinite(norm) or abs(norm - 1.0) > 1e-3:
        raise ValueError(f"quaternion norm is {norm:.6g}; give a unit quaternion (|q| within 1e-3 of 1), "
                         "scalar first [eta, q1, q2, q3]")
    return [v / norm for v in values]


# ---------------------------------------------------------------------------------------------
# Spacecraft truth
# ---------------------------------------------------------------------------------------------

class WheelTruth(_Model):
    """One reaction wheel as built (maps onto hil_sim.world.params.WheelParams)."""

    axis_B: UnitVec3 = Field(description="spin axis in body axes (normalised on load)")
    spin_inertia_kgm2: float = Field(gt=0, le=10, validation_alias=AliasChoices("spin_inertia_kgm2", "Js_kgm2"),
                                     description="rotor inertia about its spin axis [kg m^2] (also accepted under "
                                     "its former name Js_kgm2)")
    max_torque_Nm: float = Field(gt=0, le=10, description="motor torque limit [N m]")
    max_speed_rad_s: float = Field(gt=0, le=1000, description="speed limit [rad/s] (6000 rpm = 628 rad/s)")
    viscous_friction_Nm_per_rad_s: float = Field(0.0, ge=0, le=1, description="viscous friction [N m s/rad]")
    coulomb_friction_Nm: float = Field(0.0, ge=0, le=1, description="Coulomb friction torque [N m]")
    failure: Literal["none", "stuck", "no_torque"] = Field(
        "none", description="none: healthy; stuck: seized bearing; no_torque: motor/driver dead")


class ImuTruth(_Model):
    """Rate gyro as built (maps onto hil_sim.world.params.ImuParams; axes are body axes)."""

    rate_hz: float = Field(100.0, gt=0, le=1000, description="sample rate [Hz]")
    angle_random_walk_rad_per_sqrt_s: float = Field(
        2.9e-6, ge=0, le=1e-2, description="white rate noise density (ARW) [rad/sqrt(s)]")
    bias_random_walk_rad_s_per_sqrt_s: float = Field(
        1e-7, ge=0, le=1e-3, description="bias random walk: std of the bias change over dt is this * sqrt(dt) "
        "[rad/s/sqrt(s)]")
    bias_B_rad_s: bounded_vec3(0.1) = Field([0.0, 0.0, 0.0], description="gyro bias at t=0 in body axes "
                                            "[rad/s], each within +-0.1 rad/s (5.7 deg/s)")
    bias_turn_on_std_rad_s: float = Field(4.8e-6, ge=0, le=1e-2, description="random turn-on bias added to "
                                          "bias_B_rad_s, 1-sigma per axis [rad/s]")
    scale_factor_ppm: bounded_vec3(1e5) = Field([0.0, 0.0, 0.0], description="scale-factor error per axis "
                                                "[ppm], each within +-1e5 ppm (10 %)")
    quantisation_rad_s: float = Field(1e-7, ge=0, le=1e-2, description="output resolution [rad/s]")
    saturation_rad_s: float = Field(0.35, gt=0, le=20, description="measurement range per axis [rad/s]")


class StarTrackerTruth(_Model):
    """Star tracker as built (maps onto hil_sim.world.params.StarTrackerParams)."""

    rate_hz: float = Field(10.0, gt=0, le=100, description="output rate [Hz]")
    cross_boresight_std_arcsec: float = Field(5.0, ge=0, le=3600, description="1-sigma noise about the two axes "
                                              "across the boresight [arcsec]")
    about_boresight_std_arcsec: float = Field(40.0, ge=0, le=36000, description="1-sigma roll noise [arcsec]")
    q_BS: UnitQuat = Field([1.0, 0.0, 0.0, 0.0], description="mounting: rotates sensor-frame vectors into body")
    boresight_S: UnitVec3 = Field([0.0, 0.0, 1.0], description="boresight in sensor axes")
    sun_exclusion_deg: float = Field(30.0, ge=0, lt=180, description="blinded when the Sun is this close [deg]")
    moon_exclusion_deg: float = Field(25.0, ge=0, lt=180, description="blinded when the Moon is this close [deg]")
    max_rate_deg_s: float = Field(2.0, gt=0, le=90, description="no solution above this body rate [deg/s]")


class MagneticField(_Model):
    """The Earth's main field the truth models use: for the residual dipole's torque, the magnetorquer rods'
    torque and the magnetometer (hil_sim.world.geomagnetic; docs/environment.md)."""

    model: Literal["dipole", "igrf"] = Field("dipole", description="dipole: IGRF-14's centred dipole (its "
                                             "degree-1 part) at the epoch, up to ~16,500 nT and 35 deg from the "
                                             "full field at 550 km; igrf: IGRF-14 to `degree` at the epoch "
                                             "(ppigrf's coefficients), for magnetometer and magnetorquer work")
    degree: int | None = Field(None, ge=1, le=13, description="highest degree of the igrf expansion (default 13: "
                               "all of IGRF-14's main field); only with model: igrf")

    @model_validator(mode="after")
    def _degree_is_igrfs(self) -> "MagneticField":
        if self.model == "dipole" and self.degree is not None:
            raise ValueError("degree applies to model: igrf (the dipole is IGRF's degree 1): set model: igrf "
                             "or remove degree")
        return self

    @property
    def igrf_degree(self) -> int:
        """The degree of the igrf expansion (13 unless given)."""
        return 13 if self.degree is None else self.degree

    def summary(self) -> str:
        """The field in words, for the commands that report what they used."""
        if self.model == "dipole":
            return "IGRF-14's centred dipole at the epoch"
        return f"IGRF-14 to degree {self.igrf_degree} at the epoch"


class Disturbance(_Model):
    """External torque on the spacecraft: constant plus first-order Gauss-Markov per body axis."""

    constant_B_Nm: bounded_vec3(1.0) = Field([0.0, 0.0, 0.0], description="constant torque in body axes [N m], "
                                             "each within +-1 N m")
    random_std_Nm: float = Field(0.0, ge=0, le=1, description="stationary 1-sigma of the random part [N m]")
    random_correlation_time_s: float = Field(60.0, ge=0, le=1e6, description="its correlation time [s] "
                                             "(0: white, redrawn every integration step)")
    gravity_gradient: bool = Field(False, description="add the gravity-gradient torque 3 mu / r^3 (u x I u) from the "
                                   "orbit and the true inertia (u: the Earth-to-spacecraft direction in body axes)")
    solar_radiation_pressure: bool = Field(False, description="add the solar-radiation-pressure torque on "
                                           "spacecraft.facets (hil_sim.world.environment), zero in the Earth's umbra and "
                                           "scaled by the sunlit fraction of the Sun's disc in the penumbra")
    solar_flux_W_m2: float = Field(1361.0, ge=1300, le=1420, description="solar flux at 1 AU [W/m^2] (1361: the "
                                   "total solar irradiance at solar minimum, Kopp & Lean 2011; it varies by ~0.1 % "
                                   "over a solar cycle and ~3 % over the year with the distance, which is modelled)")
    aerodynamic_drag: bool = Field(False, description="add the aerodynamic drag torque on spacecraft.facets "
                                   "(hil_sim.world.environment): an exponential atmosphere rotating with the Earth")
    atmosphere_density_kg_m3: float = Field(6.967e-13, gt=0, le=1e-6, description="the atmosphere's density at "
                                            "atmosphere_reference_altitude_km [kg/m^3] (default: 500 km, moderate "
                                            "solar activity, Vallado's table 8-4; it varies ~10x over a solar "
                                            "cycle at 550 km)")
    atmosphere_reference_altitude_km: float = Field(500.0, ge=100, le=2000, description="altitude of that "
                                                    "density above the equatorial radius [km]")
    atmosphere_scale_height_km: float = Field(63.822, gt=1, le=1000, description="scale height H: the density "
                                              "is that density times exp(-(h - reference altitude) / H) [km]")
    residual_dipole_B_Am2: bounded_vec3(1000.0) = Field([0.0, 0.0, 0.0], description="the spacecraft's residual "
                                                       "magnetic dipole in body axes [A m^2] (a CubeSat ~0.01-0.1, "
                                                       "a small satellite ~1); it feels m x B in the Earth's field, "
                                                       "a centred dipole from IGRF-14 at the epoch (ppigrf) turning "
                                                       "with the Earth (magnetic_field chooses). Zero: off")
    magnetic_field: MagneticField = Field(default_factory=MagneticField, description="the Earth's field for the "
                                          "dipole torques and the magnetometer (default: the centred dipole)")


class Facet(_Model):
    """One flat outer surface of the spacecraft, for the environment torques (maps onto
    hil_sim.world.params.FacetParams). Light not reflected (1 - specular - diffuse) is absorbed."""

    area_m2: float = Field(gt=0, le=1000, description="area [m^2]")
    normal_B: Vec3 = Field(description="outward unit normal in body axes (its norm within 1e-6 of 1: a normal "
                           "that is not one is a typing mistake, not a direction to normalise)")
    centre_of_pressure_B_m: bounded_vec3(100.0) = Field(description="centre of pressure (the facet's centroid) "
                                                        "from the centre of mass, in body axes [m]")
    specular: float = Field(0.0, ge=0, le=1, description="specular reflection coefficient")
    diffuse: float = Field(0.0, ge=0, le=1, description="diffuse reflection coefficient")
    drag_coefficient: float = Field(2.2, ge=0, le=10, description="drag coefficient C_D (2.0-2.5 for a flat "
                                    "plate in free-molecular flow)")

    @field_validator("normal_B")
    @classmethod
    def _unit_normal(cls, value: list[float]) -> list[float]:
        norm = math.sqrt(sum(v * v for v in value))
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"the normal's norm is {norm:.9g}; give the outward unit normal (norm within 1e-6 "
                             "of 1), e.g. [0.0, 0.0, 1.0]")
        return [v / norm for v in value]

    @model_validator(mode="after")
    def _optical(self) -> "Facet":
        if self.specular + self.diffuse > 1.0:
            raise ValueError(f"specular + diffuse = {self.specular + self.diffuse:g} exceeds 1: of the light a "
                             "facet receives, specular + diffuse is reflected and the rest absorbed; lower one of them")
        return self


class DoorTruth(_Model):
    """A protective aperture door in front of the instrument, as built (maps onto hil_sim.devices.nodes.DoorParams).
    Its drive is a CAN node: DOOR_CMD in, DOOR_STATUS out, every GNC tick."""

    close_time_s: float = Field(gt=0, le=600, description="full stroke, open to closed [s]")
    open_time_s: float = Field(gt=0, le=600, description="full stroke, closed to open [s]")
    initially_open: bool = Field(False, description="the door's position at t = 0 (false: closed, as after launch)")
    close_on_silence_s: float = Field(1.0, ge=0, le=60, description="the drive closes the door by itself after "
                                      "this long without a valid DOOR_CMD, once it has had one [s] (0: it holds "
                                      "its position)")


def _unit_normals(values: list[list[float]], what: str) -> list[list[float]]:
    """Each row a unit vector within 1e-6 (a vector that is not one is a typing mistake, not a direction to
    normalise), normalised exactly."""
    out = []
    for i, v in enumerate(values):
        norm = math.sqrt(sum(x * x for x in v))
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"{what} {i + 1} has norm {norm:.9g}; give a unit vector (norm within 1e-6 of 1), "
                             "e.g. [1.0, 0.0, 0.0]")
        out.append([x / norm for x in v])
    return out


class MagnetometerTruth(_Model):
    """A three-axis magnetometer as built (maps onto hil_sim.world.magnetic_devices.MagnetometerParams). Node MAG:
    MAG_FIELD every GNC tick."""

    q_BS: UnitQuat = Field([1.0, 0.0, 0.0, 0.0], description="mounting: rotates sensor-frame vectors into body")
    noise_std_T: float = Field(5e-8, ge=0, le=1e-5, description="1-sigma white noise per axis and sample [T] "
                               "(small-satellite magnetometers: 20-100 nT)")
    bias_S_T: bounded_vec3(1e-4) = Field([0.0, 0.0, 0.0], description="bias in sensor axes [T]")
    resolution_T: float = Field(0.0, ge=0, le=1e-6, description="the sensor's own quantisation [T] (0: none; "
                                "the bus carries 5 nT steps)")
    full_scale_T: float = Field(1e-4, gt=0, le=1.6e-4, description="clipping range +-full_scale_T [T] "
                                "(at most the bus's +-163.8 uT)")


class SunSensorsTruth(_Model):
    """Coarse sun sensor cells as built (maps onto hil_sim.world.sun_sensors.SunSensorParams). Node CSS:
    CSS_CURRENTS every GNC tick."""

    normals_B: list[Vec3] = Field([list(v) for v in CUBE_FACES_B], min_length=1, max_length=6, description="each cell's outward unit normal in "
                                  "body axes (norm within 1e-6 of 1), 1 to 6 cells (default: one on each face "
                                  "of a cube)")
    field_of_view_half_angle_deg: float = Field(90.0, gt=0, le=90, description="a cell sees the Sun within "
                                                "this angle of its normal [deg]")
    full_scale_mA: float = Field(1.0, gt=0, le=2.5, description="a cell's output at normal incidence in full "
                                 "Sun [mA] (the bus carries 0..2.55 mA)")
    noise_std_mA: float = Field(0.005, ge=0, le=0.5, description="1-sigma white noise per cell and sample [mA]")

    @field_validator("normals_B")
    @classmethod
    def _unit(cls, value: list[list[float]]) -> list[list[float]]:
        return _unit_normals(value, "cell normal")


class MagnetorquersTruth(_Model):
    """Three magnetorquer rods as built (maps onto hil_sim.world.magnetic_devices.MagnetorquerParams). Node MTQ:
    MTQ_COMMAND in, MTQ_STATUS out, every GNC tick; their torque m x B acts on the truth in the Earth's dipole
    field (IGRF at the epoch)."""

    axes_B: list[Vec3] = Field([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], min_length=3, max_length=3,
                               description="each rod's unit axis in body axes (norm within 1e-6 of 1)")
    max_dipole_Am2: list[Annotated[float, Field(gt=0, le=32)]] = Field(
        [0.2, 0.2, 0.2], min_length=3, max_length=3, description="each rod's saturation [A m^2], > 0 (a CubeSat "
        "rod ~0.2, a small satellite's ~10-30; the bus carries +-32.8 A m^2)")
    magnetometer_coupling_T_per_Am2: list[bounded_vec3(1e-3)] = Field(
        [[0.0] * 3] * 3, min_length=3, max_length=3, description="the rods' field at the magnetometer in body axes "
        "[T per A m^2], column j for rod j (as measured on the built spacecraft; zero: none)")
    cmd_timeout_s: float = Field(0.3, gt=0, le=60, description="the drive zeroes the rods after this long without "
                                 "a valid MTQ_COMMAND [s]")

    @field_validator("axes_B")
    @classmethod
    def _unit(cls, value: list[list[float]]) -> list[list[float]]:
        return _unit_normals(value, "rod axis")


class SpacecraftTruth(_Model):
    """The spacecraft as built (the flight software has its own, possibly imperfect, knowledge)."""

    inertia_B_kgm2: Matrix3 = Field(description="whole spacecraft with the wheels locked, about the centre of "
                                    "mass in body axes [kg m^2]")
    instrument_boresight_B: UnitVec3 = Field(description="the sensitive instrument's line of sight in body "
                                             "axes: the keep-out requirement is judged on this axis")
    wheels: list[WheelTruth] = Field(min_length=3, max_length=MAX_WHEELS)
    imu: ImuTruth = Field(default_factory=ImuTruth)
    star_tracker: StarTrackerTruth = Field(default_factory=StarTrackerTruth)
    disturbance: Disturbance = Field(default_factory=Disturbance)
    door: DoorTruth | None = Field(None, description="a protective aperture door in front of the instrument "
                                   "(absent: no door, nothing of it on the bus)")
    magnetometer: MagnetometerTruth | None = Field(None, description="a three-axis magnetometer (absent: none, "
                                                   "nothing of it on the bus)")
    sun_sensors: SunSensorsTruth | None = Field(None, description="coarse sun sensor cells (absent: none, "
                                                "nothing of them on the bus)")
    magnetorquers: MagnetorquersTruth | None = Field(None, description="three magnetorquer rods (absent: none, "
                                                     "nothing of them on the bus)")
    facets: list[Facet] = Field([], max_length=64, description="the outer surfaces, for the environment torques "
                                "(disturbance.solar_radiation_pressure, aerodynamic_drag); none: no such torque can "
                                "be computed")

    @field_validator("inertia_B_kgm2")
    @classmethod
    def _physical_inertia(cls, value: list[list[float]]) -> list[list[float]]:
        J = np.asarray(value, dtype=float)
        if not np.all(np.isfinite(J)):
            raise ValueError("inertia must be finite")
        if not np.allclose(J, J.T, rtol=1e-9, atol=1e-9 * max(1.0, float(np.abs(J).max()))):
            raise ValueError("inertia must be symmetric (J[i][j] == J[j][i])")
        eig = np.linalg.eigvalsh(J)
        if eig[0] <= 0:
            raise ValueError(f"inertia must be positive definite; principal moments are {np.round(eig, 6).tolist()}")
        if eig[0] + eig[1] < eig[2] * (1 - 1e-9):
            raise ValueError(f"principal moments {np.round(eig, 6).tolist()} violate the triangle inequality "
                             "(I1 + I2 >= I3): no rigid body has this inertia")
        return value



class Orbit(_Model):
    """Keplerian elements at the epoch (two-body truth orbit about the Earth in N)."""

    semi_major_axis_km: float = Field(gt=EARTH_RADIUS_KM, le=2.0e6, description="semi-major axis [km]")
    eccentricity: float = Field(0.0, ge=0, lt=1, description="eccentricity")
    inclination_deg: float = Field(0.0, ge=0, le=180, description="inclination [deg]")
    raan_deg: float = Field(0.0, ge=0, lt=360, description="right ascension of the ascending node [deg]")
    arg_perigee_deg: float = Field(0.0, ge=0, lt=360, description="argument of perigee [deg]")
    mean_anomaly_deg: float = Field(0.0, ge=0, lt=360, description="mean anomaly at the epoch [deg]")


class InitialState(_Model):
    """Truth state at t = 0."""

    q_NB: UnitQuat | None = Field(None, description="attitude, scalar first; rotates body vectors into N. Give "
                                  "either q_NB or ra_dec_deg (+ roll_deg)")
    ra_dec_deg: RaDec | None = Field(None, description="where the instrument boresight "
                                     "(spacecraft.instrument_boresight_B) points at t = 0, as [right ascension, "
                                     "declination] [deg], like a SET_TARGET; turned into q_NB on load")
    roll_deg: float = Field(0.0, ge=-360, le=360, description="with ra_dec_deg: rotation about the boresight [deg]; "
                            "0 turns body +x (body +y if the boresight is along x) as close to celestial north as "
                            "it goes, positive is right-handed about the boresight")
    omega_BN_B_rad_s: bounded_vec3(1.0) = Field([0.0, 0.0, 0.0], description="body rate [rad/s], each "
                                                "component within +-1 rad/s (57 deg/s)")
    wheel_speeds_rad_s: list[Annotated[float, Field(ge=-1000, le=1000)]] | None = Field(None, description="one per wheel [rad/s]; default all zero")

    @model_validator(mode="after")
    def _one_attitude(self) -> "InitialState":
        if self.q_NB is None and self.ra_dec_deg is None:
            raise ValueError("give the initial attitude as q_NB, or as ra_dec_deg (+ roll_deg)")
        if self.q_NB is not None and self.ra_dec_deg is not None:
            raise ValueError("give the initial attitude once: q_NB or ra_dec_deg (+ roll_deg), not both")
        return self



# ---------------------------------------------------------------------------------------------
# Ground timeline (telecommands sent by the ground monitor at simulated times)
# ---------------------------------------------------------------------------------------------

class _Timed(_Model):
    t_s: float = Field(ge=0, le=10 * 86400, description="simulated time at which the ground sends the telecommand [s]")


class SetModeCommand(_Timed):
    command: Literal["SET_MODE"]
    mode: Literal["SAFE", "POINTING", "QUATERNION", "DETUMBLE"]


class SetTargetCommand(_Timed):
    """A new target: a pointing direction (POINTING), fixed in N or on the rotating Earth (nadir, a ground
    point, followed every cycle), or an attitude (QUATERNION)."""

    command: Literal["SET_TARGET"]
    target_N: bounded_vec3(1e6) | None = Field(None, description="boresight target direction in N (POINTING), "
                                               "normalised when used")
    ra_dec_deg: RaDec | None = Field(
        None, description="target as [right ascension, declination] [deg] (POINTING): RA in [0, 360], "
        "Dec in [-90, 90]")
    nadir: Literal[True] | None = Field(None, description="true: the boresight to nadir (POINTING), the Earth's "
                                        "centre seen from the onboard orbit, followed every cycle")
    ground: GroundTargetConfig | None = Field(None, description="a point on the rotating Earth (POINTING), "
                                              "followed every cycle: WGS-84 latitude_deg, longitude_deg, "
                                              "altitude_m, and the min_elevation_deg the mission check wants it "
                                              "seen at during its dwell")
    q_target_NB: UnitQuat | None = Field(None, description="target attitude (QUATERNION)")

    TARGET_KEYS: ClassVar[tuple[str, ...]] = ("target_N", "ra_dec_deg", "nadir", "ground", "q_target_NB")

    def target_direction_N(self) -> np.ndarray | None:
        if self.target_N is not None:
            return np.asarray(_unit_vector(self.target_N, "target_N"))
        if self.ra_dec_deg is not None:
            return ra_dec_to_unit(*self.ra_dec_deg)
        return None


class SetGainsCommand(_Timed):
    command: Literal["SET_GAINS"]
    k1: float | None = Field(None, gt=0, le=100)
    kappa: float | None = Field(None, gt=0, le=100)
    eps: float | None = Field(None, gt=0, lt=1)
    rate_limit_deg_s: float | None = Field(None, gt=0, le=30)


class SimpleCommand(_Timed):
    command: Literal["NOOP", "RESET_COUNTERS"]


TimelineEntry = Annotated[Union[SetModeCommand, SetTargetCommand, SetGainsCommand, SimpleCommand],
                          Field(discriminator="command")]


# ---------------------------------------------------------------------------------------------
# Fault injection (hil_sim.devices.faults), requirements, run settings
# ---------------------------------------------------------------------------------------------

class BusFault(_Model):
    """A fault injected on the frames of one DBC message during [start_s, end_s), a failure of the aperture
    door's mechanism during that window (the door kinds), or (wheel_stuck, wheel_no_torque) the physical
    failure of the wheel of message RWn_CMD / RWn_STATUS from start_s on."""

    kind: Literal["drop", "delay", "duplicate", "corrupt", "stick_counter", "babble", "silent", "door_stuck_open",
                  "door_stuck_closed", "door_slow", "wheel_stuck", "wheel_no_torque"] = Field(
        description="a fault of the frames (drop ... silent), a failure of the aperture door's mechanism "
        "during the window (door_stuck_open: cannot close; door_stuck_closed: cannot open; door_slow: a stroke "
        "takes delay_s longer), or a wheel's mechanism failing for good (wheel_stuck: seized bearing; "
        "wheel_no_torque: dead motor or driver), see hil_sim.devices.faults")
    message: str = Field(description="DBC message name, e.g. IMU_RATE, ST_QUAT_A, RW2_STATUS (a door failure: "
                         "DOOR_STATUS or DOOR_CMD; a wheel failure: its wheel's RWn_CMD or RWn_STATUS)")
    start_s: float = Field(ge=0, le=10 * 86400, description="start of the fault window, simulated time [s]")
    end_s: float = Field(gt=0, le=10 * 86400, description="end of the fault window, simulated time [s]")
    delay_s: float | None = Field(None, gt=0, le=10, description="for kind=delay: extra latency; for "
                                  "kind=door_slow: extra time of a full stroke [s]")
    bit: int | None = Field(None, ge=0, le=63, description="for kind=corrupt: which payload bit to flip")
    probability: float = Field(1.0, gt=0, le=1, description="fraction of the frames in the window affected")


class Requirements(_Model):
    """What a run must achieve to pass (judged on truth by the simulator, not on the FSW's view)."""

    min_keepout_margin_deg: float = Field(0.0, ge=-90, le=90, description="every zone's minimum signed margin must exceed "
                                          "this [deg] (0: never inside a physical zone)")
    settling_tolerance_deg: float = Field(0.05, gt=0, le=10, description="settled when the truth pointing "
                                          "(or attitude) error stays below this [deg]")
    max_settling_time_s: float | None = Field(None, gt=0, le=10 * 86400, description="after the last target command [s]")
    max_final_pointing_error_deg: float = Field(0.05, gt=0, le=180, description="truth error at the end [deg]")
    max_wheel_speed_fraction: float = Field(0.9, gt=0, le=1, description="peak |wheel speed| / its limit")
    max_body_rate_fraction: float = Field(1.05, gt=0, le=10, description="peak true |omega| / the configured "
                                          "rate limit (5 % allows for sensor noise and sampling)")
    max_cycle_slips: int = Field(0, ge=0)
    expected_fdir_events: list[FdirMonitor] = Field(
        [], description="FDIR monitors that MUST trip during the run (the 'monitor' of FDIR_TRIPPED events, "
        "e.g. IMU_STALE): fault scenarios")
    max_unexpected_fdir_events: int = Field(0, ge=0, description="FDIR_TRIPPED events of monitors not listed in "
                                            "expected_fdir_events")
    max_instrument_exposure_s: float = Field(0.0, ge=0, le=10 * 86400, description="with a door (spacecraft.door): "
                                             "time the instrument may look into a physical sky zone with the door "
                                             "not fully closed, judged on truth [s]")
    max_detumble_time_s: float | None = Field(None, gt=0, le=10 * 86400, description="with initial_mode DETUMBLE: "
                                              "DETUMBLE_COMPLETE must be raised by this onboard time [s] "
                                              "(absent: not judged)")


class Simulation(_Model):
    dynamics_rate_hz: float = Field(100.0, gt=0, le=2000, description="truth integration rate (RK4) [Hz]")


class Mission(_Model):
    """One SIL mission: truth, run settings, ground timeline, requirements, and the flight software config."""

    schema_version: Literal[1] = Field(description="mission file format version (this is version 1)")
    name: str = Field(pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$", description="run folders are named after it")
    description: str = ""
    epoch_utc: datetime = Field(description="UTC time at t = 0, ISO 8601 with a zone, e.g. 2026-03-20T12:00:00Z")
    duration_s: float = Field(gt=0, le=10 * 86400, description="simulated duration [s]")
    seed: int = Field(0, ge=0, le=2**32 - 1, description="seed of every random process in the truth models")
    bus: str = Field("auto", pattern=BUS_PATTERN, description="auto (socketcan on vcan0 when it exists, else "
                     "udp_multicast) | socketcan[:IFACE] | udp_multicast[:GROUP:PORT] | virtual[:CHANNEL] | "
                     "INTERFACE:CHANNEL[,KEY=VALUE...] for a python-can hardware interface (pcan:PCAN_USBBUS1, "
                     "kvaser:0, slcan:/dev/ttyACM0, ...)")
    bus_bitrate_bps: int = Field(500000, ge=CAN_BITRATE_RANGE_BPS[0], le=CAN_BITRATE_RANGE_BPS[1], description="CAN bit rate [bit/s] a hardware "
                                 "interface (pcan, kvaser, vector, slcan, ...) is opened with; SocketCAN takes the "
                                 "kernel's setting, the loopback transports have none")
    bus_authentication: bool = Field(
        False, description="true: every batch of frames on the bus carries a SecOC-style authenticator (a MAC "
        "and a freshness value, keyed from the run's link key) and each end uses only the frames it "
        "authenticates: injected, forged and replayed frames are counted and dropped (docs/security.md). "
        "Applies to `keepout sil run` and `keepout fsw` / `keepout sim`; a fast-mode campaign flies in one "
        "process, with no bus to protect")
    tmtc_ports: Literal["auto", "fixed"] = Field(
        "auto", description="auto: the SIL picks free UDP ports for telemetry and telecommands for each run "
        "(parallel runs never collide) and writes them into the config it saves; fixed: use "
        "flight_software.tmtc as given")
    telemetry_link: Literal["multicast", "unicast"] = Field(
        "multicast", description="multicast: the flight software sends telemetry to a per-run multicast group on "
        "loopback, which the SIL's ground and any number of attached ground clients join (`keepout ground --run`); "
        "unicast: to flight_software.tmtc.telemetry_host only, as to a real ground station (one receiver)")
    simulation: Simulation = Field(default_factory=Simulation)
    spacecraft: SpacecraftTruth
    orbit: Orbit
    initial_state: InitialState
    timeline: list[TimelineEntry] = Field([], description="telecommands the ground sends, by simulated time")
    faults: list[BusFault] = Field([], description="faults to inject: on a message's frames, or a wheel's physical "
                                   "failure (wheel_stuck, wheel_no_torque)")
    requirements: Requirements = Field(default_factory=Requirements)
    flight_software: FswConfig = Field(description="the flight software's own configuration: what it knows of "
                                       "the spacecraft (epoch, inertia, wheels, star-tracker mounting, boresight "
                                       "and orbit default to the truth written above), its zones, laws and limits")

    @model_validator(mode="before")
    @classmethod
    def _written_once(cls, data: Any) -> Any:
        return written_once(data)

    @field_validator("epoch_utc")
    @classmethod
    def _aware(cls, value: datetime) -> datetime:
        if value.tzinfo is None:
            raise ValueError("give the epoch with a time zone, e.g. 2026-03-20T12:00:00Z")
        return value.astimezone(timezone.utc)

    # -- cross-field checks: reported with key paths, all at once, by the loader ----------------
    def semantic_problems(self) -> list[tuple[tuple[str | int, ...], str]]:
        """Problems that involve several keys (each with the key path it concerns), in the order of the
        mission file: flight software against truth, spacecraft, orbit, initial state, timeline, faults."""
        n_wheels = len(self.spacecraft.wheels)
        out = self._flight_software_problems(n_wheels) + self._spacecraft_problems() + self._orbit_problems()
        out += self._initial_speed_problems(n_wheels)
        for i, entry in enumerate(self.timeline):
            out += self._timeline_entry_problems(i, entry)
        if self.flight_software.door is not None and self.spacecraft.door is None:
            out.append((("flight_software", "door"), "the flight software drives a door the spacecraft does not "
                        "have: add spacecraft.door or remove flight_software.door"))
        known = self.flight_software.magnetic_devices
        for key in ("magnetometer", "sun_sensors", "magnetorquers"):
            if known is not None and getattr(known, key) and getattr(self.spacecraft, key) is None:
                out.append((("flight_software", "magnetic_devices", key), f"the flight software uses {key} the "
                            f"spacecraft does not have: add spacecraft.{key} or set this false"))
        times = [e.t_s for e in self.timeline]
        if times != sorted(times):
            out.append((("timeline",), "entries must be in increasing t_s order"))
        for i, fault in enumerate(self.faults):
            out += self._fault_problems(i, fault, n_wheels)
        return out

    def _flight_software_problems(self, n_wheels: int) -> list[tuple[tuple[str | int, ...], str]]:
        """Where the flight software's knowledge contradicts the truth: its epoch, its number of wheels."""
        out: list[tuple[tuple[str | int, ...], str]] = []
        fsw = self.flight_software
        if fsw.epoch_utc != self.epoch_utc:
            out.append((("flight_software", "epoch_utc"), f"the flight software's epoch {fsw.epoch_utc.isoformat()} "
                        f"differs from the mission epoch {self.epoch_utc.isoformat()}; give the same instant "
                        "(onboard time would be offset from truth)"))
        if len(fsw.spacecraft.wheels) != n_wheels:
            out.append((("flight_software", "spacecraft", "wheels"), f"the flight software knows "
                        f"{len(fsw.spacecraft.wheels)} wheels but the spacecraft has {n_wheels} "
                        "(spacecraft.wheels); each wheel is one RWn node on the bus"))
        return out

    def _spacecraft_problems(self) -> list[tuple[tuple[str | int, ...], str]]:
        """Wheel axes that cannot give every body torque; surface forces on a spacecraft without surfaces."""
        out: list[tuple[tuple[str | int, ...], str]] = []
        axes = np.asarray([w.axis_B for w in self.spacecraft.wheels])
        if np.linalg.matrix_rank(axes, tol=1e-6) < 3:
            out.append((("spacecraft", "wheels"), "the wheel axes do not span 3 axes: some body torques "
                        "cannot be produced"))
        dist = self.spacecraft.disturbance
        for key, what in (("solar_radiation_pressure", "solar radiation pressure"), ("aerodynamic_drag", "drag")):
            if getattr(dist, key) and not self.spacecraft.facets:
                out.append((("spacecraft", "disturbance", key), f"{what} acts on the spacecraft's surfaces: give "
                            "them as spacecraft.facets (area_m2, normal_B, centre_of_pressure_B_m, specular, "
                            "diffuse, drag_coefficient), or set it false"))
        return out

    def _orbit_problems(self) -> list[tuple[tuple[str | int, ...], str]]:
        """A perigee inside the atmosphere (below 150 km altitude)."""
        perigee_km = self.orbit.semi_major_axis_km * (1 - self.orbit.eccentricity)
        if perigee_km < EARTH_RADIUS_KM + 150:
            return [(("orbit",), f"perigee radius {perigee_km:.1f} km is below {EARTH_RADIUS_KM + 150:.0f} km "
                     "(150 km altitude): the orbit hits the atmosphere")]
        return []

    def _initial_speed_problems(self, n_wheels: int) -> list[tuple[tuple[str | int, ...], str]]:
        """Initial wheel speeds: one per wheel, each within its wheel's limit."""
        speeds = self.initial_state.wheel_speeds_rad_s
        if speeds is None:
            return []
        if len(speeds) != n_wheels:
            return [(("initial_state", "wheel_speeds_rad_s"), f"{len(speeds)} speeds given for {n_wheels} wheels")]
        return [(("initial_state", "wheel_speeds_rad_s", i), f"{s} rad/s exceeds wheel {i}'s limit {w.max_speed_rad_s} rad/s")
                for i, (s, w) in enumerate(zip(speeds, self.spacecraft.wheels)) if abs(s) > w.max_speed_rad_s]

    def _timeline_entry_problems(self, i: int, entry) -> list[tuple[tuple[str | int, ...], str]]:
        """Timeline entry ``i``: within the run; a SET_TARGET with one target; a SET_GAINS that sets something."""
        out: list[tuple[tuple[str | int, ...], str]] = []
        if entry.t_s > self.duration_s:
            out.append((("timeline", i, "t_s"), f"t_s = {entry.t_s} s is after the end of the run "
                        f"(duration_s = {self.duration_s} s)"))
        if isinstance(entry, SetTargetCommand):
            given = [k for k in entry.TARGET_KEYS if getattr(entry, k) is not None]
            if len(given) != 1:
                out.append((("timeline", i), "SET_TARGET needs exactly one of target_N, ra_dec_deg, nadir, "
                            f"ground, q_target_NB (got {', '.join(given) or 'none'})"))
        if isinstance(entry, SetModeCommand) and entry.mode == "DETUMBLE" and self.flight_software.detumble is None:
            out.append((("timeline", i, "mode"), "SET_MODE DETUMBLE needs the DETUMBLE mode configured: add "
                        "flight_software.detumble (with spacecraft.magnetometer, spacecraft.magnetorquers and, "
                        "with keep-out zones, spacecraft.door)"))
        if isinstance(entry, SetGainsCommand) and all(
                getattr(entry, k) is None for k in ("k1", "kappa", "eps", "rate_limit_deg_s")):
            out.append((("timeline", i), "SET_GAINS sets nothing: give at least one of k1, kappa, eps, "
                        "rate_limit_deg_s"))
        return out

    def _fault_problems(self, i: int, fault, n_wheels: int) -> list[tuple[tuple[str | int, ...], str]]:
        """Fault ``i``: its window, the parameter its kind needs, then its door and its wheel."""
        out: list[tuple[tuple[str | int, ...], str]] = []
        if fault.end_s <= fault.start_s:
            out.append((("faults", i, "end_s"), f"end_s ({fault.end_s}) must be after start_s ({fault.start_s})"))
        if fault.kind == "delay" and fault.delay_s is None:
            out.append((("faults", i), "kind 'delay' needs delay_s"))
        if fault.kind == "corrupt" and fault.bit is None:
            out.append((("faults", i), "kind 'corrupt' needs bit"))
        return out + self._door_fault_problems(i, fault) + self._wheel_fault_problems(i, fault, n_wheels)

    def _door_fault_problems(self, i: int, fault) -> list[tuple[tuple[str | int, ...], str]]:
        """A door failure (door_*) needs a door and names a door frame; a door frame needs a door."""
        out: list[tuple[tuple[str | int, ...], str]] = []
        if fault.kind.startswith("door_"):
            if self.spacecraft.door is None:
                out.append((("faults", i, "kind"), f"{fault.kind}: the spacecraft has no door (spacecraft.door)"))
            if fault.message not in DOOR_MESSAGES:
                out.append((("faults", i, "message"), f"{fault.message}: a door failure names a door frame, "
                            "DOOR_STATUS or DOOR_CMD"))
            if fault.kind == "door_slow" and fault.delay_s is None:
                out.append((("faults", i), "kind 'door_slow' needs delay_s (the extra stroke time)"))
        elif fault.message in DOOR_MESSAGES and self.spacecraft.door is None:
            out.append((("faults", i, "message"), f"{fault.message}: the spacecraft has no door (spacecraft.door)"))
        return out

    def _wheel_fault_problems(self, i: int, fault, n_wheels: int) -> list[tuple[tuple[str | int, ...], str]]:
        """A wheel's frame (RWn_CMD, RWn_STATUS) names a wheel the spacecraft has; a wheel failure names one."""
        wheel_message = WHEEL_MESSAGE.fullmatch(fault.message)
        if wheel_message:
            if int(wheel_message.group(1)) > n_wheels:
                return [(("faults", i, "message"), f"{fault.message}: the spacecraft has only {n_wheels} wheels")]
        elif fault.kind.startswith("wheel_"):
            return [(("faults", i, "message"), f"kind {fault.kind!r} fails a wheel: name it by its RWn_CMD or "
                     "RWn_STATUS message")]
        return []


# ---------------------------------------------------------------------------------------------
# Each fact written once: the flight software's knowledge defaults to the truth in the file
# ---------------------------------------------------------------------------------------------

def written_once(data: Any) -> Any:
    """A mission's raw data with every fact the user wrote once filled in where it is needed twice.

    * the flight software's knowledge the file does not give separately is the truth written in it
      (`hil_sim.mission.knowledge.knowledge_from_truth`: epoch, inertia, wheels, star-tracker mounting, boresight, orbit,
      and the initial pointing as its first target when the initial attitude is given as RA/Dec);
    * ``initial_state.ra_dec_deg`` (+ ``roll_deg``) becomes ``initial_state.q_NB``.

    It works on the values as written, before any campaign dispersion: `hil_sim.campaign` applies it to
    the base mission once, so a dispersion changes the truth alone and the flight software never learns
    the dispersed value. Keys given under ``flight_software`` are never touched; values that are not
    valid are left for validation to report where they are written.
    """
    if not isinstance(data, dict):
        return data
    out = knowledge_from_truth(data)
    _attitude_from_ra_dec(out)
    return out


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _attitude_from_ra_dec(data: dict) -> None:
    """Replace initial_state.ra_dec_deg (+ roll_deg) by q_NB."""
    state, sc = data.get("initial_state"), data.get("spacecraft")
    if not isinstance(state, dict) or "q_NB" in state or "ra_dec_deg" not in state:
        return
    ra_dec, roll = state.get("ra_dec_deg"), state.get("roll_deg", 0.0)
    boresight = sc.get("instrument_boresight_B") if isinstance(sc, dict) else None
    if not (isinstance(ra_dec, (list, tuple)) and len(ra_dec) == 2 and all(map(_is_number, ra_dec))
            and 0 <= ra_dec[0] <= 360 and -90 <= ra_dec[1] <= 90 and _is_number(roll) and abs(roll) <= 360
            and isinstance(boresight, list) and len(boresight) == 3 and all(map(_is_number, boresight))):
        return  # validation reports what is wrong, at its key
    try:
        q = attitude_from_ra_dec(float(ra_dec[0]), float(ra_dec[1]), float(roll), np.asarray(boresight, float))
    except ValueError:
        return
    state["q_NB"] = [float(c) for c in q]
    del state["ra_dec_deg"]
    state.pop("roll_deg", None)


def attitude_from_ra_dec(ra_deg: float, dec_deg: float, roll_deg: float, boresight_B: np.ndarray) -> np.ndarray:
    """q_NB (scalar first) pointing ``boresight_B`` at (RA, Dec), rolled by ``roll_deg`` about it.

    Roll 0 turns body +x (body +y when the boresight is within 1 deg of x) as close to celestial north
    as it goes (towards N's x axis when the boresight is at a pole); positive roll is right-handed about
    the boresight.
    """
    from scipy.spatial.transform import Rotation

    b = np.asarray(boresight_B, dtype=float)
    if not np.linalg.norm(b) > 1e-9:
        raise ValueError("boresight must be a non-zero vector")
    b = b / np.linalg.norm(b)
    ref_B = np.array([1.0, 0.0, 0.0]) if abs(b[0]) < math.cos(math.radians(1.0)) else np.array([0.0, 1.0, 0.0])
    r_B = ref_B - (ref_B @ b) * b
    r_B /= np.linalg.norm(r_B)
    y = ra_dec_to_unit(ra_deg, dec_deg)
    north = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 1 - 1e-9 else np.array([1.0, 0.0, 0.0])
    n = north - (north @ y) * y
    n /= np.linalg.norm(n)
    roll = math.radians(roll_deg)
    n = math.cos(roll) * n + math.sin(roll) * np.cross(y, n)  # rotate about y by roll (right-handed)
    frame_N = np.column_stack((y, n, np.cross(y, n)))
    frame_B = np.column_stack((b, r_B, np.cross(b, r_B)))
    x, y_, z, w = Rotation.from_matrix(frame_N @ frame_B.T).as_quat()
    return np.array([w, x, y_, z])


def world_params(mission: Mission) -> "WorldParams":
    """The truth-model parameters (hil_sim.world.params.WorldParams) this mission describes."""
    from hil_sim.world.params import (DisturbanceParams, FacetParams, ImuParams, OrbitParams, SpacecraftParams,
                                StarTrackerParams, WheelParams, WorldParams)

    sc = mission.spacecraft
    speeds = mission.initial_state.wheel_speeds_rad_s or [0.0] * len(sc.wheels)
    wheels = tuple(
        WheelParams(axis_B=tuple(w.axis_B), Js_kgm2=w.spin_inertia_kgm2, max_torque_Nm=w.max_torque_Nm,
                    max_speed_rad_s=w.max_speed_rad_s, viscous_friction_Nm_per_rad_s=w.viscous_friction_Nm_per_rad_s,
                    coulomb_friction_Nm=w.coulomb_friction_Nm, initial_speed_rad_s=speed, failure=w.failure)
        for w, speed in zip(sc.wheels, speeds))
    spacecraft = SpacecraftParams(
        inertia_B_kgm2=tuple(tuple(row) for row in sc.inertia_B_kgm2), wheels=wheels,
        disturbance=DisturbanceParams(constant_B_Nm=tuple(sc.disturbance.constant_B_Nm),
                                      random_std_Nm=sc.disturbance.random_std_Nm,
                                      random_correlation_time_s=sc.disturbance.random_correlation_time_s,
                                      gravity_gradient=sc.disturbance.gravity_gradient,
                                      solar_radiation_pressure=sc.disturbance.solar_radiation_pressure,
                                      solar_flux_W_m2=sc.disturbance.solar_flux_W_m2,
                                      aerodynamic_drag=sc.disturbance.aerodynamic_drag,
                                      atmosphere_density_kg_m3=sc.disturbance.atmosphere_density_kg_m3,
                                      atmosphere_reference_altitude_km=sc.disturbance.atmosphere_reference_altitude_km,
                                      atmosphere_scale_height_km=sc.disturbance.atmosphere_scale_height_km,
                                      **_geomagnetic(mission)),
        q_NB0=tuple(mission.initial_state.q_NB), omega_BN_B0_rad_s=tuple(mission.initial_state.omega_BN_B_rad_s),
        facets=tuple(FacetParams(area_m2=f.area_m2, normal_B=tuple(f.normal_B),
                                 centre_of_pressure_B_m=tuple(f.centre_of_pressure_B_m), specular=f.specular,
                                 diffuse=f.diffuse, drag_coefficient=f.drag_coefficient) for f in sc.facets))
    imu = sc.imu
    st = sc.star_tracker
    orbit = mission.orbit
    return WorldParams(
        spacecraft=spacecraft,
        imu=ImuParams(rate_hz=imu.rate_hz, bias_B_rad_s=tuple(imu.bias_B_rad_s),
                      bias_turn_on_std_rad_s=imu.bias_turn_on_std_rad_s,
                      bias_random_walk_rad_s_per_sqrt_s=imu.bias_random_walk_rad_s_per_sqrt_s,
                      angle_random_walk_rad_per_sqrt_s=imu.angle_random_walk_rad_per_sqrt_s,
                      scale_factor_ppm=tuple(imu.scale_factor_ppm), quantisation_rad_s=imu.quantisation_rad_s,
                      saturation_rad_s=imu.saturation_rad_s),
        star_tracker=StarTrackerParams(rate_hz=st.rate_hz, q_BS=tuple(st.q_BS), boresight_S=tuple(st.boresight_S),
                                       cross_boresight_std_arcsec=st.cross_boresight_std_arcsec,
                                       about_boresight_std_arcsec=st.about_boresight_std_arcsec,
                                       sun_exclusion_deg=st.sun_exclusion_deg,
                                       moon_exclusion_deg=st.moon_exclusion_deg, max_rate_deg_s=st.max_rate_deg_s),
        orbit=OrbitParams(semi_major_axis_km=orbit.semi_major_axis_km, eccentricity=orbit.eccentricity,
                          inclination_deg=orbit.inclination_deg, raan_deg=orbit.raan_deg,
                          arg_perigee_deg=orbit.arg_perigee_deg, mean_anomaly_deg=orbit.mean_anomaly_deg),
        epoch_utc=mission.epoch_utc.strftime("%Y-%m-%dT%H:%M:%S.%fZ"),
        max_integration_step_s=1.0 / mission.simulation.dynamics_rate_hz,
    )


def _geomagnetic(mission: Mission) -> dict[str, Any]:
    """The residual dipole and, when it is not zero or rods are fitted, the Earth's dipole field at the epoch
    (IGRF, via hil_sim.world.geomagnetic) for DisturbanceParams; with ``magnetic_field.model: igrf`` and
    something that feels or reads the field (a residual dipole, rods, a magnetometer), IGRF's coefficients to
    the degree asked for."""
    sc = mission.spacecraft
    dipole = tuple(sc.disturbance.residual_dipole_B_Am2)
    rods = sc.magnetorquers is not None  # their torque goes through the dipole's row
    field = sc.disturbance.magnetic_field
    igrf = field.model == "igrf" and (any(dipole) or rods or sc.magnetometer is not None)
    if not any(dipole) and not rods and not igrf:
        return {}
    out = {"residual_dipole_B_Am2": dipole, "dipole_torque": rods, **_field_coefficients(mission)}
    if igrf:
        from hil_sim.world.geomagnetic import gauss_coefficients_T

        out["geomagnetic_gauss_T"] = gauss_coefficients_T(mission.epoch_utc, field.igrf_degree)
    return out


def _field_coefficients(mission: Mission) -> dict[str, Any]:
    """The Earth's dipole at the epoch (IGRF, via hil_sim.world.geomagnetic) and its rotation angle at t = 0."""
    from hil_sim.world.geomagnetic import dipole_coefficients_T, earth_rotation_angle_rad

    return {"geomagnetic_dipole_T": dipole_coefficients_T(mission.epoch_utc),
            "earth_rotation_angle_rad": earth_rotation_angle_rad(mission.epoch_utc)}


def door_params(mission: Mission) -> Any:
    """The aperture door as built (hil_sim.devices.nodes.DoorParams), None when the mission has no door."""
    from hil_sim.devices.nodes import DoorParams

    door = mission.spacecraft.door
    if door is None:
        return None
    return DoorParams(close_time_s=door.close_time_s, open_time_s=door.open_time_s,
                      initially_open=door.initially_open, close_on_silence_s=door.close_on_silence_s)


def magnetic_device_params(mission: Mission) -> Any:
    """The magnetometer, sun sensors and magnetorquers as built (hil_sim.devices.magnetic.MagneticParams), None
    when the mission has none of them."""
    from hil_sim.devices.magnetic import MagneticParams
    from hil_sim.world.magnetic_devices import MagnetometerParams, MagnetorquerParams
    from hil_sim.world.sun_sensors import SunSensorParams

    sc = mission.spacecraft
    if sc.magnetometer is None and sc.sun_sensors is None and sc.magnetorquers is None:
        return None
    mag = css = mtq = None
    if sc.magnetometer is not None:
        g = sc.magnetometer
        mag = MagnetometerParams(q_BS=tuple(g.q_BS), noise_std_T=g.noise_std_T, bias_S_T=tuple(g.bias_S_T),
                                 resolution_T=g.resolution_T, full_scale_T=g.full_scale_T)
    if sc.sun_sensors is not None:
        c = sc.sun_sensors
        css = SunSensorParams(normals_B=tuple(tuple(n) for n in c.normals_B),
                              field_of_view_half_angle_deg=c.field_of_view_half_angle_deg,
                              full_scale=c.full_scale_mA, noise_std=c.noise_std_mA)
    if sc.magnetorquers is not None:
        r = sc.magnetorquers
        mtq = MagnetorquerParams(axes_B=tuple(tuple(a) for a in r.axes_B), max_dipole_Am2=tuple(r.max_dipole_Am2),
                                 magnetometer_coupling_T_per_Am2=tuple(
                                     tuple(row) for row in r.magnetometer_coupling_T_per_Am2))
    return MagneticParams(magnetometer=mag, sun_sensors=css, magnetorquers=mtq,
                          mtq_cmd_timeout_s=sc.magnetorquers.cmd_timeout_s if mtq is not None else 0.3,
                          **_field_coefficients(mission))


def ra_dec_to_unit(ra_deg: float, dec_deg: float) -> np.ndarray:
    """Unit vector in N from right ascension and declination [deg]."""
    ra, dec = math.radians(ra_deg), math.radians(dec_deg)
    return np.array([math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec)])


def load_mission(path: str | Path, *, text: str | None = None) -> Mission:
    """Load and validate a mission file; raise yaml_loader.ConfigError listing every problem."""
    return load_mission_marked(path, text=text)[0]


def load_mission_or_report(path: str | Path) -> Mission | None:
    """`load_mission` for a command: None when the file is refused, its problems printed to stderr."""
    from hil_sim.mission.loader import ConfigError

    try:
        return load_mission(path)
    except ConfigError as exc:
        print(exc, file=sys.stderr)
        return None


def load_mission_marked(path: str | Path, *, text: str | None = None) -> tuple[Mission, "Marked"]:
    """`load_mission`, plus the file's key positions (to place later findings at file:line:col)."""
    from hil_sim.mission.loader import ConfigError, Problem, load_marked, problems_from_validation
    from pydantic import ValidationError

    doc = load_marked(path, text)
    try:
        mission = Mission.model_validate(doc.data)
    except ValidationError as exc:
        raise ConfigError(problems_from_validation(doc, _ErrorsAsWritten(doc.data, exc), Mission)) from None
    problems = [Problem(doc.file, *doc.mark_for(loc), _path(loc), msg) for loc, msg in mission.semantic_problems()]
    if problems:
        raise ConfigError(problems)
    return mission, doc


# ---------------------------------------------------------------------------------------------
# Validation messages about the keys as written: units named, copies of the truth not reported twice
# ---------------------------------------------------------------------------------------------

Loc = tuple[str | int, ...]
# Units read from a key's suffix (the project's convention) when its description gives none in [brackets]:
# the validator names them in range errors, and mission_docs prints them.
SUFFIX_UNITS = (("_rad_per_sqrt_s", "rad/sqrt(s)"), ("_rad_s_per_sqrt_s", "rad/s/sqrt(s)"),
                ("_rad_s_sqrt_hz", "rad/s/sqrt(Hz)"), ("_rad_s2_sqrt_hz", "rad/s^2/sqrt(Hz)"),
                ("_Nm_per_rad_s", "N m s/rad"), ("_deg_s3", "deg/s^3"), ("_deg_s2", "deg/s^2"), ("_deg_s", "deg/s"),
                ("_rad_s", "rad/s"), ("_1_s", "1/s"), ("_arcsec", "arcsec"), ("_deg", "deg"), ("_rad", "rad"),
                ("_kg_m3", "kg/m^3"), ("_kgm2", "kg m^2"), ("_Nm", "N m"), ("_km", "km"), ("_W_m2", "W/m^2"), ("_Am2", "A m^2"),
                ("_m2", "m^2"), ("_m", "m"), ("_hz", "Hz"), ("_Hz", "Hz"), ("_ppm", "ppm"), ("_bps", "bit/s"),
                ("_utc", "UTC"), ("_s", "s"))
# longest suffix first
UNIT_SUFFIXES: tuple[tuple[str, str], ...] = tuple(sorted(SUFFIX_UNITS, key=lambda item: -len(item[0])))
# Units a value may have been typed in by mistake, per unit of the key: (name, factor to the key's unit).
_MISTAKEN_UNITS: dict[str, tuple[tuple[str, float], ...]] = {
    "rad/s": (("rpm", math.pi / 30.0), ("deg/s", math.pi / 180.0)),
    "deg/s": (("rad/s", 180.0 / math.pi),),
    "rad": (("deg", math.pi / 180.0),),
    "deg": (("rad", 180.0 / math.pi),),
}
_BOUND_WORDS = {"gt": "greater than", "ge": "greater than or equal to", "lt": "less than",
                "le": "less than or equal to"}


def key_unit(loc: Loc) -> str:
    """The unit named by the last key of ``loc`` ('' when its name carries none)."""
    name = next((part for part in reversed(loc) if isinstance(part, str) and not _internal(part)), "")
    return next((unit for suffix, unit in UNIT_SUFFIXES if name.endswith(suffix)), "")


def _internal(part: Any) -> bool:
    return isinstance(part, str) and ("[" in part or part.startswith("function-"))


def _written(loc: Loc) -> Loc:
    return tuple(p for p in loc if not _internal(p))


def _in_data(data: Any, loc: Loc) -> bool:
    node = data
    for part in _written(loc):
        if isinstance(node, dict) and part in node:
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
            node = node[part]
        else:
            return False
    return True


def _bounded(value: float, ctx: dict[str, Any]) -> bool:
    checks = {"gt": lambda b: value > b, "ge": lambda b: value >= b, "lt": lambda b: value < b,
              "le": lambda b: value <= b}
    return all(checks[k](float(b)) for k, b in ctx.items() if k in checks)


def range_message(loc: Loc, err: dict[str, Any]) -> str | None:
    """A range error with the key's unit on the bound and the value, and the conversion when the value fits
    the range in a unit it was likely typed in (6000 in a rad/s key: 6000 rpm = 628.3 rad/s)."""
    ctx, value, unit = err.get("ctx") or {}, err.get("input"), key_unit(loc)
    bound = next(((k, ctx[k]) for k in _BOUND_WORDS if k in ctx), None)
    if not unit or bound is None or not _is_number(value) or not err.get("type", "").endswith(
            ("greater_than", "greater_than_equal", "less_than", "less_than_equal")):
        return None
    msg = f"Input should be {_BOUND_WORDS[bound[0]]} {bound[1]:g} {unit} (got {value!r})"
    hints = [f"{value:g} {other} = {value * factor:.4g} {unit}" for other, factor in _MISTAKEN_UNITS.get(unit, ())
             if _bounded(value * factor, ctx)]
    if hints:
        msg += f"; if you meant another unit, write it in {unit}: " + ", ".join(hints)
    return msg


class _ErrorsAsWritten:
    """A pydantic ValidationError's errors as the user wrote the file (for `problems_from_validation`):

    * an error in the flight software's copy of a truth key the file does not give under flight_software
      (`KNOWLEDGE_SOURCES`) is dropped when the truth key has its own error (one mistake, one message), and
      otherwise reported at the truth key, saying which copy refused it;
    * a range error names the key's unit and the value converted from a unit it was likely typed in.
    """

    def __init__(self, data: Any, exc: Any):
        self.data, self.exc = data, exc

    def errors(self, include_url: bool = False) -> list[dict[str, Any]]:
        from hil_sim.mission.loader import format_path

        errors = self.exc.errors(include_url=include_url)
        written = [_written(tuple(e.get("loc", ()))) for e in errors]
        out = []
        for err, loc in zip(errors, written):
            err = dict(err)
            text = range_message(loc, err)
            if text is not None:
                err["msg"] = text
                err.pop("input", None)  # the message already shows it, beside the unit
            source = self._source(loc)
            if source is not None:
                if any(other[:len(source)] == source or source[:len(other)] == other
                       for other in written if other and other[0] != "flight_software"):
                    continue  # the truth key's own error says it
                if "input" in err:  # shown before the note, where problems_from_validation would append it
                    err["msg"] = f"{err.get('msg', 'invalid')} (got {err.pop('input')!r})"
                err["msg"] = (f"{err.get('msg', 'invalid')}, in {format_path(loc)}, the flight software's copy of "
                              "this value (flight_software does not give it)")
                err["loc"] = source
            out.append(err)
        return out

    def _source(self, loc: Loc) -> Loc | None:
        """The truth key a flight-software key not written in the file was copied from (else None)."""
        for copied, source in KNOWLEDGE_SOURCES.items():
            if loc[:len(copied)] == copied and not _in_data(self.data, copied):
                return source + loc[len(copied):]
        return None


# Values that pass the range but whose size suggests another unit: (key name, test, what it suggests).
_SUSPECT_VALUES: tuple[tuple[str, Any, str], ...] = (
    ("omega_BN_B_rad_s", lambda v: abs(v) > 0.1,
     lambda v: f"{v:g} rad/s is {math.degrees(v):.3g} deg/s, a fast tumble for a spacecraft; if you meant "
               f"{v:g} deg/s, write {math.radians(v):.4g}"),
    ("bias_B_rad_s", lambda v: abs(v) > 1e-3,
     lambda v: f"a gyro bias of {v:g} rad/s is {math.degrees(v) * 3600:.3g} deg/h; if you meant {v:g} deg/s, write "
               f"{math.radians(v):.4g}, or {v:g} deg/h, {math.radians(v) / 3600:.4g}"),
    ("max_speed_rad_s", lambda v: v < 30.0,
     lambda v: f"{v:g} rad/s is {v * 30 / math.pi:.3g} rpm, slow for a reaction wheel; if you meant {v:g} krpm, "
               f"write {v * 1000 * math.pi / 30:.4g}"),
    ("half_angle_deg", lambda v: v < math.pi / 2,
     lambda v: f"{v:g} deg is a small cone; if you meant {v:g} rad, write {math.degrees(v):.4g}"),
)


def unit_warnings(doc: "Marked") -> list[tuple[Loc, str]]:
    """Values as written whose size suggests the wrong unit (e.g. 0.5 deg/s typed into a rad/s key): each
    with its key path and what to write instead. Warnings, not errors: such a value may be meant."""
    out: list[tuple[Loc, str]] = []

    def walk(node: Any, loc: Loc) -> None:
        if isinstance(node, dict):
            for key, value in node.items():
                walk(value, loc + (key,))
        elif isinstance(node, list):
            for i, value in enumerate(node):
                walk(value, loc + (i,))
        elif _is_number(node):
            name = next((p for p in reversed(loc) if isinstance(p, str)), "")
            for key, suspect, why in _SUSPECT_VALUES:
                if name == key and suspect(float(node)):
                    out.append((loc, why(float(node))))

    walk(doc.data, ())
    return out


def _path(loc: tuple[str | int, ...]) -> str:
    from hil_sim.mission.loader import format_path
    return format_path(loc)


SCHEMA_PATH = config_path("schema", "mission.schema.json")
DRAFT07 = "http://json-schema.org/draft-07/schema#"


def mission_json_schema() -> dict[str, Any]:
    """The JSON Schema of a mission file, kept to draft-07 features so every yaml-language-server takes it.

    pydantic emits 2020-12 idioms; we rewrite them: ``$defs`` -> ``definitions``, a ``$ref`` with sibling
    keywords (ignored next to ``$ref`` before 2019-09) -> ``allOf: [{$ref}]`` plus the siblings,
    ``prefixItems`` -> draft-07 tuple ``items``, and drop OpenAPI's ``discriminator`` (the ``const`` of
    each branch already selects it).
    """
    raw = Mission.model_json_schema(ref_template="#/definitions/{model}")
    definitions = raw.pop("$defs", {})
    body = _draft07(raw)
    return {"$schema": DRAFT07, **body, "definitions": {k: _draft07(v) for k, v in sorted(definitions.items())}}


def _draft07(node: Any) -> Any:
    if isinstance(node, list):
        return [_draft07(v) for v in node]
    if not isinstance(node, dict):
        return node
    out = {k: _draft07(v) for k, v in node.items() if k != "discriminator"}
    if "prefixItems" in out:
        out["items"] = out.pop("prefixItems")
        out.setdefault("additionalItems", False)
    if "$ref" in out and len(out) > 1:
        ref = out.pop("$ref")
        out = {"allOf": [{"$ref": ref}], **out}
    return out


def write_json_schema(path: str | Path = SCHEMA_PATH) -> Path:
    """Write the draft-07 mission schema (sorted keys, trailing newline) and return the path."""
    import json
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(mission_json_schema(), indent=2, sort_keys=False) + "\n", encoding="utf-8")
    return path
