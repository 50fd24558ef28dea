"""Environment torques: solar radiation pressure and aerodynamic drag on the spacecraft's facets, and the
torque of a residual magnetic dipole in the Earth's field.

Each effect is optional (``spacecraft.disturbance``); a run with none of them on packs no rows here and the
dynamics step does exactly what it did without this module. A run with one on gets extra rows in the body
array B of ``hil_sim.world.dynamics`` (after its ``B_FIELDS`` rows): the effects' switches, the Sun's position
(from the Earth's centre, written by the world kernels at the start of every step and held over it, as a
simulator's input message is) and the facets. The torques are evaluated at every RK4 stage from the stage's
attitude and orbit position, like the gravity gradient.

Solar radiation pressure on a flat facet of area A, outward unit normal n and centre of pressure c (from the
centre of mass), lit at cos(theta) = n . s > 0 (s: the unit vector to the Sun):

    F = -P A cos(theta) [ (1 - rho_s) s + 2 (rho_d / 3 + rho_s cos(theta)) n ],   tau = c x F

with P = (flux / c_light) (1 AU / |r_sun - r|)^2 times the sunlit fraction of the Sun's disc (the conical
shadow of gnc.eclipse: 0 in the umbra), rho_s and rho_d the specular and diffuse reflection
coefficients (the rest is absorbed). This is Basilisk's facetSRPDynamicEffector model; facets shadowing one
another are not modelled (a convex body has none).

Aerodynamic drag on a facet facing the flow, cos(theta) = n . v_hat > 0, v the velocity relative to the air:

    F = -1/2 rho |v|^2 C_D A cos(theta) v_hat,   tau = c x F,   v = v_orbit - omega_E x r

an exponential atmosphere rho = rho_ref exp(-(|r| - R_E - h_ref) / H) above the WGS-84 equatorial sphere,
rotating with the Earth about N's z axis (the pole's precession since J2000, ~0.3 deg, moves the air by
less than 0.01 % of the orbital speed). Basilisk's facetDragDynamicEffector model, with its
exponentialAtmosphere and zeroWindModel.

A residual dipole m (body axes, A m^2) in the Earth's field feels tau = m x B_B, the field a centred dipole
turning with the Earth (hil_sim.world.geomagnetic: IGRF's degree-1 part at the epoch; Basilisk's
magneticFieldCenteredDipole, and MtbEffector's m x B), or, where the mission asks for it, IGRF to degree N
(`earth_field_N`: the same Earth-fixed frame, its Gauss coefficients in rows after the facets).
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np
from numba import njit

from gnc.eclipse import SUN_RADIUS_KM, sunlit_fraction_at
from gnc.ephemeris import AU_KM, EARTH_RADIUS_KM
from gnc import _geomagnetic_nb
from hil_sim.world.geomagnetic import IGRF_REFERENCE_RADIUS_KM, degree_of, unnormalised_rows
from hil_sim.world.orbit import orbit_position_row_N_km, orbit_velocity_row_N_km_s
from hil_sim.world.params import SpacecraftParams

SPEED_OF_LIGHT_M_S = 299_792_458.0
EARTH_ROTATION_RAD_S = 7.292115e-5  # sidereal (IERS), as Basilisk's zeroWindModel takes it

# Rows of B after hil_sim.world.dynamics.B_FIELDS (24): switches (bits), the Sun held over the step, the solar flux,
# the number of facets, the atmosphere (reference density, its altitude, scale height, the Earth's rotation),
# the residual dipole (3), the Earth's dipole m = (g11, h11, g10) [T] and the Earth rotation angle at t = 0,
# the Earth's field model (its degree N; 0: the centred dipole) and the first row of its 2 x N (N + 3) / 2
# coefficients (after the facets), then FACET_FIELDS rows per facet from ENV_FACETS on.
ENV_FLAGS, ENV_SUN, ENV_FLUX, ENV_N_FACETS = 24, 25, 28, 29
ENV_RHO, ENV_H_REF, ENV_SCALE_H, ENV_OMEGA_E = 30, 31, 32, 33
ENV_DIPOLE, ENV_EARTH_DIPOLE, ENV_ERA0 = 34, 37, 40
ENV_FIELD_DEGREE, ENV_FIELD_FIRST = 41, 42
ENV_FACETS = 46
FACET_AREA, FACET_NORMAL, FACET_COP, FACET_SPECULAR, FACET_DIFFUSE, FACET_CD = 0, 1, 4, 7, 8, 9
FACET_FIELDS = 10
# bit k of ENV_FLAGS: effect k of EFFECTS on
# the order of environment_torques_B's rows, and their names in `keepout truth`'s file
EFFECTS = ("solar radiation pressure", "aerodynamic drag", "residual magnetic dipole")
EFFECT_KEYS = ("srp_torque_B_Nm", "drag_torque_B_Nm", "dipole_torque_B_Nm")


def effects_on(disturbance: Any) -> tuple[bool, bool, bool]:
    """Which of EFFECTS a disturbance (the mission's, or hil_sim.world.params.DisturbanceParams: the same names)
    turns on."""
    d = disturbance
    return (d.solar_radiation_pressure, d.aerodynamic_drag,
            any(d.residual_dipole_B_Am2) or bool(getattr(d, "dipole_torque", False)))


def environment_effects(mission: Any) -> list[str]:
    """The names (EFFECTS) of the environment effects a mission (hil_sim.mission.model.Mission) turns on."""
    return [name for name, on in zip(EFFECTS, effects_on(mission.spacecraft.disturbance)) if on]


def environment_rows(params: Sequence[SpacecraftParams]) -> np.ndarray | None:
    """The rows to append to the dynamics' B (ENV_FACETS + FACET_FIELDS * facets + the field's coefficients, M)
    for a batch, or None when no run has an environment effect on or a field model other than the dipole
    (B is then exactly as without this module). A run whose field is IGRF carries it even with no effect on:
    its magnetometer reads it (`field_rows`)."""
    flags = [sum(1 << k for k, on in enumerate(effects_on(p.disturbance)) if on) for p in params]
    fields = [unnormalised_rows(p.disturbance.geomagnetic_gauss_T) if p.disturbance.geomagnetic_gauss_T else None
              for p in params]
    if not any(flags) and not any(f is not None for f in fields):
        return None
    n_facets = max(len(p.facets) for p in params)
    first = ENV_FACETS + FACET_FIELDS * n_facets
    rows = np.zeros((first + max(f.size if f is not None else 0 for f in fields), len(params)))
    for m, p in enumerate(params):
        if fields[m] is not None:
            rows[ENV_FIELD_DEGREE, m] = degree_of(len(p.disturbance.geomagnetic_gauss_T))
            rows[ENV_FIELD_FIRST, m] = first
            rows[first:first + fields[m].size, m] = fields[m]
        rows[ENV_FLAGS, m] = flags[m]
        rows[ENV_FLUX, m] = p.disturbance.solar_flux_W_m2
        rows[ENV_N_FACETS, m] = len(p.facets)
        d = p.disturbance
        rows[ENV_RHO:ENV_OMEGA_E + 1, m] = (d.atmosphere_density_kg_m3, d.atmosphere_reference_altitude_km,
                                            d.atmosphere_scale_height_km, EARTH_ROTATION_RAD_S)
        g10, g11, h11 = d.geomagnetic_dipole_T
        rows[ENV_DIPOLE:ENV_ERA0 + 1, m] = (*d.residual_dipole_B_Am2, g11, h11, g10, d.earth_rotation_angle_rad)
        for k, f in enumerate(p.facets):
            o = ENV_FACETS + FACET_FIELDS * k
            rows[o + FACET_AREA, m] = f.area_m2
            rows[o + FACET_NORMAL:o + FACET_NORMAL + 3, m] = f.normal_B
            rows[o + FACET_COP:o + FACET_COP + 3, m] = f.centre_of_pressure_B_m
            rows[o + FACET_SPECULAR, m] = f.specular
            rows[o + FACET_DIFFUSE, m] = f.diffuse
            rows[o + FACET_CD, m] = f.drag_coefficient
    return rows[ENV_FLAGS:]


@njit(cache=True, error_model="numpy")
def hold_sun(B, sun_N_km):
    """Every run's Sun position (from the Earth's centre, km) for the coming step."""
    for m in range(B.shape[1]):
        B[ENV_SUN, m] = sun_N_km[0]
        B[ENV_SUN + 1, m] = sun_N_km[1]
        B[ENV_SUN + 2, m] = sun_N_km[2]


@njit(cache=True, error_model="numpy", inline="always")
def to_body(q0, q1, q2, q3, x, y, z):
    """R(q)^T v: a vector in N into body axes (R(q) rotates body vectors into N)."""
    return ((1.0 - 2.0 * (q2 * q2 + q3 * q3)) * x + 2.0 * (q1 * q2 + q0 * q3) * y + 2.0 * (q1 * q3 - q0 * q2) * z,
            2.0 * (q1 * q2 - q0 * q3) * x + (1.0 - 2.0 * (q1 * q1 + q3 * q3)) * y + 2.0 * (q2 * q3 + q0 * q1) * z,
            2.0 * (q1 * q3 + q0 * q2) * x + 2.0 * (q2 * q3 - q0 * q1) * y + (1.0 - 2.0 * (q1 * q1 + q2 * q2)) * z)


@njit(cache=True, error_model="numpy", inline="always")
def _moment(B, m, o, fx, fy, fz):
    """c x F: the moment about the centre of mass of force F on the facet at row o (its centre of pressure c)."""
    cx, cy, cz = B[o + FACET_COP, m], B[o + FACET_COP + 1, m], B[o + FACET_COP + 2, m]
    return cy * fz - cz * fy, cz * fx - cx * fz, cx * fy - cy * fx


@njit(cache=True, error_model="numpy", inline="always")
def srp_torque(B, m, q0, q1, q2, q3, rx, ry, rz):
    """The solar-radiation-pressure torque [N m] in body axes on run m at attitude q and position r [km]."""
    sx, sy, sz = B[ENV_SUN, m] - rx, B[ENV_SUN + 1, m] - ry, B[ENV_SUN + 2, m] - rz
    lit = sunlit_fraction_at(rx, ry, rz, sx, sy, sz, EARTH_RADIUS_KM, SUN_RADIUS_KM)
    tx = ty = tz = 0.0
    if lit == 0.0:
        return tx, ty, tz
    sn = math.sqrt(sx * sx + sy * sy + sz * sz)
    ux, uy, uz = to_body(q0, q1, q2, q3, sx / sn, sy / sn, sz / sn)
    au = AU_KM / sn
    pressure = B[ENV_FLUX, m] / SPEED_OF_LIGHT_M_S * au * au * lit
    for k in range(int(B[ENV_N_FACETS, m])):
        o = ENV_FACETS + FACET_FIELDS * k
        nx, ny, nz = B[o + FACET_NORMAL, m], B[o + FACET_NORMAL + 1, m], B[o + FACET_NORMAL + 2, m]
        cos = nx * ux + ny * uy + nz * uz
        if cos <= 0.0:
            continue  # the facet faces away from the Sun
        spec = B[o + FACET_SPECULAR, m]
        k_s = -pressure * B[o + FACET_AREA, m] * cos
        a = k_s * (1.0 - spec)
        b = k_s * 2.0 * (B[o + FACET_DIFFUSE, m] / 3.0 + spec * cos)
        mx, my, mz = _moment(B, m, o, a * ux + b * nx, a * uy + b * ny, a * uz + b * nz)
        tx, ty, tz = tx + mx, ty + my, tz + mz
    return tx, ty, tz


@njit(cache=True, error_model="numpy", inline="always")
def drag_torque(B, m, q0, q1, q2, q3, rx, ry, rz, vx, vy, vz):
    """The aerodynamic drag torque [N m] in body axes on run m at attitude q, position r [km] and inertial
    velocity v [km/s]."""
    w = B[ENV_OMEGA_E, m]
    # the velocity relative to the co-rotating air, m/s: v - omega_E z x r
    ax, ay, az = 1e3 * (vx + w * ry), 1e3 * (vy - w * rx), 1e3 * vz
    speed = math.sqrt(ax * ax + ay * ay + az * az)
    tx = ty = tz = 0.0
    if speed <= 1e-12:
        return tx, ty, tz
    ux, uy, uz = to_body(q0, q1, q2, q3, ax / speed, ay / speed, az / speed)
    h = math.sqrt(rx * rx + ry * ry + rz * rz) - EARTH_RADIUS_KM
    dynamic = 0.5 * B[ENV_RHO, m] * math.exp(-(h - B[ENV_H_REF, m]) / B[ENV_SCALE_H, m]) * speed * speed
    for k in range(int(B[ENV_N_FACETS, m])):
        o = ENV_FACETS + FACET_FIELDS * k
        cos = B[o + FACET_NORMAL, m] * ux + B[o + FACET_NORMAL + 1, m] * uy + B[o + FACET_NORMAL + 2, m] * uz
        if cos <= 0.0:
            continue  # in the facet's wake
        f = -dynamic * B[o + FACET_CD, m] * B[o + FACET_AREA, m] * cos
        mx, my, mz = _moment(B, m, o, f * ux, f * uy, f * uz)
        tx, ty, tz = tx + mx, ty + my, tz + mz
    return tx, ty, tz


@njit(cache=True, error_model="numpy", inline="always")
def dipole_field_N(B, m, rx, ry, rz, t_s):
    """The Earth's field [T] in N at position r [km] and time t_s: the centred dipole of run m, in the
    Earth-fixed frame turned by the rotation angle ERA0 + omega_E t about z."""
    th = B[ENV_ERA0, m] + B[ENV_OMEGA_E, m] * t_s
    c, s = math.cos(th), math.sin(th)
    rn = math.sqrt(rx * rx + ry * ry + rz * rz)
    ux, uy, uz = (c * rx + s * ry) / rn, (c * ry - s * rx) / rn, rz / rn  # r_hat, Earth-fixed
    k = IGRF_REFERENCE_RADIUS_KM / rn
    k = k * k * k
    mx, my, mz = B[ENV_EARTH_DIPOLE, m], B[ENV_EARTH_DIPOLE + 1, m], B[ENV_EARTH_DIPOLE + 2, m]
    d = 3.0 * (mx * ux + my * uy + mz * uz)
    bx, by, bz = k * (d * ux - mx), k * (d * uy - my), k * (d * uz - mz)
    return c * bx - s * by, s * bx + c * by, bz


@njit(cache=True, error_model="numpy", inline="always")
def earth_field_N(B, m, rx, ry, rz, t_s):
    """The Earth's field [T] in N at position r [km] and time t_s for run m: its centred dipole
    (`dipole_field_N`) or, when ENV_FIELD_DEGREE is N > 0, IGRF to degree N
    (gnc._geomagnetic_nb.field_E) in the same Earth-fixed frame."""
    degree = int(B[ENV_FIELD_DEGREE, m])
    if degree == 0:
        return dipole_field_N(B, m, rx, ry, rz, t_s)
    th = B[ENV_ERA0, m] + B[ENV_OMEGA_E, m] * t_s
    c, s = math.cos(th), math.sin(th)
    bx, by, bz = _geomagnetic_nb.field_E(B, m, int(B[ENV_FIELD_FIRST, m]), degree, c * rx + s * ry,
                                         c * ry - s * rx, rz)
    return c * bx - s * by, s * bx + c * by, bz


def compile_field_kernels() -> None:
    """Compile (or load) `earth_field_N` as the magnetometer calls it from Python on an IGRF mission: no shipped
    mission flies IGRF, so `keepout warmup`'s closed loops alone would leave it to such a run's first tick."""
    rows = np.zeros((ENV_FIELD_FIRST + 5, 1))
    rows[ENV_FIELD_DEGREE, 0], rows[ENV_FIELD_FIRST, 0] = 1.0, ENV_FIELD_FIRST + 1.0
    rows[ENV_FIELD_FIRST + 1, 0] = -3e-5  # g10 of a degree-1 field
    earth_field_N(rows, 0, 7000.0, 0.0, 0.0, 0.0)


def field_model_rows(B: np.ndarray) -> np.ndarray | None:
    """The world's B when its run 0 flies a field model other than the centred dipole (for `earth_field_N`),
    else None (the dipole: a magnetometer keeps its own rows for `dipole_field_N`)."""
    return B if B.shape[0] > ENV_FIELD_DEGREE and B[ENV_FIELD_DEGREE, 0] > 0.0 else None


@njit(cache=True, error_model="numpy", inline="always")
def dipole_torque(B, m, q0, q1, q2, q3, rx, ry, rz, t_s):
    """The residual dipole's torque m x B [N m] in body axes on run m at attitude q, position r [km], t_s (B:
    the Earth's field, `earth_field_N`)."""
    nx, ny, nz = earth_field_N(B, m, rx, ry, rz, t_s)
    bx, by, bz = to_body(q0, q1, q2, q3, nx, ny, nz)
    mx, my, mz = B[ENV_DIPOLE, m], B[ENV_DIPOLE + 1, m], B[ENV_DIPOLE + 2, m]
    return my * bz - mz * by, mz * bx - mx * bz, mx * by - my * bx


@njit(cache=True, error_model="numpy", inline="always")
def _effect_torque(effect, B, ORB, m, t_s, q0, q1, q2, q3, r):
    """Effect ``effect`` (an index of EFFECTS) on run m; r: its position at t_s [km]."""
    if effect == 0:
        return srp_torque(B, m, q0, q1, q2, q3, r[0], r[1], r[2])
    if effect == 2:
        return dipole_torque(B, m, q0, q1, q2, q3, r[0], r[1], r[2], t_s)
    vx, vy, vz = orbit_velocity_row_N_km_s(ORB, m, t_s)
    return drag_torque(B, m, q0, q1, q2, q3, r[0], r[1], r[2], vx, vy, vz)


@njit(cache=True, error_model="numpy", inline="always")
def add_environment_torque(X, B, ORB, m, t_s, r, tau):
    """tau[:, m] += the environment torques of run m at t_s (state X[:, m]); r: scratch (3,)."""
    flags = int(B[ENV_FLAGS, m])
    orbit_position_row_N_km(ORB, m, t_s, r)
    q0, q1, q2, q3 = X[0, m], X[1, m], X[2, m], X[3, m]
    for effect in range(len(EFFECTS)):
        if flags & (1 << effect):
            tx, ty, tz = _effect_torque(effect, B, ORB, m, t_s, q0, q1, q2, q3, r)
            tau[0, m] += tx
            tau[1, m] += ty
            tau[2, m] += tz


@njit(cache=True, error_model="numpy")
def environment_torques_B(X, B, ORB, t_s, out):
    """Each effect's torque [N m] on every run at t_s, state X: out (M, len(EFFECTS), 3), zero where off
    (what `keepout truth` records and `keepout budget` integrates: the kernels of the dynamics step)."""
    r = np.empty(3)
    for m in range(X.shape[1]):
        flags = int(B[ENV_FLAGS, m])
        orbit_position_row_N_km(ORB, m, t_s, r)
        q0, q1, q2, q3 = X[0, m], X[1, m], X[2, m], X[3, m]
        for effect in range(len(EFFECTS)):
            out[m, effect, 0] = out[m, effect, 1] = out[m, effect, 2] = 0.0
            if flags & (1 << effect):
                out[m, effect, 0], out[m, effect, 1], out[m, effect, 2] = _effect_torque(
                    effect, B, ORB, m, t_s, q0, q1, q2, q3, r)
