"""The one place where a cycle's sensor inputs become a `fsw.records.SensorSnapshot`.

The bus driver hands the flight software one of two views: lockstep `TickInputs` (everything received for
one SYNC tick; the driver's own carry its gyro rows and wheel status as arrays) and real-time
`LatestInputs` (the newest sample of each kind with its age on the driver clock). A test may build either by
hand. `SensorIntake.snapshot` reads any of them, applies the freshness rules the flight software keeps
(real-time ages, the star tracker's maximum age and norm check) and the bus-health bookkeeping that needs
the driver's E2E counters (frames rejected since the last cycle; wheels heard only through corrupt
frames), and returns the snapshot every stage after it reads.
"""
from __future__ import annotations

import math
from itertools import repeat
from typing import Any

import numpy as np

from fsw.bus.driver import TickInputs
from fsw.records import NAN3, NO_CELLS, SensorSnapshot, new_record

# the E2E classes that count as a rejected (corrupt) frame
CORRUPT_CLASSES = ("crc_error", "bad_length", "out_of_range", "wrong_sequence")
# longest run of cycles [s] in which a wheel's status frames arrive only corrupt and the wheel still counts
# as heard (a bus fault); past it nothing has been read from the wheel for that long: silence
CORRUPT_STATUS_HEARD_S = 10.0
_NO_SAMPLES = np.zeros((0, 3))


def vector_norm(v: list[float]) -> float:
    """Euclidean norm of a short list of floats (numpy's call overhead is most of a 4-vector's norm)."""
    total = 0.0
    for x in v:
        total += x * x
    return math.sqrt(total)


def _status_rejections(counts: dict | None) -> int:
    return 0 if counts is None else sum(counts.get(k, 0) for k in CORRUPT_CLASSES)


class SensorIntake:
    """Turns each cycle's inputs into a `SensorSnapshot` (see the module docstring).

    ``driver``: the bus driver, whose ``counters`` (E2E classes per message) are read; ``n_wheels``;
    ``period_s``: the GNC period; ``st_max_age_s``: the oldest star-tracker fix the estimator may use."""

    def __init__(self, driver: Any, n_wheels: int, period_s: float, st_max_age_s: float,
                 magnetic: Any = None) -> None:
        self.driver = driver
        # the magnetometer's and sun sensors' frames this flight software reads (fsw.config.MagneticDevicesConfig)
        self._mag = magnetic is not None and magnetic.magnetometer
        self._css = magnetic is not None and magnetic.sun_sensors
        self._cols: dict[str, list[int]] = {}  # the value rows' slots of their signals, in DBC order
        for on, name in ((self._mag, "MAG_FIELD"), (self._css, "CSS_CURRENTS")):
            if on:
                driver.keep_latest(name)
                self._cols[name] = [driver.icd.column(name, s) for s in driver.icd.spec(name).signals]
        self.period_s = period_s
        self.st_max_age_s = st_max_age_s
        self._rt_t0: float | None = None  # driver clock of the first real-time cycle
        self._corrupt_src: dict | None = None
        self._corrupt_dicts: tuple[list[dict], list[str], list[dict], list[str]] = ([], [], [], [])
        self._corrupt_totals: tuple[int, int] = (0, 0)  # (IMU, star tracker) E2E rejections so far
        # wheels whose status frames arrive but fail E2E: heard, not silent (_heard_through_corruption)
        self._wheel_status_msgs = [f"RW{i + 1}_STATUS" for i in range(n_wheels)]
        self._wheel_corrupt_src: dict | None = None
        self._wheel_corrupt_dicts: list = []
        self._wheel_corrupt_seen: list[int] = []
        self._wheel_corrupt_since = [math.nan] * n_wheels
        self._wheel_corrupt_pairs: tuple[list, list] = ([], [])
        self._wheel_corrupt_total = 0
        self._wheel_corrupt_streak = False

    @staticmethod
    def tick_of(inputs: Any, cycle: int) -> int:
        """The tick ``inputs`` belong to: a lockstep tick's own, else ``cycle`` (real time)."""
        return int(inputs.tick) if hasattr(inputs, "tick") else cycle

    def snapshot(self, inputs: Any, cycle: int) -> SensorSnapshot:
        """This cycle's snapshot of ``inputs``: a lockstep tick (anything with a ``tick``: onboard time is the
        tick's own) or a real-time view (onboard time is the driver clock since the first such cycle, the
        tick is ``cycle``)."""
        dt = self.period_s
        driver_tick = type(inputs) is TickInputs  # the array fast paths of the driver's own ticks
        if driver_tick or hasattr(inputs, "tick"):
            t_s, tick, realtime = float(inputs.t), int(inputs.tick), False
            imu = inputs.imu
        else:
            if self._rt_t0 is None:
                self._rt_t0 = float(inputs.t)
            t_s, tick, realtime = float(inputs.t) - self._rt_t0, cycle, True
            imu = inputs.imu
            age = inputs.imu_age_s  # a sample older than 2.5 cycles counts as none
            if imu is not None and (age is None or age > 2.5 * dt):
                imu = None
        if imu is not None and not getattr(imu, "valid", True):
            imu = None
        # the driver's tick: its decoded gyro rows (every one valid) are the estimator's (n, 3) samples as
        # they are, without building an ImuSample per row
        samples = inputs.fresh_imu_omega_BN_B() if driver_tick else None
        if samples is None:
            samples = self._gyro_rows(inputs, imu)
        st = inputs.star_tracker
        fresh, q_NS, latency, nq = self._star_tracker(inputs, st, realtime)
        speeds, faults = self._wheels(inputs, driver_tick, realtime, dt)
        imu_corrupt, st_corrupt = self._corrupt_deltas()
        return new_record(SensorSnapshot, (
            tick, t_s, dt, realtime, samples, imu is not None, st is not None, st.blind_source if st is not None else 0,
            fresh, q_NS if fresh else None, nq, latency, speeds, self._heard_through_corruption(faults, t_s),
            imu_corrupt, st_corrupt, self._field(inputs) if self._mag else NAN3,
            self._cells(inputs) if self._css else NO_CELLS))

    def _fresh_row(self, name: str, inputs: Any) -> list | None:
        """The newest delivered ``name`` frame's application values (DBC order), when it came this cycle (in
        lockstep: with this tick; in real time: within 1.5 periods)."""
        kept = self.driver.latest(name)
        if kept is None or float(inputs.t) - kept[1] > 1.5 * self.period_s:
            return None
        row = kept[0]
        return [row[c] for c in self._cols[name]]

    def _field(self, inputs: Any) -> np.ndarray:
        """MAG_FIELD of this cycle as the field in sensor axes [T], NaN without a valid one."""
        row = self._fresh_row("MAG_FIELD", inputs)
        if row is None or row[3] < 0.5:
            return NAN3
        return 1e-6 * np.array(row[:3])

    def _cells(self, inputs: Any) -> np.ndarray:
        """CSS_CURRENTS of this cycle as the fitted cells' outputs [mA], no cells without one."""
        row = self._fresh_row("CSS_CURRENTS", inputs)
        return NO_CELLS if row is None else np.array(row[:int(row[6])])

    @staticmethod
    def _gyro_rows(inputs: Any, imu: Any) -> np.ndarray:
        """The valid gyro samples of ``inputs`` as an (n, 3) array; the newest sample alone when the inputs
        list none, no rows when there is none at all."""
        imu_samples = getattr(inputs, "imu_samples", None) or ()
        rows = [s.omega_BN_B for s in imu_samples if getattr(s, "valid", True)] or (
            [imu.omega_BN_B] if imu is not None else None)
        return _NO_SAMPLES if rows is None else np.array(rows, dtype=float).reshape(-1, 3)

    def _star_tracker(self, inputs: Any, st: Any, realtime: bool) -> tuple[bool, np.ndarray | None, float, float]:
        """(fresh?, q_NS, latency [s], |q_NS|) of the star tracker sample ``st``: fresh when valid, no older
        than star_tracker_max_age_s and of a norm the estimator can use (q_NS None when not valid)."""
        if st is None or not st.valid:
            return False, None, 0.0, 1.0
        if realtime:
            st_latency = float(inputs.star_tracker_age_s or 0.0)
        else:
            st_latency = max(0.0, float(inputs.t) - float(st.t))
        q_NS = np.ascontiguousarray(st.q_NS, dtype=float)
        nq = vector_norm(q_NS.tolist())
        return not st_latency > self.st_max_age_s and 0.9 < nq < 1.1, q_NS, st_latency, nq

    @staticmethod
    def _wheels(inputs: Any, driver_tick: bool, realtime: bool, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """(speeds, fault flags) of the wheels: NaN and -1 for a wheel with no status this cycle (in real time,
        none for 3 cycles)."""
        wheel_arrays = inputs.fresh_wheel_arrays() if driver_tick else None
        if wheel_arrays is not None:
            return wheel_arrays
        wheels = inputs.wheels
        if realtime:
            ages = inputs.wheel_ages_s
            wheels = [w if (w is not None and a is not None and a < 3 * dt) else None for w, a in zip(wheels, ages)]
        speeds = np.array([w.speed_rad_s if w is not None else math.nan for w in wheels], dtype=float)
        faults = np.array([w.fault if w is not None else -1 for w in wheels], dtype=np.int64)
        return speeds, faults

    def _corrupt_deltas(self) -> tuple[int, int]:
        """(IMU, star tracker) frames rejected by E2E since the last cycle."""
        counters = self.driver.counters
        if counters is not self._corrupt_src:
            # the per-message counter dicts live as long as the receiver: look them up once, as the
            # (dict, class) pairs each sensor's total sums (IMU dicts, IMU classes, tracker dicts, classes)
            self._corrupt_src = counters
            self._corrupt_dicts = tuple(
                part
                for msgs in (("IMU_RATE",), ("ST_QUAT_A", "ST_QUAT_B"))
                for part in ([counters[m] for m in msgs if m in counters for _ in CORRUPT_CLASSES],
                             [k for m in msgs if m in counters for k in CORRUPT_CLASSES]))
        imu_dicts, imu_keys, st_dicts, st_keys = self._corrupt_dicts
        # integer sums in C (map over dict.get): the same totals as a loop
        imu_total = sum(map(dict.get, imu_dicts, imu_keys, repeat(0)))
        st_total = sum(map(dict.get, st_dicts, st_keys, repeat(0)))
        imu_prev, st_prev = self._corrupt_totals
        self._corrupt_totals = (imu_total, st_total)
        return max(0, imu_total - imu_prev), max(0, st_total - st_prev)

    def _heard_through_corruption(self, faults: np.ndarray, t_s: float) -> np.ndarray:
        """Wheel fault flags with a wheel whose status frames arrived this cycle but failed E2E (CRC, length,
        range, sequence) counted as heard, not silent (no flag, its speed unknown): corrupt frames are a bus
        fault (BUS_CORRUPT), not a wheel's, and the wheel still obeys its commands. A streak of such cycles
        longer than CORRUPT_STATUS_HEARD_S is silence after all (nothing has been read from it for that long)."""
        counters = self.driver.counters
        if counters is not self._wheel_corrupt_src:
            self._wheel_corrupt_src = counters
            self._wheel_corrupt_dicts = [counters.get(m) for m in self._wheel_status_msgs]
            self._wheel_corrupt_seen = [_status_rejections(d) for d in self._wheel_corrupt_dicts]
            pairs = [(d, k) for d in self._wheel_corrupt_dicts if d is not None for k in CORRUPT_CLASSES]
            self._wheel_corrupt_pairs = ([d for d, _ in pairs], [k for _, k in pairs])
            self._wheel_corrupt_total = sum(self._wheel_corrupt_seen)
        # the usual cycle: no status frame rejected since the last one and no streak running (a C-level sum)
        total = sum(map(dict.get, *self._wheel_corrupt_pairs, repeat(0)))
        if total == self._wheel_corrupt_total and not self._wheel_corrupt_streak:
            return faults
        self._wheel_corrupt_total = total
        out = faults
        for i, d in enumerate(self._wheel_corrupt_dicts):
            total = _status_rejections(d)
            rejected = total != self._wheel_corrupt_seen[i]
            self._wheel_corrupt_seen[i] = total
            if faults[i] >= 0 or not rejected:
                self._wheel_corrupt_since[i] = math.nan
                continue
            self._wheel_corrupt_streak = True
            if math.isnan(self._wheel_corrupt_since[i]):
                self._wheel_corrupt_since[i] = t_s
            if t_s - self._wheel_corrupt_since[i] <= CORRUPT_STATUS_HEARD_S:
                if out is faults:
                    out = np.array(faults, dtype=np.int64)
                out[i] = 0
        self._wheel_corrupt_streak = any(not math.isnan(t) for t in self._wheel_corrupt_since)
        return out
