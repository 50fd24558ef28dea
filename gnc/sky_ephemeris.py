"""Onboard sky ephemeris: the Sun, Moon and Earth directions seen from the spacecraft, from the
analytic series (`gnc.ephemeris`) and the configured circular orbit; and the directions of targets on the
rotating Earth (nadir, a ground point: `gnc.earth`).

The flight software's guidance steers with it; the ground console and the mission check evaluate the same
model, so that all three see the zones where the flight software sees them. ``cfg`` is the flight software's
configuration (`fsw.config.FswConfig`: its epoch, orbit knowledge and pointing zones)."""
from __future__ import annotations

import math

import numpy as np

from gnc._sky_ephemeris_nb import sky_directions_nb
from gnc.eclipse import SUN_RADIUS_KM, sunlit_fraction_at
from gnc.earth import direction_to_point_N, earth_fixed_to_inertial, geodetic_to_earth_fixed_km, nadir_N
from gnc.ephemeris import EARTH_RADIUS_KM, julian_date, julian_date_tdb, moon_position_N_km, sun_position_N_km

EPHEMERIS_NODE_S = 10.0
EPHEMERIS_BLOCK_NODES = 32  # nodes evaluated in one batched call of the series (320 s of flight)
_MU_EARTH_KM3_S2 = 398600.4418


class SkyEphemeris:
    """Onboard directions of the Sun, Moon and Earth from the spacecraft (N frame) at mission time t."""

    def __init__(self, cfg):
        self.jd0 = julian_date_tdb(cfg.epoch_utc)
        o = cfg.orbit
        self.radius_km = float(o.radius_km)
        self.n_rad_s = math.sqrt(_MU_EARTH_KM3_S2 / o.radius_km**3)
        i, raan = math.radians(o.inclination_deg), math.radians(o.raan_deg)
        self.u0 = math.radians(o.arg_latitude_at_epoch_deg)
        node = np.array([math.cos(raan), math.sin(raan), 0.0])
        # in-plane axis 90 deg ahead of the ascending node
        self.p_hat = node
        self.q_hat = np.array([-math.sin(raan) * math.cos(i), math.cos(raan) * math.cos(i), math.sin(i)])
        self.jd0_utc = julian_date(cfg.epoch_utc)
        atmosphere_km = cfg.pointing.atmosphere_height_km()
        # the Earth zones' limb: the solid Earth's, or the top of the atmosphere when a zone asks for it
        limb_km = EARTH_RADIUS_KM if atmosphere_km is None else EARTH_RADIUS_KM + atmosphere_km
        self.earth_angular_radius_deg = math.degrees(math.asin(min(1.0, limb_km / o.radius_km)))
        self._block_first = 0  # node of the block's first row
        self._block: tuple[np.ndarray, np.ndarray] | None = None  # Sun and Moon positions [km], a row per node

    def position_N_km(self, t_s: float) -> np.ndarray:
        u = self.u0 + self.n_rad_s * t_s
        return self.radius_km * (math.cos(u) * self.p_hat + math.sin(u) * self.q_hat)

    def velocity_direction_N(self, t_s: float) -> np.ndarray:
        """Unit vector of the spacecraft's velocity in N at mission time ``t_s`` (the circular orbit's)."""
        u = self.u0 + self.n_rad_s * t_s
        return -math.sin(u) * self.p_hat + math.cos(u) * self.q_hat

    def orbit_normal_N(self) -> np.ndarray:
        """Unit normal of the orbit plane in N (along the orbital angular momentum)."""
        return np.cross(self.p_hat, self.q_hat)

    def sunlit_fraction(self, t_s: float) -> float:
        """Share of the Sun's disc seen past the Earth at mission time ``t_s``: 1 in full Sun, 0 in the umbra,
        between in the penumbra (`gnc.eclipse`, the truth's conical shadow, on the onboard Sun and orbit).

        The geocentric Sun is interpolated between ephemeris nodes as in `directions`; the Earth is the
        sphere of radius EARTH_RADIUS_KM, as the truth's shadow."""
        k = math.floor(t_s / EPHEMERIS_NODE_S)
        f = t_s / EPHEMERIS_NODE_S - k
        s0 = self._geocentric(k)[0]
        s1 = self._geocentric(k + 1)[0]
        sun = s0 + f * (s1 - s0)
        r = self.position_N_km(t_s)
        s = sun - r
        return float(sunlit_fraction_at(float(r[0]), float(r[1]), float(r[2]), float(s[0]), float(s[1]),
                                        float(s[2]), EARTH_RADIUS_KM, SUN_RADIUS_KM))

    def target_direction_N(self, t_s: float, ground_E_km: np.ndarray | None) -> np.ndarray:
        """Unit vector in N from the spacecraft to a target on the Earth at mission time ``t_s``: the Earth
        fixed point ``ground_E_km`` [km] (`ground_point_E_km`), or nadir (None)."""
        r_sc = self.position_N_km(t_s)
        if ground_E_km is None:
            return nadir_N(r_sc)
        return direction_to_point_N(r_sc, earth_fixed_to_inertial(self.jd0_utc + t_s / 86400.0) @ ground_E_km)

    @staticmethod
    def ground_point_E_km(ground) -> np.ndarray:
        """Earth-fixed position [km] of a `fsw.config.GroundTargetConfig`."""
        return geodetic_to_earth_fixed_km(ground.latitude_deg, ground.longitude_deg, ground.altitude_m)

    def _geocentric(self, node: int) -> tuple[np.ndarray, np.ndarray]:
        """Geocentric Sun and Moon positions [km] at ephemeris node ``node``.

        The series are numpy expressions of the time, element by element: evaluated for a block of
        EPHEMERIS_BLOCK_NODES nodes at once they give each node's numbers exactly as one evaluation per
        node did (tests/fsw/test_guidance.py), in the time of three or four single nodes (one node is ~100
        numpy calls on scalars). A block starts one node before the missing one, so that the pair of
        nodes a cycle interpolates between is always in one block."""
        i = node - self._block_first
        block = self._block
        if block is None or not 0 <= i < EPHEMERIS_BLOCK_NODES:
            self._block_first = first = node - 1
            nodes = np.arange(first, first + EPHEMERIS_BLOCK_NODES)
            jd = self.jd0 + nodes * EPHEMERIS_NODE_S / 86400.0
            self._block = block = (np.asarray(sun_position_N_km(jd), dtype=float),
                                   np.asarray(moon_position_N_km(jd), dtype=float))
            i = 1
        return block[0][i], block[1][i]

    def directions(self, t_s: float) -> dict[str, np.ndarray]:
        """Unit vectors from the spacecraft to the Sun, Moon and Earth centre in N.

        The analytic series are evaluated every EPHEMERIS_NODE_S seconds and interpolated linearly in
        between (error < 1e-6 deg for the Moon over 10 s, far below the series' own 0.3 deg); the
        spacecraft position (parallax) is evaluated every call.
        """
        k = math.floor(t_s / EPHEMERIS_NODE_S)
        f = t_s / EPHEMERIS_NODE_S - k
        s0, m0 = self._geocentric(k)
        s1, m1 = self._geocentric(k + 1)
        d = sky_directions_nb(float(t_s), self.u0, self.n_rad_s, self.radius_km, self.p_hat, self.q_hat, f,
                              s0, s1, m0, m1)
        return {"sun": d[0], "moon": d[1], "earth": d[2]}
