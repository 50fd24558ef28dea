"""Helpers for closed-loop tests: flight software against the hil_sim truth models.

`DirectLoop` runs the flight software and a `hil_sim.world.world.World` in lockstep without a bus (the driver
is a recorder that hands the wheel commands straight to the world). It exercises the same
`FlightSoftware.run_cycle` code as the bus path, at unit-test speed; the bus path itself is tested with
the virtual CAN interface elsewhere.
"""
from __future__ import annotations

import math

import numpy as np

from fsw.bus.driver import ImuSample, StarTrackerSample, TickInputs, WheelStatus
from fsw.config import FswConfig


class RecordingDriver:
    """Stands in for FswBusDriver: keeps the last wheel command, counts cycle-done and heartbeats."""

    def __init__(self, n_wheels: int):
        self.n_wheels = n_wheels
        self.torques = np.zeros(n_wheels)
        self.cycle_done = 0
        self.heartbeats = 0
        self.counters: dict[str, dict[str, int]] = {}

    def send_wheel_torques(self, tick, torques, cycle_done=False):
        assert len(torques) == self.n_wheels
        self.torques = np.asarray(torques, dtype=float)
        self.cycle_done += int(cycle_done)

    def send_cycle_done(self, tick):
        self.cycle_done += 1

    def send_heartbeat(self, mode, cycle):
        self.heartbeats += 1


def fsw_config_for(world_params, **sections) -> FswConfig:
    """An FswConfig whose spacecraft/orbit knowledge matches the world (plus section overrides)."""
    sc = world_params.spacecraft
    o = world_params.orbit
    st = world_params.star_tracker
    data = {
        "epoch_utc": world_params.epoch_utc.replace("Z", "+00:00"),
        "spacecraft": {
            "inertia_B_kgm2": [list(r) for r in sc.inertia_B_kgm2],
            "wheels": [
                {"axis_B": list(w.axis_B), "max_torque_Nm": w.max_torque_Nm, "max_speed_rad_s": w.max_speed_rad_s,
                 "spin_inertia_kgm2": w.Js_kgm2}
                for w in sc.wheels
            ],
            "star_tracker_q_BS": list(st.q_BS),
        },
        "orbit": {
            "radius_km": o.semi_major_axis_km,
            "inclination_deg": o.inclination_deg,
            "raan_deg": o.raan_deg,
            "arg_latitude_at_epoch_deg": o.arg_perigee_deg + o.mean_anomaly_deg,
        },
        "estimator": {
            "gyro_arw_rad_s_sqrt_hz": max(world_params.imu.angle_random_walk_rad_per_sqrt_s, 1e-6),
            "gyro_bias_rw_rad_s2_sqrt_hz": max(world_params.imu.bias_random_walk_rad_s_per_sqrt_s, 1e-8),
            "star_tracker_sigma_arcsec": max(st.cross_boresight_std_arcsec, st.about_boresight_std_arcsec, 1.0),
        },
    }
    for key, value in sections.items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            merged = dict(data[key])
            merged.update(value)
            data[key] = merged
        else:
            data[key] = value
    return FswConfig.model_validate(data)


class DirectLoop:
    """Flight software + World in lockstep: per tick, IMU samples over the tick, star tracker at its rate."""

    def __init__(self, fsw, world, period_s: float):
        self.fsw = fsw
        self.world = world
        self.period_s = period_s
        self.n_imu = max(1, round(period_s / world.imu_period_s))
        self.st_every = max(1, round(world.star_tracker_period_s / period_s))
        self.tick = 0
        self._imu_batch: list[ImuSample] = []
        self.drop_imu = False
        self.drop_st = False
        self.wheel_fault_override: dict[int, int] = {}

    def inputs(self) -> TickInputs:
        w = self.world
        t = self.tick * self.period_s
        st = None
        if self.tick % self.st_every == 0 and not self.drop_st:
            s = w.star_tracker_sample()
            st = StarTrackerSample(np.asarray(s.q_NS, dtype=float), bool(s.valid), int(s.blind_source), t)
        wheels = []
        for i, ws in enumerate(w.wheel_status()):
            # world bits (1 stuck, 2 no torque, 4 speed limit) -> ICD bits (1 overspeed, 4 drive fault)
            fault = (1 if ws.fault & 4 else 0) | (4 if ws.fault & 3 else 0)
            fault = self.wheel_fault_override.get(i, fault)
            wheels.append(WheelStatus(ws.speed_rad_s, ws.torque_Nm, ws.current_A, ws.temp_C, fault, t))
        imu = [] if self.drop_imu else self._imu_batch
        return TickInputs(self.tick, t, self.period_s, imu[-1] if imu else None, st, wheels, list(imu))

    def step(self) -> None:
        """One tick: FSW cycle on the current inputs, then the world over one period."""
        self.fsw.run_cycle(self.inputs())
        torques = self.fsw.driver.torques
        self._imu_batch = []
        dt = self.period_s / self.n_imu
        for k in range(self.n_imu):
            self.world.step(dt, torques)
            s = self.world.imu_sample()
            self._imu_batch.append(ImuSample(np.asarray(s.omega_BN_B, dtype=float), bool(s.saturated),
                                             (self.tick + (k + 1) / self.n_imu) * self.period_s))
        self.tick += 1

    def prime(self) -> None:
        """Fill the first IMU batch (the first cycle otherwise has no gyro sample)."""
        s = self.world.imu_sample()
        self._imu_batch = [ImuSample(np.asarray(s.omega_BN_B, dtype=float), bool(s.saturated), 0.0)]


def boresight_N(q_NB: np.ndarray, b_B: np.ndarray) -> np.ndarray:
    from gnc.attitude import quat_rotate

    return np.asarray(quat_rotate(q_NB, b_B))


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(max(-1.0, min(1.0, float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))))))


class BusLoop:
    """Flight software and `hil_sim.sil.lockstep.Simulator` in one process on a ``virtual`` CAN bus.

    Every frame goes through the ICD encoding, E2E protection and the flight software's bus driver, and
    the simulator's fault injector (``faults``: hil_sim.devices.faults.FaultSpec or dicts) can act on it.
    """

    _channel = 0

    def __init__(self, cfg, world, faults=(), telemetry=None, dispatcher=None, clock=None):
        from fsw.app import FlightSoftware
        from fsw.bus import FswBusDriver
        from comms.bus import Icd, open_bus
        from hil_sim.sil.lockstep import Simulator

        BusLoop._channel += 1
        name = f"virtual:closed-loop-{id(self)}-{BusLoop._channel}"
        self.icd = Icd()
        self.sim_bus, self.fsw_bus = open_bus(name), open_bus(name)
        self.sim = Simulator(world, self.sim_bus, self.icd, gnc_period_s=cfg.gnc_period_s, faults=faults)
        self.driver = FswBusDriver(self.fsw_bus, self.icd, len(cfg.spacecraft.wheels))
        extra = {} if clock is None else {"clock": clock}
        self.fsw = FlightSoftware(cfg, self.driver, telemetry, dispatcher, **extra)
        self.world = world

    def step(self) -> bool:
        def cycle():
            inputs = self.driver.collect_tick(0.0)
            if inputs is not None:
                self.fsw.run_cycle(inputs)

        return self.sim.step_in_process(cycle)

    def run(self, n: int, every=None) -> None:
        for k in range(n):
            self.step()
            if every is not None:
                every(k)

    def close(self) -> None:
        self.fsw.checker.close()
        self.sim_bus.shutdown()
        self.fsw_bus.shutdown()


def blind_free_bus_loop(epoch_utc: str, sections: dict, seed: int, faults=(), q0=(1.0, 0.0, 0.0, 0.0)):
    """A `BusLoop` from the flight-software config ``sections``, in a world whose star tracker has no Sun
    or Moon exclusion (so only the faults a test injects make it stale) and with telemetry and commanding
    in process (no sockets); returns (loop, telemetry sender, command dispatcher)."""
    from comms.dictionary import DICTIONARY
    from fsw.telecommand import CommandDispatcher
    from fsw.telemetry import TelemetrySender
    from hil_sim.world.params import SpacecraftParams, StarTrackerParams, WorldParams
    from hil_sim.world.world import World

    wp = WorldParams(epoch_utc=epoch_utc, spacecraft=SpacecraftParams(q_NB0=tuple(q0)),
                     star_tracker=StarTrackerParams(sun_exclusion_deg=0.0, moon_exclusion_deg=0.0))
    cfg = fsw_config_for(wp, **sections)
    tm = TelemetrySender(DICTIONARY, port=None)
    tc = CommandDispatcher(DICTIONARY, tm, port=None)
    return BusLoop(cfg, World(wp, seed=seed), faults=faults, telemetry=tm, dispatcher=tc), tm, tc


def slew_geometry(epoch_utc: str, beta_deg: float = 32.0, offset_deg: float = 3.0, half_span_deg: float = 60.0):
    """Start and target boresight directions for a 2*half_span slew whose straight path passes
    ``offset_deg`` from the Sun centre, on the side of the Moon, heading at ``beta_deg`` from the
    Sun-Moon direction. Returns (y0_N, yd_N, sun_N, moon_N) from the onboard ephemeris (geocentric)."""
    from gnc.ephemeris import julian_date_tdb, moon_direction_N, sun_direction_N

    jd = julian_date_tdb(epoch_utc)
    s = sun_direction_N(jd)
    m = moon_direction_N(jd)
    tm = m - (m @ s) * s
    tm /= np.linalg.norm(tm)
    beta = math.radians(beta_deg)
    t = math.cos(beta) * tm + math.sin(beta) * np.cross(s, tm)
    n = np.cross(s, t)
    side = 1.0 if m @ n > 0 else -1.0
    off = math.radians(offset_deg)
    c0 = math.cos(off) * s + math.sin(off) * side * n
    t0 = t - (t @ c0) * c0
    t0 /= np.linalg.norm(t0)
    h = math.radians(half_span_deg)
    return math.cos(h) * c0 - math.sin(h) * t0, math.cos(h) * c0 + math.sin(h) * t0, s, m


def attitude_with_boresight(y_N: np.ndarray, b_B=(0.0, 0.0, 1.0)) -> np.ndarray:
    """A q_NB that puts body axis b_B on y_N (shortest rotation), scalar first."""
    from scipy.spatial.transform import Rotation

    b = np.asarray(b_B, dtype=float)
    axis = np.cross(b, y_N)
    s = np.linalg.norm(axis)
    ang = math.atan2(s, float(b @ y_N))
    rot = Rotation.from_rotvec(axis / s * ang) if s > 1e-12 else Rotation.identity()
    return np.roll(rot.as_quat(), 1)
