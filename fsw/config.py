"""Flight-software configuration: everything the onboard software knows about itself and its mission.

`FswConfig` is a pydantic v2 model (extra keys forbidden, units in key names). The mission YAML embeds
it under the key ``flight_software:``, where the simulator's mission reader (hil_sim.mission) fills in the
knowledge the file leaves to the truth; the flight software reads only its resolved configuration file
(`FswRunConfig`, `load_fsw_run_config`). ``FswConfig.model_json_schema()`` is the JSON Schema editors
use: every field carries a description and a default, so the schema is the reference manual.

Conventions: vectors carry their frame suffix (``_B`` body, ``_N`` inertial GCRS/J2000 equatorial),
quaternions are scalar first Hamilton ``[eta, q1, q2, q3]``; ``q_BS`` rotates star-tracker-frame vectors
into the body frame, a target ``q_NB`` rotates body vectors into N.
"""
from __future__ import annotations

import datetime as _dt
import math
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from comms.bus.transport import CAN_BITRATE_RANGE_BPS
from comms.dictionary import MAX_WHEELS

Vec3 = Annotated[list[float], Field(min_length=3, max_length=3)]
Quat = Annotated[list[float], Field(min_length=4, max_length=4)]



class _Strict(BaseModel):
    # allow_inf_nan=False: a NaN or inf in a gain or a vector would otherwise reach the control loop
    model_config = ConfigDict(extra="forbid", validate_assignment=True, allow_inf_nan=False)


def _unit(v: list[float], what: str) -> list[float]:
    arr = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(arr))
    if not math.isfinite(n) or n < 1e-9:
        raise ValueError(f"{what} must be a non-zero finite vector, got {v}")
    return (arr / n).tolist()


# --------------------------------------------------------------------------------------------- rates
class RatesConfig(_Strict):
    """Rate groups of the executive. One tick source drives all groups."""

    gnc_rate_hz: float = Field(10.0, ge=1.0, le=50.0, description="GNC rate group frequency [Hz] (1..50).")
    housekeeping_rate_hz: float = Field(1.0, gt=0.0, le=10.0, description="Housekeeping rate group frequency [Hz]; must divide the GNC rate.")
    tick_source: Literal["sync", "clock"] = Field(
        "sync",
        description="'sync': lockstep, one GNC cycle per simulator SYNC frame (deterministic); "
        "'clock': real time, cycles paced by the monotonic clock with the newest sensor samples.",
    )
    lockstep_timeout_s: float = Field(5.0, gt=0.0, le=600.0, description="Lockstep: how long to wait for a SYNC tick before declaring the simulator gone [s].")
    realtime_priority: int = Field(0, ge=0, le=99, description="Real time only: SCHED_FIFO priority of the executive thread (1..99; 0 = the host's normal scheduler), with memory locked (mlockall) and the garbage collector's start-up objects frozen, so other work on the host cannot stretch a cycle. Needs root or CAP_SYS_NICE; when refused, the flight software runs best effort and says so in an event.")
    slip_event_throttle_s: float = Field(10.0, ge=0.0, le=3600.0, description="Minimum interval between two cycle-slip warning events per rate group [s]; every slip is still counted.")

    @model_validator(mode="after")
    def _divides(self) -> "RatesConfig":
        ratio = self.gnc_rate_hz / self.housekeeping_rate_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ValueError(
                f"rates.housekeeping_rate_hz={self.housekeeping_rate_hz} must divide rates.gnc_rate_hz={self.gnc_rate_hz}"
            )
        return self


# ---------------------------------------------------------------------------------------- spacecraft
class WheelConfig(_Strict):
    """One reaction wheel as the flight software knows it."""

    axis_B: Vec3 = Field(description="Spin axis in body frame (normalised on load).")
    max_torque_Nm: float = Field(0.05, gt=0.0, le=10.0, description="Motor torque limit [N m].")
    max_speed_rad_s: float = Field(600.0, gt=0.0, le=2000.0, description="Wheel speed limit [rad/s].")
    spin_inertia_kgm2: float = Field(0.002, gt=0.0, le=10.0, description="Wheel inertia about its spin axis [kg m^2].")

    _norm = field_validator("axis_B")(lambda v: _unit(v, "wheel axis_B"))


def _pyramid_wheels() -> list[WheelConfig]:
    s = 1.0 / math.sqrt(3.0)
    return [WheelConfig(axis_B=[sx * s, sy * s, s]) for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]


class SpacecraftConfig(_Strict):
    """Spacecraft knowledge: inertia, wheels, star-tracker mounting."""

    inertia_B_kgm2: list[Vec3] = Field(
        default_factory=lambda: [[10.0, 0.0, 0.0], [0.0, 12.0, 0.0], [0.0, 0.0, 8.0]],
        min_length=3, max_length=3,
        description="Spacecraft inertia about the centre of mass in body frame [kg m^2], symmetric positive definite.",
    )
    wheels: list[WheelConfig] = Field(default_factory=_pyramid_wheels, min_length=3, max_length=MAX_WHEELS, description="Reaction wheels (3..6), in bus order RW1..RWn.")
    star_tracker_q_BS: Quat = Field([1.0, 0.0, 0.0, 0.0], description="Star-tracker mounting quaternion q_BS (rotates star-tracker vectors into body), scalar first.")
    max_rate_deg_s: float = Field(1.0, gt=0.0, le=20.0, description="Body rate limit: the angular-velocity command is scaled so |omega_cmd| never exceeds it [deg/s].")
    star_tracker_max_rate_deg_s: float = Field(2.0, gt=0.0, le=90.0, description="Body rate above which the star tracker gives no attitude [deg/s]; SET_GAINS may not raise the rate limit past it.")
    imu_range_rad_s: float = Field(0.35, gt=0.0, le=20.0, description="Gyro measurement range per axis [rad/s]; SET_GAINS may not raise the rate limit past it.")

    @field_validator("inertia_B_kgm2")
    @classmethod
    def _spd(cls, v: list[list[float]]) -> list[list[float]]:
        J = np.asarray(v, dtype=float)
        if not np.allclose(J, J.T, atol=1e-9 * max(1.0, np.abs(J).max())):
            raise ValueError("spacecraft.inertia_B_kgm2 must be symmetric")
        if np.linalg.eigvalsh(J).min() <= 0:
            raise ValueError("spacecraft.inertia_B_kgm2 must be positive definite")
        return v

    _qn = field_validator("star_tracker_q_BS")(lambda v: _unit(v, "star_tracker_q_BS"))

    @model_validator(mode="after")
    def _span(self) -> "SpacecraftConfig":
        axes = np.array([w.axis_B for w in self.wheels])
        if np.linalg.matrix_rank(axes, tol=1e-6) < 3:
            raise ValueError("spacecraft.wheels: wheel axes must span 3-D (three-axis control)")
        return self


# ------------------------------------------------------------------------------------------ estimator
class EstimatorConfig(_Strict):
    """Multiplicative EKF: gyro propagation, star-tracker updates, gyro-bias estimation."""

    gyro_arw_rad_s_sqrt_hz: float = Field(1e-4, gt=0.0, le=1.0, description="Gyro angle random walk (rate white-noise density) [rad/s/sqrt(Hz)].")
    gyro_bias_rw_rad_s2_sqrt_hz: float = Field(1e-6, gt=0.0, le=1e-2, description="Gyro bias random walk density [rad/s^2/sqrt(Hz)].")
    star_tracker_sigma_arcsec: float = Field(20.0, gt=0.0, le=3600.0, description="Star-tracker 1-sigma attitude noise per axis [arcsec] (the default of the two below).")
    star_tracker_cross_sigma_arcsec: float | None = Field(None, gt=0.0, le=3600.0, description="Star-tracker 1-sigma noise about each of its two cross-boresight axes (sensor x, y) [arcsec]; default star_tracker_sigma_arcsec.")
    star_tracker_about_sigma_arcsec: float | None = Field(None, gt=0.0, le=36000.0, description="Star-tracker 1-sigma roll noise about its boresight (sensor z) [arcsec]; default star_tracker_sigma_arcsec.")
    initial_attitude_sigma_deg: float = Field(5.0, gt=0.0, le=180.0, description="Initial attitude 1-sigma per axis after (re)initialisation from the star tracker [deg].")
    initial_bias_sigma_deg_s: float = Field(0.05, gt=0.0, le=10.0, description="Initial gyro bias 1-sigma per axis [deg/s].")
    star_tracker_max_age_s: float = Field(0.5, gt=0.0, le=10.0, description="A star-tracker sample older than this is stale and not used [s].")
    innovation_gate_deg: float = Field(1.0, gt=0.0, le=180.0, description="Innovations larger than this are rejected (not fused) and reported to FDIR [deg].")
    acquisition_delay_s: float = Field(10.0, gt=0.0, le=3600.0, description="With no attitude fix for this long (star tracker never valid, e.g. blinded by the Sun at start), rotate about the instrument boresight to bring the star tracker out of its exclusion zone [s].")
    acquisition_rate_deg_s: float = Field(0.5, gt=0.0, le=5.0, description="Rate of the star-tracker acquisition rotation about the instrument boresight [deg/s]: the instrument direction does not move, the tracker sweeps a circle that no exclusion cone can cover.")


# ----------------------------------------------------------------------------------- keep-out zones
class ConeShape(_Strict):
    """Circular cone of half-angle `half_angle_deg` around the body direction."""

    shape: Literal["cone"] = "cone"
    half_angle_deg: float = Field(gt=0.0, lt=90.0, description="Cone half-angle about the body direction [deg].")


class SuperellipseShape(_Strict):
    """|x/a|^p + |y/b|^p <= 1 in the tangent plane at the body direction (gnomonic angles)."""

    shape: Literal["superellipse"] = "superellipse"
    semi_axes_deg: Annotated[list[float], Field(min_length=2, max_length=2)] = Field(description="Angular semi-axes [a, b] along the local x (towards celestial north, rotated by orientation_deg) and y axes [deg], each in (0, 89).")
    exponent: float = Field(2.0, gt=0.1, le=20.0, description="Superellipse exponent p (2: ellipse, <1: star/astroid, large: rectangle).")
    orientation_deg: float = Field(0.0, ge=-360.0, le=360.0, description="Rotation of the semi-axes about the body direction, from celestial north towards east [deg].")

    @field_validator("semi_axes_deg")
    @classmethod
    def _range(cls, v: list[float]) -> list[float]:
        if any(not (0.0 < a < 89.0) for a in v):
            raise ValueError(f"semi_axes_deg must lie in (0, 89) deg, got {v}")
        return v


class PolygonShape(_Strict):
    """Star-shaped polygon with respect to the body direction, vertices as angular offsets."""

    shape: Literal["polygon"] = "polygon"
    vertices_deg: list[Annotated[list[float], Field(min_length=2, max_length=2)]] = Field(
        min_length=3, description="Vertices [x, y] as angular offsets from the body direction in the local tangent frame [deg] (x towards celestial north rotated by orientation_deg, y east), counter-clockwise, star-shaped about the origin."
    )
    orientation_deg: float = Field(0.0, ge=-360.0, le=360.0, description="Rotation of the polygon about the body direction [deg].")

    @field_validator("vertices_deg")
    @classmethod
    def _range(cls, v: list[list[float]]) -> list[list[float]]:
        for p in v:
            if math.hypot(*p) >= 89.0 or math.hypot(*p) <= 0.0:
                raise ValueError(f"polygon vertex {p} must be between 0 and 89 deg from the body direction")
        return v


SkyShape = Annotated[Union[ConeShape, SuperellipseShape, PolygonShape], Field(discriminator="shape")]


class SkyZoneConfig(_Strict):
    """A keep-out zone for the instrument boresight on S^2, centred on a body or a fixed direction."""

    name: str = Field(description="Zone name used in events and telemetry.", min_length=1, max_length=24)
    body: Literal["sun", "moon", "earth", "inertial"] = Field(description="Centre: the Sun, Moon or Earth direction from the spacecraft (onboard ephemeris), or a fixed inertial direction.")
    direction_N: Vec3 | None = Field(None, description="Centre direction for body='inertial' (normalised on load).")
    geometry: SkyShape = Field(description="Zone shape about the centre direction.")
    add_body_angular_radius: bool = Field(True, description="Earth only: enlarge the zone by the Earth's apparent angular radius seen from the onboard orbit.")
    armed: Literal["always", "inertial_targets"] = Field("always", description="When the zone is kept out: 'always', or 'inertial_targets': only while the POINTING target is a fixed direction (a star or dark field), from the first cycle the boresight is outside the law's (inflated) zone and can stop short of the zone from the rate it closes on it; a nadir or ground target disarms it at once, and it stays disarmed in SAFE until such a target is followed no more. Meant for an Earth zone on an Earth-observing instrument: its ground targets lie inside the Earth's disc, but the bright Earth and its limb must stay out of its sky observations. While disarmed the zone's margin reads NaN (no keep-out) in telemetry, FDIR and the aperture door, and the truth judge leaves it out (hil_sim.sil.judge).")
    atmosphere_height_km: float | None = Field(None, ge=0.0, le=1000.0, description="Earth only, with add_body_angular_radius: the zone reaches the top of an atmosphere this high [km] instead of the solid Earth's limb: its half-angle is asin((R_E + h) / r) plus the geometry's own, r the onboard orbit radius. Unset: the solid Earth (R_E = 6378.137 km). Every Earth zone that sets it must give the same height.")

    @model_validator(mode="after")
    def _dir(self) -> "SkyZoneConfig":
        if self.atmosphere_height_km is not None and not (self.body == "earth" and self.add_body_angular_radius):
            raise ValueError(f"zone '{self.name}': atmosphere_height_km needs body='earth' and add_body_angular_radius: true")
        if self.body == "inertial":
            if self.direction_N is None:
                raise ValueError(f"zone '{self.name}': body='inertial' requires direction_N")
            self.__dict__["direction_N"] = _unit(self.direction_N, f"zone '{self.name}' direction_N")
        elif self.direction_N is not None:
            raise ValueError(f"zone '{self.name}': direction_N is only allowed with body='inertial'")
        return self


class S3ConeConfig(_Strict):
    """Forbidden attitudes within a geodesic cone on S^3 around a centre quaternion."""

    shape: Literal["cone"] = "cone"
    name: str = Field(min_length=1, max_length=24)
    center_q: Quat = Field(description="Centre quaternion g on S^3 (scalar first, normalised on load).")
    half_angle_deg: float = Field(gt=0.0, lt=90.0, description="Half-angle of the cone on S^3 [deg] (note: an S^3 angle is half the rotation angle).")
    antipodal_copy: bool = Field(False, description="Also forbid -g (the same physical attitudes on the other sheet of the double cover).")

    _qn = field_validator("center_q")(lambda v: _unit(v, "center_q"))


class S3SuperellipsoidConfig(_Strict):
    """Star-shaped zone on S^3: central projection of |p1/a1|^e + |p2/a2|^e + |p3/a3|^e <= 1 in the tangent space at g."""

    shape: Literal["superellipsoid"] = "superellipsoid"
    name: str = Field(min_length=1, max_length=24)
    center_q: Quat = Field(description="Kernel/centre quaternion g (normalised on load).")
    semi_axes: Vec3 = Field(description="Semi-axes in the tangent space at g (dimensionless, tangent-plane units; 1 = 45 deg on S^3).")
    exponent: float = Field(2.0, gt=0.1, le=20.0, description="Superellipsoid exponent.")
    antipodal_copy: bool = Field(False, description="Also forbid the antipodal copy about -g.")

    _qn = field_validator("center_q")(lambda v: _unit(v, "center_q"))

    @field_validator("semi_axes")
    @classmethod
    def _pos(cls, v: list[float]) -> list[float]:
        if any(a <= 0 or a > 50 for a in v):
            raise ValueError(f"semi_axes must be in (0, 50], got {v}")
        return v


S3Zone = Annotated[Union[S3ConeConfig, S3SuperellipsoidConfig], Field(discriminator="shape")]


# --------------------------------------------------------------------------------------------- laws
class LawConfig(_Strict):
    """Parameters of the paper's feedback laws."""

    k1: float = Field(0.1, gt=0.0, le=100.0, description="Law gain k1 [1/s]: the kinematic law's time scale (the paper uses 1 in its kinematic study; a spacecraft needs ~0.05-0.2 so the rate loop can follow). The resulting rate command is then saturated at the rate limit.")
    kappa: float = Field(1.0, gt=0.0, le=100.0, description="StarShapedLaw gain kappa (must exceed the kappa_bar reported by gnc.checks).")
    eps: float | Literal["auto"] = Field("auto", description="Layer thickness eps (in d_s units, 1 - cos angle), or 'auto' to take eps_fraction of the admissible upper bound every cycle.")
    eps_fraction: float = Field(0.5, gt=0.0, lt=1.0, description="With eps='auto': eps = eps_fraction * eps_max from gnc.checks.")
    eps_max_used: float = Field(0.15, gt=0.0, le=1.0, description="Upper cap on eps whatever the check allows (keeps the avoidance layer thin).")
    margin_deg: float = Field(3.0, ge=0.0, le=30.0, description="The law avoids physical zones inflated by this margin [deg]; see fsw.guidance for how to choose it.")
    merge_gap_deg: float = Field(4.0, ge=0.0, le=30.0, description="Two (inflated) zones whose bounding caps are closer than this gap [deg] are replaced by one conservative cone containing both, with an event. Assumption 1 ties eps to the gap (eps < 1 - cos(gap/2)), so a small gap forces an eps-layer too thin for the loop to turn in; merging trades sky area for a usable layer.")
    retreat_standoff_deg: float = Field(3.0, gt=0.0, le=30.0, description="When the target is unusable (in a zone's eps-layer, or between two zones about to merge around the spacecraft), the law steers to the nearest direction at least this far [deg] outside every (inflated) zone instead. It keeps a parked boresight clear of a zone sweeping towards it and must be at least half of merge_gap_deg, so the substitute never lies in a gap about to merge.")
    stall_watchdog_s: float = Field(30.0, ge=0.0, le=3600.0, description="Guidance watchdog (fsw.guidance.watchdog): a POINTING slew whose error has not fallen for this long [s], with the law's rate near zero and the boresight outside every eps-layer, raises GUIDANCE_STALLED and is replanned from where the boresight is; 0 disables it.")
    check_period_s: float = Field(10.0, gt=0.0, le=3600.0, description="How often the full assumption check (gnc.checks, incl. the numerical Assumption 2 test) is re-run while zones move [s]; it is re-submitted at once on target/gain/mode/zone-merge changes.")
    check_max_cpu_fraction: float = Field(0.1, gt=0.0, le=1.0, description="CPU budget of the periodic full check in 'process' mode: after a check that took d seconds, the next periodic one waits at least d (1/fraction - 1) seconds of host time, whatever check_period_s says. It binds in lockstep runs faster than real time; checks after a target/gain/mode/zone change are not delayed.")
    assumption_check: Literal["process", "inline", "off"] = Field("process", description="Where the full check runs: 'process' (a worker process, so the seconds it can take never delay a GNC cycle; results only feed telemetry/events), 'inline' (in the housekeeping group; deterministic, for tests), 'off'. The per-cycle eps bound never depends on it.")

    @model_validator(mode="after")
    def _standoff_clears_merge_gap(self) -> "LawConfig":
        if self.retreat_standoff_deg < 0.5 * self.merge_gap_deg:
            raise ValueError(f"retreat_standoff_deg ({self.retreat_standoff_deg:g}) must be at least half of merge_gap_deg "
                             f"({self.merge_gap_deg:g}): a substitute target closer than that to two zones could sit in a gap about to merge")
        return self


# -------------------------------------------------------------------------------------------- modes
class PathGuidanceConfig(_Strict):
    """POINTING slews planned round the zones (fsw.guidance.path_planning): the law's target moves along the
    shortest path that keeps a standoff from every zone the law avoids, instead of heading straight for a
    target behind a zone and creeping round the zone's edge."""

    enabled: bool = Field(True, description="Plan slews whose great circle is blocked by a zone; false: the law heads straight for the target.")
    standoff_deg: float = Field(2.0, gt=0.0, le=20.0, description="Clearance of the planned path from every zone as the law sees it (inflated by law.margin_deg, merged) [deg]; keeps the boresight out of the law's eps-layer while it follows the path.")
    lookahead_deg: float = Field(6.0, ge=1.0, le=45.0, description="The law's target is at least this far ahead of the boresight along the path [deg], and far enough that the law's rate k1 sin(angle) stays at the rate limit (12.6 deg for k1 = 0.1 1/s at 1 deg/s). More than the braking distance at the rate limit (w^2 / 2a, 3.3 deg at 1 deg/s and 0.15 deg/s^2) keeps the slew at full rate; much more cuts corners into the zones' standoff.")
    replan_period_s: float = Field(30.0, gt=0.0, le=3600.0, description="While a path is followed it is planned again from the boresight this often [s], so it follows zones that move (the Earth from low orbit moves ~0.06 deg/s).")
    polygon_sides: int = Field(48, ge=8, le=360, description="Sides of the convex polygon drawn round each zone for planning (a plan costs ~3 ms with 48 sides and three zones, growing as the square).")


class GroundTargetConfig(_Strict):
    """A point on the rotating Earth (WGS-84): the boresight follows it every GNC cycle, its direction
    computed from the onboard orbit (`orbit`) and the Earth's rotation (`gnc.earth`)."""

    latitude_deg: float = Field(ge=-90.0, le=90.0, description="Geodetic latitude (WGS-84) [deg], north positive.")
    longitude_deg: float = Field(ge=-180.0, le=360.0, description="Longitude [deg], east positive.")
    altitude_m: float = Field(0.0, ge=-500.0, le=9000.0, description="Height above the WGS-84 ellipsoid [m].")
    min_elevation_deg: float = Field(0.0, ge=0.0, lt=90.0, description="Lowest elevation of the spacecraft above the target's horizon at which it can be observed [deg]. The mission check reports a ground target commanded for a dwell in which it never rises this high; onboard the target is followed whatever its elevation.")


class PointingConfig(_Strict):
    """POINTING mode: instrument boresight to a target direction avoiding sky zones."""

    boresight_B: Vec3 = Field([0.0, 0.0, 1.0], description="Instrument boresight in body frame (normalised).")
    target_N: Vec3 = Field([1.0, 0.0, 0.0], description="Initial target direction in N (normalised), with target_kind 'inertial'; SET_TARGET changes it.")
    target_kind: Literal["inertial", "nadir", "ground"] = Field("inertial", description="What the initial target is: 'inertial' (target_N, fixed in N), 'nadir' (the Earth's centre seen from the onboard orbit) or 'ground' (target_ground on the rotating Earth). A nadir or ground target moves: its direction is computed again every GNC cycle and the zones are kept out as for any target; SET_TARGET replaces it.")
    target_ground: GroundTargetConfig | None = Field(None, description="The ground point for target_kind 'ground'.")
    roll_axis_B: Vec3 = Field([1.0, 0.0, 0.0], description="Body axis (not parallel to the boresight) whose projection is steered towards the roll reference (roll_reference): e.g. the normal of the face carrying the solar array.")
    roll_reference: Literal["inertial", "sun", "velocity", "orbit_normal"] = Field("inertial", description="What the roll about the boresight turns roll_axis_B towards, as far as rotation about the boresight allows: 'inertial' (roll_reference_N, fixed), 'sun' (the Sun from the onboard ephemeris: roll_axis_B's face as sunlit as the boresight leaves it), 'velocity' (the onboard orbit's velocity) or 'orbit_normal' (the onboard orbit's angular momentum). Rotation about the boresight never moves it: the keep-out guarantee is the same with any rule. Where the reference comes within 25 deg of the target's line (the Sun near nadir or zenith for a nadir target) the last reference outside it is held.")
    roll_reference_N: Vec3 = Field([0.0, 0.0, 1.0], description="Inertial reference for the roll about the boresight with roll_reference 'inertial' (falls back to another axis when nearly parallel to the boresight).")
    roll_gain_1_s: float = Field(0.05, ge=0.0, le=10.0, description="Roll law gain about the boresight [1/s]; 0 disables roll control.")
    zones: list[SkyZoneConfig] = Field(default_factory=list, max_length=6, description="Keep-out zones for the boresight (at most 6).")
    path: PathGuidanceConfig = Field(default_factory=PathGuidanceConfig, description="Slew path planning round the zones.")

    _n = field_validator("boresight_B", "target_N", "roll_axis_B", "roll_reference_N")(lambda v: _unit(v, "direction"))

    @model_validator(mode="after")
    def _roll(self) -> "PointingConfig":
        if abs(float(np.dot(self.boresight_B, self.roll_axis_B))) > 0.99:
            raise ValueError("pointing.roll_axis_B must not be parallel to pointing.boresight_B")
        names = [z.name for z in self.zones]
        if len(set(names)) != len(names):
            raise ValueError(f"pointing.zones: duplicate zone names {names}")
        if (self.target_kind == "ground") != (self.target_ground is not None):
            raise ValueError("pointing.target_ground is needed with target_kind 'ground', and only then")
        heights = {z.atmosphere_height_km for z in self.zones if z.body == "earth" and z.atmosphere_height_km is not None}
        if len(heights) > 1:
            raise ValueError(f"pointing.zones: Earth zones give different atmosphere_height_km {sorted(heights)}; "
                             "the onboard ephemeris carries one Earth limb")
        return self

    def atmosphere_height_km(self) -> float | None:
        """The height of the atmosphere the Earth zones reach [km], or None (the solid Earth's limb)."""
        return next((z.atmosphere_height_km for z in self.zones if z.atmosphere_height_km is not None), None)


class QuaternionModeConfig(_Strict):
    """QUATERNION mode: full attitude target on S^3 avoiding forbidden-attitude zones."""

    target_q_NB: Quat = Field([1.0, 0.0, 0.0, 0.0], description="Initial target attitude q_NB (scalar first, normalised); SET_TARGET changes it.")
    law: Literal["auto", "star", "gradient"] = Field("auto", description="'gradient' (all zones must be cones), 'star' (any zones) or 'auto' (gradient when all are cones).")
    zones: list[S3Zone] = Field(default_factory=list, max_length=16, description="Forbidden-attitude zones on S^3.")
    path: PathGuidanceConfig = Field(default_factory=PathGuidanceConfig, description="Slew path planning on S^3 round the zones' bounding balls (fsw.guidance.attitude_planning): enabled, standoff_deg and lookahead_deg are used, as quaternion angles (half the rotation angle).")

    _qn = field_validator("target_q_NB")(lambda v: _unit(v, "target_q_NB"))

    @model_validator(mode="after")
    def _law(self) -> "QuaternionModeConfig":
        if self.law == "gradient" and any(z.shape != "cone" for z in self.zones):
            raise ValueError("quaternion.law='gradient' needs every quaternion zone to be a cone")
        return self


class SafeConfig(_Strict):
    """SAFE mode: rate damping, then a body axis (solar arrays) to the Sun."""

    sun_axis_B: Vec3 = Field([0.0, 0.0, -1.0], description="Body axis pointed at the Sun in SAFE (normalised).")
    damping_exit_rate_deg_s: float = Field(0.05, gt=0.0, le=10.0, description="Rate damping ends when |omega| stays below this for 1 s [deg/s].")
    sun_gain_1_s: float = Field(0.1, gt=0.0, le=10.0, description="Sun-pointing gain [1/s].")
    max_rate_deg_s: float = Field(0.5, gt=0.0, le=20.0, description="Rate limit in SAFE [deg/s].")
    _n = field_validator("sun_axis_B")(lambda v: _unit(v, "sun_axis_B"))


class ControlConfig(_Strict):
    """Rate loop: tau = J (kp (omega_cmd - omega) + d omega_cmd/dt) + omega x (J omega + h_wheels)."""

    rate_bandwidth_rad_s: float = Field(1.0, gt=0.0, le=20.0, description="Rate-loop bandwidth kp [rad/s] (keep below ~gnc_rate_hz).")
    feedforward_command_rate: bool = Field(True, description="Add J d(omega_cmd)/dt (finite difference, limited) as feed-forward.")
    max_command_accel_deg_s2: float = Field(0.5, gt=0.0, le=50.0, description="Slew-rate limit on omega_cmd [deg/s^2] (what the wheels can deliver).")
    max_command_jerk_deg_s3: float | Literal["auto"] = Field("auto", description="Limit on the change of omega_cmd's acceleration [deg/s^3]: the torque command stays smooth when the law's command swings inside an eps-layer. 'auto': rate_bandwidth_rad_s x max_command_accel_deg_s2 (full acceleration in one loop time constant); 0: no jerk limit (the acceleration may reverse every cycle).")

    @field_validator("max_command_jerk_deg_s3")
    @classmethod
    def _jerk(cls, v: float | str) -> float | str:
        if v != "auto" and not (0.0 <= float(v) <= 1000.0):
            raise ValueError(f"max_command_jerk_deg_s3 must be 'auto' or in [0, 1000] deg/s^3, got {v}")
        return v


# ------------------------------------------------------------------------------------ magnetic devices
class MagneticDevicesConfig(_Strict):
    """The magnetometer, coarse sun sensors and magnetorquer rods the flight software reads and drives: each
    fitted one's frames reach the `SensorSnapshot` (MAG_FIELD as `mag_S_T`, CSS_CURRENTS as `css_mA`), and with
    rods MTQ_COMMAND goes out every GNC cycle (zero unless a law asks). Without this section none of them."""

    magnetometer: bool = Field(False, description="MAG_FIELD is read (default: true when spacecraft.magnetometer is given).")
    sun_sensors: bool = Field(False, description="CSS_CURRENTS is read (default: true when spacecraft.sun_sensors is given).")
    magnetorquers: bool = Field(False, description="MTQ_COMMAND is sent every GNC cycle (default: true when spacecraft.magnetorquers is given).")


class CoarseAttitudeConfig(_Strict):
    """The coarse attitude (`fsw.coarse_attitude`): once no star-tracker fix has been fused for ``after_s``,
    the estimator fuses the Sun direction the cells measure (two axes across the Sun line) and, with
    ``field_sigma_deg``, the magnetometer's field against the onboard dipole (two axes across the field
    line); never initialised, it takes the TRIAD attitude of the two. What it knows of the cells, the
    magnetometer and the field (defaults: the spacecraft's and the epoch's, `hil_sim.mission.knowledge`);
    cells with a field of view under 90 deg give no fix (the dark cells' bound needs the whole hemisphere)."""

    after_s: float = Field(10.0, gt=0.0, le=3600.0, description="The star tracker silent (no fused fix) this long before the coarse sensors are fused [s].")
    sun_sigma_deg: float = Field(2.0, gt=0.0, le=30.0, description="1-sigma error of one measured Sun direction per axis [deg] (the cells' noise and the dark cells' bound, asin(lit_fraction)).")
    field_sigma_deg: float | None = Field(None, gt=0.0, le=30.0, description="1-sigma error of the measured field's direction against the onboard dipole per axis [deg] (the magnetometer's noise, and the dipole's error where the truth is IGRF to a higher degree: up to ~15 deg in low orbit); absent: the magnetometer is not used.")
    gate_deg: float = Field(10.0, gt=0.0, le=90.0, description="A direction further than this (and four predicted sigmas) from the estimate's is not fused [deg].")
    lit_fraction: float = Field(0.05, gt=0.0, lt=0.5, description="A cell counts as lit above this fraction of its full scale.")
    normals_B: list[Vec3] = Field([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]], min_length=3, max_length=6, description="Each cell's unit normal in body axes as the flight software knows them, in CSS_CURRENTS order (normalised on load).")
    full_scale_mA: float = Field(1.0, gt=0.0, le=2.5, description="A cell's output at normal incidence in full Sun [mA].")
    field_of_view_half_angle_deg: float = Field(90.0, gt=0.0, le=90.0, description="The cells' field of view [deg]; the fix needs 90.")
    magnetometer_q_BS: Quat = Field([1.0, 0.0, 0.0, 0.0], description="Magnetometer mounting as the flight software knows it: rotates sensor-frame vectors into body, scalar first (normalised on load).")
    field_degree: int = Field(1, ge=1, le=13, description="Degree of the onboard IGRF field model (1: the centred dipole; default: the truth's, spacecraft.disturbance.magnetic_field).")
    geomagnetic_gauss_T: list[Annotated[list[float], Field(min_length=2, max_length=2)]] | None = Field(None, description="The onboard field model's Schmidt semi-normalised Gauss coefficients (g, h) [T], n = 1..field_degree, m = 0..n (default with field_sigma_deg: IGRF-14's at epoch_utc).")
    margin_deg: float | None = Field(None, ge=0.0, le=45.0, description="The law's margin while the coarse attitude flies [deg]: law.margin_deg plus the coarse estimate's error, which the star tracker's budget does not cover. The law's zones grow to it when the coarse sensors take over (COARSE_ATTITUDE_ON) and shrink back when the star tracker returns (COARSE_ATTITUDE_OFF). Default: law.margin_deg + 3 sun_sigma_deg; at least law.margin_deg + 3 sigma of the better of the two directions.")

    @field_validator("normals_B")
    @classmethod
    def _normals(cls, v: list[list[float]]) -> list[list[float]]:
        return [_unit(n, "normals_B") for n in v]

    @model_validator(mode="after")
    def _consistent(self) -> "CoarseAttitudeConfig":
        if self.field_of_view_half_angle_deg < 90.0:
            raise ValueError("coarse_attitude: the Sun fix reads the dark cells as a bound, which needs cells that see "
                             f"the whole hemisphere (field_of_view_half_angle_deg 90), got {self.field_of_view_half_angle_deg}")
        gauss = self.geomagnetic_gauss_T
        if self.field_sigma_deg is not None and not gauss:
            raise ValueError("coarse_attitude: field_sigma_deg needs the onboard field model geomagnetic_gauss_T "
                             "(IGRF's (g, h) pairs [T] to field_degree)")
        wanted = self.field_degree * (self.field_degree + 3) // 2
        if gauss and len(gauss) != wanted:
            raise ValueError(f"coarse_attitude: geomagnetic_gauss_T has {len(gauss)} (g, h) pairs; degree "
                             f"{self.field_degree} takes {wanted}")
        return self


class _RodsKnowledge(_Strict):
    """What a law driving the rods knows of them and of the magnetometer: each rod's limit and axis, the
    magnetometer's mounting (defaults: the spacecraft's, `hil_sim.mission.knowledge`)."""

    max_dipole_Am2: Annotated[list[Annotated[float, Field(gt=0.0, le=32.0)]], Field(min_length=3, max_length=3)] = Field(
        [0.2, 0.2, 0.2], description="Each rod's command limit [A m^2]; a command is scaled down as a whole (its direction kept) until every rod is within it.")
    magnetometer_q_BS: Quat = Field([1.0, 0.0, 0.0, 0.0], description="Magnetometer mounting as the flight software knows it: rotates sensor-frame vectors into body, scalar first (normalised on load).")
    rod_axes_B: list[Vec3] = Field([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], min_length=3, max_length=3, description="Each rod's unit axis in body axes as the flight software knows it (normalised on load; they must span 3-D).")

    _qn = field_validator("magnetometer_q_BS")(lambda v: _unit(v, "magnetometer_q_BS"))

    @field_validator("rod_axes_B")
    @classmethod
    def _rods(cls, v: list[list[float]]) -> list[list[float]]:
        axes = [_unit(a, "rod axis") for a in v]
        if np.linalg.matrix_rank(np.array(axes), tol=1e-6) < 3:
            raise ValueError("rod_axes_B: the rod axes must span 3-D")
        return axes


class MomentumManagementConfig(_RodsKnowledge):
    """Magnetic momentum management (`fsw.momentum`): every GNC cycle, after the rate loop, the wheels' stored
    momentum above `wheel_momentum_bias_Nms` is dumped through the rods with the cross-product law while the
    attitude loop keeps pointing (the field's torque only drains the wheels). Needs magnetic_devices with the
    magnetometer and the magnetorquers. Off by default."""

    enabled: bool = Field(False, description="Command the rods to unload the wheels (false: the rods get zero, as without this section).")
    gain_1_s: float = Field(1e-3, gt=0.0, le=1.0, description="Cross-product law gain k: the field is asked for the torque -k (h_w - bias) [1/s].")
    wheel_momentum_bias_Nms: Vec3 = Field([0.0, 0.0, 0.0], description="Stored wheel momentum the law keeps, in body axes [N m s].")


class DetumbleConfig(_RodsKnowledge):
    """DETUMBLE mode (`fsw.detumble`): B-dot on the magnetometer, m = -k dB/dt with dB/dt the measured field's
    rate of change in body axes through a first-order low-pass filter, mapped onto the rods and saturated; the
    wheels get zero torque; once the gyro's body rate has stayed below `rate_threshold_deg_s` for `dwell_s`,
    DETUMBLE_COMPLETE and SAFE. Needs magnetic_devices with the magnetometer and the magnetorquers, and a door
    (flight_software.door) when there are sky zones: a tumbling body cannot steer its boresight, the door is
    held closed throughout. Absent (the default): no DETUMBLE mode."""

    gain_Am2_s_T: float = Field(2.0e5, gt=0.0, le=1.0e9, description="B-dot gain k: dipole per field rate [A m^2 per T/s] (large: the rods saturate until the rate is low).")
    filter_time_constant_s: float = Field(1.0, ge=0.0, le=100.0, description="Time constant of the low-pass filter on the field rate [s] (0: the raw difference of two samples).")
    rate_threshold_deg_s: float = Field(0.5, gt=0.0, le=10.0, description="Detumbled when the gyro's |omega| stays below this [deg/s].")
    dwell_s: float = Field(30.0, ge=0.0, le=3600.0, description="How long |omega| must stay below rate_threshold_deg_s before SAFE [s].")


# --------------------------------------------------------------------------------------------- door
class DoorConfig(_Strict):
    """The protective aperture door as the flight software knows and drives it (`fsw.door`): DOOR_CMD every
    GNC cycle, DOOR_STATUS read back. It closes the door when its own prediction says the boresight will come
    within `guard_deg` of a physical zone before the control can stop it, counting the door's closing time
    as reaction time, or when KEEP_OUT_VIOLATION is raised, or while it has no attitude; it opens it again
    only when every physical margin has stayed at least `reopen_margin_deg` for `reopen_dwell_s` with no
    such prediction. Without this section there is no door (nothing of it on the bus)."""

    close_time_s: float = Field(gt=0.0, le=600.0, description="Full stroke open -> closed as the flight software knows it [s] (default: spacecraft.door.close_time_s).")
    open_time_s: float = Field(gt=0.0, le=600.0, description="Full stroke closed -> open [s] (default: spacecraft.door.open_time_s).")
    guard_deg: float = Field(0.5, ge=0.0, le=30.0, description="Close when the boresight is predicted to come within this of a physical zone [deg].")
    reopen_margin_deg: float = Field(2.0, ge=0.0, le=90.0, description="Reopen only when every physical margin is at least this [deg] (hysteresis above guard_deg).")
    reopen_dwell_s: float = Field(10.0, ge=0.0, le=3600.0, description="Reopen only after every physical margin has been at least reopen_margin_deg, with no closing prediction, for this long [s] (the dwell).")
    coast_horizon_s: float = Field(60.0, gt=0.0, le=3600.0, description="With fewer than three usable wheels (no braking): how far ahead a coasting approach to a zone closes the door [s].")
    stroke_margin: float = Field(1.5, ge=1.0, le=10.0, description="DOOR_FAULT when a commanded stroke takes longer than this times its known time (plus one second) [-].")
    status_timeout_s: float = Field(1.0, gt=0.0, le=60.0, description="DOOR_FAULT (NO_STATUS) after this long without a valid DOOR_STATUS [s].")

    @model_validator(mode="after")
    def _hysteresis(self) -> "DoorConfig":
        if self.reopen_margin_deg < self.guard_deg:
            raise ValueError(f"door.reopen_margin_deg ({self.reopen_margin_deg}) must be at least door.guard_deg "
                             f"({self.guard_deg}): the door would open where it closes")
        return self


# --------------------------------------------------------------------------------------------- FDIR
FdirAction = Literal["none", "safe", "reset_estimator", "isolate_wheel", "isolate_wheel_safe"]


class FdirRule(_Strict):
    """Limit-check rule: when the monitored value exceeds `limit` for `persistence_cycles` consecutive GNC cycles, emit the event and take `action` (once per trip)."""

    enabled: bool = True
    limit: float = Field(ge=-1e6, le=1e6, description="Threshold in the rule's unit (see the rule description).")
    persistence_cycles: int = Field(3, ge=1, le=100000, description="Consecutive GNC cycles beyond the limit before the rule trips.")
    action: FdirAction = Field("none", description="Action when tripped.")


class FdirConfig(_Strict):
    """FDIR rules (limit, persistence, event, action). Monitored values and their units per rule."""

    imu_stale: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.5, persistence_cycles=5, action="safe"), description="No valid IMU sample this cycle (value 1/0; limit 0.5).")
    imu_corrupt: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.5, persistence_cycles=3, action="none"), description="IMU frames with CRC/sequence/length errors this cycle (count; limit).")
    star_tracker_stale: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.5, persistence_cycles=50, action="none"), description="No valid fresh star-tracker sample this cycle (value 1/0): the estimator coasts; event after persistence.")
    star_tracker_corrupt: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.5, persistence_cycles=3, action="none"), description="Star-tracker frames with CRC/sequence/length errors this cycle (count; limit).")
    innovation: FdirRule = Field(default_factory=lambda: FdirRule(limit=1.0, persistence_cycles=5, action="reset_estimator"), description="Star-tracker innovation angle above `limit` [deg].")
    wheel_fault: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.5, persistence_cycles=3, action="isolate_wheel"), description="Wheel reports a fault flag, no status, or a speed that does not follow its torque commands (value 1/0), per wheel.")
    wheel_speed: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.95, persistence_cycles=5, action="safe"), description="|wheel speed| / max_speed above `limit`, per wheel.")
    keepout_yellow: FdirRule = Field(default_factory=lambda: FdirRule(limit=1.0, persistence_cycles=1, action="none"), description="Physical keep-out margin below `limit` [deg] (yellow): KEEP_OUT_MARGIN_LOW warning.")
    keepout_red: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.0, persistence_cycles=2, action="safe"), description="Physical keep-out margin below `limit` [deg] (red, 0 = inside): KEEP_OUT_VIOLATION.")
    cycle_slip: FdirRule = Field(default_factory=lambda: FdirRule(limit=0.5, persistence_cycles=3, action="none"), description="GNC cycle slipped (value 1/0): `persistence_cycles` consecutive slipping cycles trip the rule.")


# -------------------------------------------------------------------------------------- orbit/TMTC
class OrbitKnowledge(_Strict):
    """Onboard circular-orbit model (Earth direction and Moon parallax)."""

    radius_km: float = Field(42164.0, gt=6478.0, le=2.0e6, description="Orbit radius [km].")
    inclination_deg: float = Field(0.0, ge=0.0, le=180.0)
    raan_deg: float = Field(0.0, ge=-360.0, le=360.0)
    arg_latitude_at_epoch_deg: float = Field(0.0, ge=-360.0, le=360.0, description="Argument of latitude at the epoch [deg].")


class LinkSecurityConfig(_Strict):
    """Link security (comms.link_security, in the manner of CCSDS SDLS): MAC and anti-replay on TC and TM."""

    key_file: str | None = Field(None, description="Path of the link key file (hex, mode 0600; `keepout ground keygen FILE` makes one), relative to the mission file's folder. Never the key itself. Required by the flight software process; the SIL makes a fresh key for every run in its run folder and uses that instead.")
    tc_window: int = Field(1024, ge=1, le=1_000_000, description="Anti-replay window: an uplink security sequence number is accepted when above the last accepted one by at most this much; beyond it only SEC_RESYNC is.")


def is_loopback_host(host: str) -> bool:
    """True for a loopback IP literal (127.0.0.0/8, ::1) or "localhost"."""
    import ipaddress

    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class TmTcConfig(_Strict):
    """Telemetry/telecommand sockets (loopback unless the mission names another address)."""

    telemetry_host: str = Field("127.0.0.1", description="Destination address of telemetry datagrams: a "
                                "ground station's address (unicast), or a multicast group (224.0.0.0/4) that "
                                "any number of ground clients join.")

    @field_validator("telemetry_host")
    @classmethod
    def _unicast_or_group(cls, v: str) -> str:
        import ipaddress

        try:
            addr = ipaddress.ip_address(v)
        except ValueError:
            return v  # a host name: resolved when the socket is opened
        if addr.is_unspecified or addr == ipaddress.ip_address("255.255.255.255"):
            kind = "unspecified" if addr.is_unspecified else "broadcast"
            raise ValueError(f"{v} is a {kind} address: give a ground station's unicast address "
                             "(e.g. 127.0.0.1) or a multicast group (224.0.0.0/4)")
        return v
    telemetry_port: int = Field(50100, ge=1, le=65535)
    telemetry_multicast_interface: str = Field(
        "127.0.0.1", description="With a multicast telemetry_host: the local address whose interface sends the "
        "group (loopback keeps the telemetry on this computer).")
    telemetry_multicast_ttl: int = Field(
        0, ge=0, le=255, description="With a multicast telemetry_host: hops the datagrams may take (0: this host only).")
    telecommand_bind_host: str = Field("127.0.0.1", description="Address the telecommand socket binds to; a non-loopback address needs allow_non_loopback: true.")
    telecommand_port: int = Field(50101, ge=0, le=65535, description="0 = ephemeral port.")
    allow_non_loopback: bool = Field(False, description="Explicit consent to bind the telecommand socket to a non-loopback address (reachable from the network; commands are still authenticated). A warning is printed whenever it is used.")
    uplink_budget_ms: float = Field(5.0, gt=0.0, le=1000.0, description="Host time a GNC cycle may spend reading the uplink [ms]; what is left stays queued for the next cycle, and what the kernel had to drop is counted (tc_uplink_dropped).")
    gnc_packet_every_n_cycles: int = Field(1, ge=1, le=1000, description="Send the GNC state packet every n GNC cycles.")
    security: LinkSecurityConfig = Field(default_factory=LinkSecurityConfig, description="Link security: the key file and the uplink anti-replay window (docs/security.md).")

    @model_validator(mode="after")
    def _loopback_unless_allowed(self) -> "TmTcConfig":
        if not is_loopback_host(self.telecommand_bind_host) and not self.allow_non_loopback:
            raise ValueError(f"telecommand_bind_host {self.telecommand_bind_host!r} is not a loopback address "
                             "(127.0.0.1, ::1, localhost): any host that can reach it could send telecommands; "
                             "set allow_non_loopback: true to bind it anyway")
        return self

    def warnings(self) -> list[str]:
        """What ``config validate`` and the flight software print about these sockets."""
        if is_loopback_host(self.telecommand_bind_host):
            return []
        return [f"flight_software.tmtc.telecommand_bind_host {self.telecommand_bind_host!r} is not loopback "
                "(allow_non_loopback: true): telecommands are accepted from the network, authenticated "
                "by the link key only"]


class PluginsConfig(_Strict):
    """A user's own guidance law or estimator in place of keepout's, by entry-point name (docs/plugins.md). Keep-out stays keepout's: its margins, rate limit, FDIR and plug-in guard watch a plug-in."""

    guidance: str | None = Field(None, min_length=1, description="Entry-point name in the group keepout.guidance of the guidance law flown in POINTING and QUATERNION; none: keepout's own laws.")
    estimator: str | None = Field(None, min_length=1, description="Entry-point name in the group keepout.estimator of the attitude estimator; none: keepout's own MEKF.")

    @field_validator("guidance", "estimator")
    @classmethod
    def _installed(cls, v: str | None, info) -> str | None:
        from fsw.plugins import installed, unknown_name_message

        if v is not None and v not in installed(info.field_name):
            raise ValueError(unknown_name_message(info.field_name, v))
        return v


class FswConfig(_Strict):
    """Complete flight-software configuration (embedded in the mission YAML under ``flight_software:``)."""

    epoch_utc: _dt.datetime = Field(_dt.datetime(2026, 3, 20, 12, 0, tzinfo=_dt.timezone.utc), description="UTC epoch of tick 0 (ISO 8601).")
    initial_mode: Literal["SAFE", "POINTING", "QUATERNION", "DETUMBLE"] = Field("SAFE", description="Mode at start (DETUMBLE needs the detumble section).")
    rates: RatesConfig = Field(default_factory=RatesConfig)
    spacecraft: SpacecraftConfig = Field(default_factory=SpacecraftConfig)
    orbit: OrbitKnowledge = Field(default_factory=OrbitKnowledge)
    estimator: EstimatorConfig = Field(default_factory=EstimatorConfig)
    law: LawConfig = Field(default_factory=LawConfig)
    control: ControlConfig = Field(default_factory=ControlConfig)
    pointing: PointingConfig = Field(default_factory=PointingConfig)
    quaternion: QuaternionModeConfig = Field(default_factory=QuaternionModeConfig)
    safe: SafeConfig = Field(default_factory=SafeConfig)
    fdir: FdirConfig = Field(default_factory=FdirConfig)
    tmtc: TmTcConfig = Field(default_factory=TmTcConfig)
    plugins: PluginsConfig = Field(default_factory=PluginsConfig)
    door: DoorConfig | None = Field(None, description="The protective aperture door the flight software drives (default: present, with the spacecraft's stroke times, when spacecraft.door is given; absent otherwise).")
    magnetic_devices: MagneticDevicesConfig | None = Field(None, description="The magnetometer, sun sensors and magnetorquers the flight software reads and drives (default: present, naming those the spacecraft has, when it has any; absent otherwise).")
    momentum_management: MomentumManagementConfig = Field(default_factory=MomentumManagementConfig, description="Magnetic unloading of the wheels' momentum through the rods (off by default).")
    detumble: DetumbleConfig | None = Field(None, description="B-dot detumbling, the DETUMBLE mode (absent: no DETUMBLE mode; initial_mode DETUMBLE and SET_MODE DETUMBLE need it).")
    coarse_attitude: CoarseAttitudeConfig | None = Field(None, description="The attitude held (or found) on the coarse sun sensors and the magnetometer while the star tracker is lost (absent: the gyro alone carries it).")

    @model_validator(mode="after")
    def _momentum_devices(self) -> "FswConfig":
        d = self.magnetic_devices
        rods = d is not None and d.magnetometer and d.magnetorquers
        if self.momentum_management.enabled and not rods:
            raise ValueError("momentum_management.enabled needs magnetic_devices with magnetometer and magnetorquers")
        if self.initial_mode == "DETUMBLE" and self.detumble is None:
            raise ValueError("initial_mode DETUMBLE needs the detumble section (flight_software.detumble)")
        if self.detumble is not None and not rods:
            raise ValueError("detumble: DETUMBLE needs magnetic_devices with magnetometer and magnetorquers "
                             "(spacecraft.magnetometer and spacecraft.magnetorquers)")
        if self.detumble is not None and (self.pointing.zones or self.quaternion.zones) and self.door is None:
            raise ValueError("detumble: a tumbling spacecraft cannot steer its boresight out of the keep-out zones "
                             "(pointing.zones, quaternion.zones); DETUMBLE keeps the instrument behind the aperture door: add "
                             "spacecraft.door (or flight_software.door)")
        coarse = self.coarse_attitude
        if coarse is not None and (d is None or not d.sun_sensors):
            raise ValueError("coarse_attitude needs magnetic_devices with sun_sensors (spacecraft.sun_sensors)")
        if coarse is not None and coarse.field_sigma_deg is not None and not d.magnetometer:
            raise ValueError("coarse_attitude.field_sigma_deg needs magnetic_devices with magnetometer "
                             "(spacecraft.magnetometer)")
        if coarse is not None and coarse.margin_deg is not None:
            best = min(coarse.sun_sigma_deg, coarse.field_sigma_deg or math.inf)
            floor = self.law.margin_deg + 3.0 * best
            if coarse.margin_deg < floor:
                raise ValueError(f"coarse_attitude.margin_deg {coarse.margin_deg:g} does not cover the coarse attitude's "
                                 f"error: it must be at least law.margin_deg ({self.law.margin_deg:g}) plus 3 sigma of the "
                                 f"better direction ({best:g} deg), {floor:g}; leave it out for law.margin_deg + 3 "
                                 f"sun_sigma_deg ({self.law.margin_deg + 3.0 * coarse.sun_sigma_deg:g})")
        return self

    def coarse_margin_deg(self) -> float | None:
        """The law's margin while the coarse attitude flies [deg] (`CoarseAttitudeConfig.margin_deg`, its
        default resolved), or None without a coarse attitude."""
        coarse = self.coarse_attitude
        if coarse is None:
            return None
        return coarse.margin_deg if coarse.margin_deg is not None else self.law.margin_deg + 3.0 * coarse.sun_sigma_deg

    @field_validator("epoch_utc")
    @classmethod
    def _tz(cls, v: _dt.datetime) -> _dt.datetime:
        return v if v.tzinfo else v.replace(tzinfo=_dt.timezone.utc)

    @property
    def gnc_period_s(self) -> float:
        return 1.0 / self.rates.gnc_rate_hz


class BusConfig(_Strict):
    """The bus the flight software opens, as the mission resolved it (its ``bus``, ``bus_bitrate_bps`` and
    ``bus_authentication``)."""

    spec: str = Field("auto", min_length=1, description="Bus spec: auto | socketcan[:IFACE] | udp_multicast[:GROUP:PORT] | virtual[:CHANNEL] | INTERFACE:CHANNEL[,KEY=VALUE...] (any python-can interface).")
    bitrate_bps: int | None = Field(None, ge=CAN_BITRATE_RANGE_BPS[0], le=CAN_BITRATE_RANGE_BPS[1], description="CAN bit rate a hardware interface is opened with [bit/s]; none: the interface's own.")
    authentication: bool = Field(False, description="Every batch of frames carries a SecOC authenticator keyed from the link key.")


class FswRunConfig(_Strict):
    """The flight software's configuration file (``python -m fsw --config FILE``): its bus and its own
    configuration, resolved by whoever starts it (the SIL writes it into the run folder, ``keepout fsw
    MISSION`` builds it from the mission), with nothing of the truth in it."""

    bus: BusConfig = Field(default_factory=BusConfig)
    flight_software: FswConfig


class FswConfigError(ValueError):
    """The flight software's configuration file is missing, unreadable or invalid; the message names the
    file and the key."""


def load_fsw_run_config(path: str | Path) -> FswRunConfig:
    """The flight software's configuration file, read once: safe YAML within `fsw.safe_yaml`'s limits, then a
    strict validation. Nothing is filled in from anywhere else: the file was resolved before it got here."""
    import yaml

    from fsw.safe_yaml import UnreadableFile, load_config_file

    p = Path(path)
    try:
        data = load_config_file(p)
    except UnreadableFile as exc:
        raise FswConfigError(f"{p}: cannot read: {exc}") from None
    except yaml.YAMLError as exc:
        raise FswConfigError(f"{p}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise FswConfigError(f"{p}: expected a mapping with the keys flight_software and bus, got "
                             f"{type(data).__name__}")
    hint = ""
    if set(data) - set(FswRunConfig.model_fields):
        # the truth's keys never reach the flight software: a mission is resolved first
        hint = "\n(a mission file? `keepout fsw MISSION` resolves it for the flight software)"
    return _validated(FswRunConfig, data, str(p), "", hint)


def parse_fsw_config(data: dict, source: str = "<dict>", prefix: str = "") -> FswConfig:
    """``data`` as an FswConfig; raises FswConfigError listing every key refused, as ``prefix`` + key path."""
    return _validated(FswConfig, data, source, prefix)


def _validated(model: type[_Strict], data: dict, source: str, prefix: str, hint: str = "") -> Any:
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        lines = [f"  {prefix}{'.'.join(str(x) for x in err['loc'])}: {err['msg']}" for err in exc.errors()]
        raise FswConfigError(f"{source}: invalid flight-software configuration:\n" + "\n".join(lines) + hint) from None
