"""Parameters of the simulated world (truth models), as explicit frozen dataclasses.

Every number the truth models use is a named field here, with its unit in the name, so that the SIL
engineer can build a world from a mission config, the campaigns engineer can disperse any field with
``dataclasses.replace`` (or ``WorldParams.from_dict``), and every run can write back exactly what it used
(``WorldParams.to_dict``). Vectors are tuples (immutable, hashable); frames follow DESIGN.md:
``_B`` body, ``_N`` inertial (GCRS / J2000 equatorial), ``_S`` star-tracker sensor frame.
Quaternions are scalar first, Hamilton, ``q_XY`` rotating Y-frame vectors into X.

Validation happens in ``__post_init__`` and raises ``ValueError`` naming the field and what is allowed.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

WHEEL_FAILURE_MODES = ("none", "stuck", "no_torque")
"""``none`` healthy; ``stuck`` seized bearing (relative speed locked at zero, momentum handed to the hub);
``no_torque`` motor/driver dead (no motor torque, friction still acts)."""

_PYRAMID_ELEVATION_RAD = math.radians(30.0)


def _pyramid_axes_B() -> tuple[tuple[float, float, float], ...]:
    """Four wheels in the classic pyramid: 30 deg elevation above the body x-y plane, 90 deg apart."""
    c, s = math.cos(_PYRAMID_ELEVATION_RAD), math.sin(_PYRAMID_ELEVATION_RAD)
    axes = []
    for k in range(4):
        az = math.radians(45.0 + 90.0 * k)
        axes.append((c * math.cos(az), c * math.sin(az), s))
    return tuple(axes)


def _vec(value: Any, n: int, name: str) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected {n} finite numbers, got {value!r}")
    return tuple(float(x) for x in arr)


def _unit_quat(value: Any, name: str) -> tuple[float, float, float, float]:
    q = np.asarray(_vec(value, 4, name))
    norm = float(np.linalg.norm(q))
    if abs(norm - 1.0) > 1e-6:
        raise ValueError(f"{name}: quaternion must be unit norm (scalar first), |q| = {norm:.9f}")
    return tuple(float(x) for x in q / norm)  # type: ignore[return-value]


def _nonneg(value: float, name: str) -> float:
    v = float(value)
    if not math.isfinite(v) or v < 0.0:
        raise ValueError(f"{name}: must be a finite number >= 0, got {value!r}")
    return v


def _positive(value: float, name: str) -> float:
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"{name}: must be a finite number > 0, got {value!r}")
    return v


@dataclass(frozen=True)
class WheelParams:
    """One reaction wheel. ``axis_B`` is the unit spin axis g in body axes; speed is relative to the body."""

    axis_B: tuple[float, float, float]
    Js_kgm2: float = 0.05
    max_torque_Nm: float = 0.2
    max_speed_rad_s: float = 628.3  # 6000 rpm
    viscous_friction_Nm_per_rad_s: float = 0.0
    coulomb_friction_Nm: float = 0.0
    # Coulomb friction uses tanh(Omega / this) so RK4 does not chatter through zero speed.
    coulomb_smoothing_rad_s: float = 0.05
    initial_speed_rad_s: float = 0.0
    failure: str = "none"
    # Electrical/thermal model, only for the status telemetry (current, temperature).
    motor_constant_Nm_per_A: float = 0.03
    winding_resistance_ohm: float = 2.0
    thermal_resistance_K_per_W: float = 4.0
    thermal_capacity_J_per_K: float = 300.0
    ambient_temp_C: float = 20.0

    def __post_init__(self) -> None:
        axis = np.asarray(_vec(self.axis_B, 3, "wheel.axis_B"))
        norm = float(np.linalg.norm(axis))
        if abs(norm - 1.0) > 1e-6:
            raise ValueError(f"wheel.axis_B: must be a unit vector, |axis| = {norm:.9f}")
        object.__setattr__(self, "axis_B", tuple(float(x) for x in axis / norm))
        object.__setattr__(self, "Js_kgm2", _positive(self.Js_kgm2, "wheel.Js_kgm2"))
        object.__setattr__(self, "max_torque_Nm", _nonneg(self.max_torque_Nm, "wheel.max_torque_Nm"))
        object.__setattr__(self, "max_speed_rad_s", _positive(self.max_speed_rad_s, "wheel.max_speed_rad_s"))
        for name in ("viscous_friction_Nm_per_rad_s", "coulomb_friction_Nm", "thermal_resistance_K_per_W",
                     "winding_resistance_ohm"):
            object.__setattr__(self, name, _nonneg(getattr(self, name), f"wheel.{name}"))
        for name in ("coulomb_smoothing_rad_s", "motor_constant_Nm_per_A", "thermal_capacity_J_per_K"):
            object.__setattr__(self, name, _positive(getattr(self, name), f"wheel.{name}"))
        object.__setattr__(self, "initial_speed_rad_s", float(self.initial_speed_rad_s))
        object.__setattr__(self, "ambient_temp_C", float(self.ambient_temp_C))
        if self.failure not in WHEEL_FAILURE_MODES:
            raise ValueError(f"wheel.failure: {self.failure!r} not allowed; use one of {WHEEL_FAILURE_MODES}")


@dataclass(frozen=True)
class DisturbanceParams:
    """External torque on the hub: constant plus a first-order Gauss-Markov random part per body axis.

    The random part d obeys d_{k+1} = a d_k + sqrt(1 - a^2) sigma n_k with a = exp(-dt / tau) at each
    integration step (held over the step), so its stationary std is ``random_std_Nm``. With
    ``random_correlation_time_s`` = 0 it is white noise redrawn every integration step.
    """

    constant_B_Nm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    random_std_Nm: float = 0.0
    random_correlation_time_s: float = 60.0
    seed: int | None = None
    gravity_gradient: bool = False  # 3 mu / r^3 (u x I u) from the orbit and the true inertia
    # Solar radiation pressure on the spacecraft's facets (SpacecraftParams.facets), zero in the umbra and
    # scaled by the sunlit fraction in the penumbra (hil_sim.world.environment).
    solar_radiation_pressure: bool = False
    solar_flux_W_m2: float = 1361.0  # at 1 AU (total solar irradiance, Kopp & Lean 2011)
    # Aerodynamic drag on the facets in an exponential atmosphere rotating with the Earth:
    # rho = atmosphere_density_kg_m3 exp(-(h - atmosphere_reference_altitude_km) / atmosphere_scale_height_km),
    # the defaults the 500-600 km band of Vallado's table 8-4 (Fundamentals of Astrodynamics, 4th ed.).
    aerodynamic_drag: bool = False
    atmosphere_density_kg_m3: float = 6.967e-13
    atmosphere_reference_altitude_km: float = 500.0
    atmosphere_scale_height_km: float = 63.822
    # A residual magnetic dipole of the spacecraft (A m^2, body axes; zero: off) in the Earth's field, a centred
    # dipole of Gauss coefficients (g10, g11, h11) [T] turning with the Earth, whose rotation angle at the
    # epoch is given (hil_sim.world.geomagnetic makes both from IGRF at the mission epoch).
    residual_dipole_B_Am2: tuple[float, float, float] = (0.0, 0.0, 0.0)
    geomagnetic_dipole_T: tuple[float, float, float] = (0.0, 0.0, 0.0)
    earth_rotation_angle_rad: float = 0.0
    # The dipole torque on even with a zero residual: magnetorquer rods are fitted, and the simulator adds their
    # dipole to the residual's row each GNC period (hil_sim.devices.magnetic).
    dipole_torque: bool = False
    # The Earth's field as IGRF instead of the centred dipole: Schmidt semi-normalised (g_n^m, h_n^m) [T] for
    # n = 1..N, m = 0..n (hil_sim.world.geomagnetic.gauss_coefficients_T at the epoch); empty: the dipole.
    geomagnetic_gauss_T: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "constant_B_Nm", _vec(self.constant_B_Nm, 3, "disturbance.constant_B_Nm"))
        object.__setattr__(self, "random_std_Nm", _nonneg(self.random_std_Nm, "disturbance.random_std_Nm"))
        object.__setattr__(self, "random_correlation_time_s",
                           _nonneg(self.random_correlation_time_s, "disturbance.random_correlation_time_s"))
        for name in ("solar_flux_W_m2", "atmosphere_density_kg_m3", "atmosphere_scale_height_km"):
            object.__setattr__(self, name, _positive(getattr(self, name), f"disturbance.{name}"))
        name = "atmosphere_reference_altitude_km"
        object.__setattr__(self, name, _nonneg(getattr(self, name), f"disturbance.{name}"))
        for name in ("residual_dipole_B_Am2", "geomagnetic_dipole_T"):
            object.__setattr__(self, name, _vec(getattr(self, name), 3, f"disturbance.{name}"))
        if (any(self.residual_dipole_B_Am2) or self.dipole_torque) and not any(self.geomagnetic_dipole_T):
            raise ValueError("disturbance.geomagnetic_dipole_T: a residual dipole needs the Earth's field "
                             "(hil_sim.world.geomagnetic.dipole_coefficients_T at the epoch)")
        if not math.isfinite(self.earth_rotation_angle_rad):
            raise ValueError("disturbance.earth_rotation_angle_rad: must be finite")
        if self.geomagnetic_gauss_T:
            from hil_sim.world.geomagnetic import degree_of

            pairs = tuple(_vec(gh, 2, "disturbance.geomagnetic_gauss_T[k]") for gh in self.geomagnetic_gauss_T)
            degree_of(len(pairs))
            object.__setattr__(self, "geomagnetic_gauss_T", pairs)


@dataclass(frozen=True)
class FacetParams:
    """One flat surface of the spacecraft for the environment torques: its area, outward unit normal and
    centre of pressure (from the centre of mass) in body axes, and its optical coefficients (specular,
    diffuse; the rest of the light is absorbed) and drag coefficient."""

    area_m2: float
    normal_B: tuple[float, float, float]
    centre_of_pressure_B_m: tuple[float, float, float]
    specular: float = 0.0
    diffuse: float = 0.0
    drag_coefficient: float = 2.2  # C_D of a flat plate in free-molecular flow, the usual 2.0-2.5

    def __post_init__(self) -> None:
        object.__setattr__(self, "area_m2", _positive(self.area_m2, "facet.area_m2"))
        normal = np.asarray(_vec(self.normal_B, 3, "facet.normal_B"))
        if abs(float(np.linalg.norm(normal)) - 1.0) > 1e-6:
            raise ValueError(f"facet.normal_B: must be a unit vector, |n| = {np.linalg.norm(normal):.9f}")
        object.__setattr__(self, "normal_B", tuple(float(x) for x in normal / np.linalg.norm(normal)))
        object.__setattr__(self, "centre_of_pressure_B_m",
                           _vec(self.centre_of_pressure_B_m, 3, "facet.centre_of_pressure_B_m"))
        for name in ("specular", "diffuse"):
            value = _nonneg(getattr(self, name), f"facet.{name}")
            if value > 1.0:
                raise ValueError(f"facet.{name}: must be within [0, 1], got {value!r}")
            object.__setattr__(self, name, value)
        object.__setattr__(self, "drag_coefficient", _nonneg(self.drag_coefficient, "facet.drag_coefficient"))
        if self.specular + self.diffuse > 1.0:
            raise ValueError(f"facet: specular + diffuse = {self.specular + self.diffuse:g} exceeds 1 "
                             "(the absorbed share is 1 - specular - diffuse)")


def _default_wheels() -> tuple[WheelParams, ...]:
    return tuple(WheelParams(axis_B=a) for a in _pyramid_axes_B())


@dataclass(frozen=True)
class SpacecraftParams:
    """Hub + wheels. ``inertia_B_kgm2`` is the whole spacecraft with the wheels locked (it already
    contains each wheel's Js g g^T), about the centre of mass, in body axes."""

    inertia_B_kgm2: tuple[tuple[float, float, float], ...] = ((20.0, 0.0, 0.0), (0.0, 25.0, 0.0), (0.0, 0.0, 15.0))
    wheels: tuple[WheelParams, ...] = field(default_factory=_default_wheels)
    disturbance: DisturbanceParams = field(default_factory=DisturbanceParams)
    q_NB0: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    omega_BN_B0_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    facets: tuple[FacetParams, ...] = ()  # the outer surfaces, for solar radiation pressure and drag

    def __post_init__(self) -> None:
        inertia = np.asarray(self.inertia_B_kgm2, dtype=float)
        if inertia.shape != (3, 3) or not np.all(np.isfinite(inertia)):
            raise ValueError(f"spacecraft.inertia_B_kgm2: expected a 3x3 matrix, got {self.inertia_B_kgm2!r}")
        if not np.allclose(inertia, inertia.T, rtol=0, atol=1e-12 * np.abs(inertia).max()):
            raise ValueError("spacecraft.inertia_B_kgm2: must be symmetric")
        object.__setattr__(self, "inertia_B_kgm2", tuple(tuple(float(x) for x in row) for row in inertia))
        wheels = tuple(WheelParams(**w) if isinstance(w, dict) else w for w in self.wheels)
        if not all(isinstance(w, WheelParams) for w in wheels):
            raise ValueError("spacecraft.wheels: each entry must be a WheelParams or a dict of its fields")
        object.__setattr__(self, "wheels", wheels)
        if isinstance(self.disturbance, dict):
            object.__setattr__(self, "disturbance", DisturbanceParams(**self.disturbance))
        # The hub without the wheel rotors must stay positive definite, or the equations of motion are singular.
        hub_only = inertia - sum(w.Js_kgm2 * np.outer(w.axis_B, w.axis_B) for w in wheels) if wheels else inertia
        if np.linalg.eigvalsh(hub_only).min() <= 0.0:
            raise ValueError("spacecraft.inertia_B_kgm2: inertia minus the wheels' Js g g^T must be positive "
                             "definite (the hub inertia includes the wheels locked)")
        object.__setattr__(self, "q_NB0", _unit_quat(self.q_NB0, "spacecraft.q_NB0"))
        object.__setattr__(self, "omega_BN_B0_rad_s", _vec(self.omega_BN_B0_rad_s, 3, "spacecraft.omega_BN_B0_rad_s"))
        facets = tuple(FacetParams(**f) if isinstance(f, dict) else f for f in self.facets)
        if not all(isinstance(f, FacetParams) for f in facets):
            raise ValueError("spacecraft.facets: each entry must be a FacetParams or a dict of its fields")
        object.__setattr__(self, "facets", facets)
        if (self.disturbance.solar_radiation_pressure or self.disturbance.aerodynamic_drag) and not facets:
            raise ValueError("spacecraft.facets: solar radiation pressure and drag need the spacecraft's facets")


@dataclass(frozen=True)
class ImuParams:
    """Rate gyro (3 axes, in body axes). Noise model (IEEE-952 style):

    measured = (1 + scale_factor) * omega_true + bias + n_arw, then saturation, then quantisation.
    n_arw is white with std ``angle_random_walk_rad_per_sqrt_s / sqrt(1 / rate_hz)`` per sample; the bias
    starts at ``bias_B_rad_s`` + N(0, ``bias_turn_on_std_rad_s``) and random-walks with
    ``bias_random_walk_rad_s_per_sqrt_s`` (std of the change over dt = coefficient * sqrt(dt)).
    """

    rate_hz: float = 100.0
    bias_B_rad_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    bias_turn_on_std_rad_s: float = math.radians(1.0) / 3600.0  # 1 deg/h class
    bias_random_walk_rad_s_per_sqrt_s: float = 1.0e-7
    angle_random_walk_rad_per_sqrt_s: float = math.radians(0.01) / 60.0  # 0.01 deg/sqrt(h)
    scale_factor_ppm: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quantisation_rad_s: float = 1.0e-7
    saturation_rad_s: float = math.radians(20.0)
    seed: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_hz", _positive(self.rate_hz, "imu.rate_hz"))
        object.__setattr__(self, "bias_B_rad_s", _vec(self.bias_B_rad_s, 3, "imu.bias_B_rad_s"))
        object.__setattr__(self, "scale_factor_ppm", _vec(self.scale_factor_ppm, 3, "imu.scale_factor_ppm"))
        for name in ("bias_turn_on_std_rad_s", "bias_random_walk_rad_s_per_sqrt_s",
                     "angle_random_walk_rad_per_sqrt_s", "quantisation_rad_s"):
            object.__setattr__(self, name, _nonneg(getattr(self, name), f"imu.{name}"))
        object.__setattr__(self, "saturation_rad_s", _positive(self.saturation_rad_s, "imu.saturation_rad_s"))


@dataclass(frozen=True)
class StarTrackerParams:
    """Star tracker: outputs q_NS (sensor frame S to N). The boresight is ``boresight_S`` in the sensor frame
    (default +z), mounted by ``q_BS``. Errors are a small rotation in S with std ``cross_boresight_std_arcsec``
    about the two axes normal to the boresight and ``about_boresight_std_arcsec`` about it. Output is invalid
    when the Sun (Moon) centre is within ``sun_exclusion_deg`` (``moon_exclusion_deg``) of the boresight or
    |omega_BN_B| exceeds ``max_rate_deg_s``."""

    rate_hz: float = 10.0
    q_BS: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    boresight_S: tuple[float, float, float] = (0.0, 0.0, 1.0)
    cross_boresight_std_arcsec: float = 5.0
    about_boresight_std_arcsec: float = 40.0
    sun_exclusion_deg: float = 30.0
    moon_exclusion_deg: float = 25.0
    max_rate_deg_s: float = 2.0
    seed: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "rate_hz", _positive(self.rate_hz, "star_tracker.rate_hz"))
        object.__setattr__(self, "q_BS", _unit_quat(self.q_BS, "star_tracker.q_BS"))
        b = np.asarray(_vec(self.boresight_S, 3, "star_tracker.boresight_S"))
        if abs(np.linalg.norm(b) - 1.0) > 1e-6:
            raise ValueError("star_tracker.boresight_S: must be a unit vector")
        object.__setattr__(self, "boresight_S", tuple(float(x) for x in b / np.linalg.norm(b)))
        for name in ("cross_boresight_std_arcsec", "about_boresight_std_arcsec", "sun_exclusion_deg",
                     "moon_exclusion_deg"):
            object.__setattr__(self, name, _nonneg(getattr(self, name), f"star_tracker.{name}"))
        object.__setattr__(self, "max_rate_deg_s", _positive(self.max_rate_deg_s, "star_tracker.max_rate_deg_s"))
        for name in ("sun_exclusion_deg", "moon_exclusion_deg"):
            if getattr(self, name) >= 180.0:
                raise ValueError(f"star_tracker.{name}: must be < 180 deg")


@dataclass(frozen=True)
class OrbitParams:
    """Two-body Keplerian orbit of the spacecraft about the Earth in N (GCRS), elements at the epoch."""

    semi_major_axis_km: float = 6378.137 + 550.0
    eccentricity: float = 0.0
    inclination_deg: float = 97.6
    raan_deg: float = 0.0
    arg_perigee_deg: float = 0.0
    mean_anomaly_deg: float = 0.0
    mu_km3_s2: float = 398600.4418

    def __post_init__(self) -> None:
        object.__setattr__(self, "semi_major_axis_km", _positive(self.semi_major_axis_km, "orbit.semi_major_axis_km"))
        e = float(self.eccentricity)
        if not 0.0 <= e < 1.0:
            raise ValueError(f"orbit.eccentricity: must be in [0, 1) (closed orbit), got {self.eccentricity!r}")
        if self.semi_major_axis_km * (1.0 - e) < 6378.137:
            raise ValueError("orbit: perigee radius a(1-e) is below the Earth's equatorial radius 6378.137 km")
        object.__setattr__(self, "eccentricity", e)
        object.__setattr__(self, "mu_km3_s2", _positive(self.mu_km3_s2, "orbit.mu_km3_s2"))
        for name in ("inclination_deg", "raan_deg", "arg_perigee_deg", "mean_anomaly_deg"):
            v = float(getattr(self, name))
            if not math.isfinite(v):
                raise ValueError(f"orbit.{name}: must be finite")
            object.__setattr__(self, name, v)


@dataclass(frozen=True)
class WorldParams:
    """Everything a ``hil_sim.world.world.World`` needs. ``epoch_utc`` is ISO-8601 UTC (t = 0 of the run)."""

    spacecraft: SpacecraftParams = field(default_factory=SpacecraftParams)
    imu: ImuParams = field(default_factory=ImuParams)
    star_tracker: StarTrackerParams = field(default_factory=StarTrackerParams)
    orbit: OrbitParams = field(default_factory=OrbitParams)
    epoch_utc: str = "2030-03-20T12:00:00Z"
    # step(dt) is split into equal RK4 sub-steps no longer than this.
    max_integration_step_s: float = 0.01
    # Truth ephemeris: astropy evaluated on this grid and interpolated by cubic spline (see ephemeris_truth).
    ephemeris_node_spacing_s: float = 3600.0

    def __post_init__(self) -> None:
        for name, cls in (("spacecraft", SpacecraftParams), ("imu", ImuParams),
                          ("star_tracker", StarTrackerParams), ("orbit", OrbitParams)):
            value = getattr(self, name)
            if isinstance(value, dict):
                object.__setattr__(self, name, _from_dict(cls, value, name))
            elif not isinstance(value, cls):
                raise ValueError(f"{name}: expected {cls.__name__} or a dict of its fields")
        from gnc.ephemeris import parse_utc  # light module; validates the epoch string

        parse_utc(self.epoch_utc, "epoch_utc")
        object.__setattr__(self, "max_integration_step_s",
                           _positive(self.max_integration_step_s, "max_integration_step_s"))
        object.__setattr__(self, "ephemeris_node_spacing_s",
                           _positive(self.ephemeris_node_spacing_s, "ephemeris_node_spacing_s"))

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (JSON/YAML-ready) of every field."""
        return _to_plain(dataclasses.asdict(self))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "WorldParams":
        """Inverse of ``to_dict``; unknown keys raise ``ValueError`` naming the key and the allowed ones."""
        return _from_dict(cls, data, "world")


def _to_plain(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _to_plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_to_plain(v) for v in obj]
    return obj


_NESTED = {
    (SpacecraftParams, "disturbance"): DisturbanceParams,
    (WorldParams, "spacecraft"): SpacecraftParams,
    (WorldParams, "imu"): ImuParams,
    (WorldParams, "star_tracker"): StarTrackerParams,
    (WorldParams, "orbit"): OrbitParams,
}


def _from_dict(cls: type, data: dict[str, Any], where: str) -> Any:
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a mapping of {cls.__name__} fields, got {type(data).__name__}")
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - allowed)
    if unknown:
        raise ValueError(f"{where}: unknown key(s) {unknown}; allowed: {sorted(allowed)}")
    kwargs: dict[str, Any] = {}
    for key, value in data.items():
        nested = _NESTED.get((cls, key))
        if nested is not None and isinstance(value, dict):
            value = _from_dict(nested, value, f"{where}.{key}")
        elif cls is SpacecraftParams and key == "wheels":
            value = tuple(_from_dict(WheelParams, w, f"{where}.wheels[{i}]") if isinstance(w, dict) else w
                          for i, w in enumerate(value))
        elif cls is SpacecraftParams and key == "facets":
            value = tuple(_from_dict(FacetParams, f, f"{where}.facets[{i}]") if isinstance(f, dict) else f
                          for i, f in enumerate(value))
        elif cls is SpacecraftParams and key == "inertia_B_kgm2":
            value = tuple(tuple(row) for row in value)
        elif isinstance(value, list):
            value = tuple(value)
        kwargs[key] = value
    return cls(**kwargs)
