"""The GNC cycle's messages: what each stage reads and writes.

One cycle, as Basilisk's flight modules pass messages (each stage reads its input record, calls pure
maths, writes its output record)::

    SensorSnapshot -> estimator -> AttitudeEstimate -> guidance -> GuidanceOutput -> control
                   -> ControlOutput -> FDIR

`SensorSnapshot` is made in one place (`fsw.intake.SensorIntake`) from whatever the caller brings: the bus
driver's lockstep `TickInputs` or real-time `LatestInputs`, or a test's hand-built ticks. Every stage after it
sees that one shape only.

The records are built every cycle (10-50 Hz; the whole cycle takes some tens of microseconds): the two
made by the cycle itself are NamedTuples (immutable; built and read in C, a fraction of a microsecond).
`GuidanceOutput` and `ControlOutput` keep the dataclass form their stages fill (the pointing mode sets a
GuidanceOutput's fields in one step; FDIR and telemetry read them by name).

Not to be confused with `fsw.plugins.AttitudeEstimate`, the part of an estimate a plug-in returns; the guard
(`fsw.plugin_guard.GuardedEstimator`) turns that into this module's `AttitudeEstimate`.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np


def _nan_constant(n: int) -> np.ndarray:
    a = np.full(n, np.nan)
    a.flags.writeable = False  # shared by every output that has no such vector: nobody may write into it
    return a


# a vector a record does not have this cycle: shared and read-only
NAN3, NAN4, NO_CELLS = _nan_constant(3), _nan_constant(4), _nan_constant(0)
# builds a NamedTuple record from the tuple of its fields in their declared order, without the generated
# constructor's argument handling: half its cost, for the records the cycle makes every tick
new_record = tuple.__new__


class SensorSnapshot(NamedTuple):
    """What the flight software learned from its sensors for one cycle, checked and converted.

    Times on the onboard clock [s]; ``tick`` the simulator's SYNC tick in lockstep, the cycle count in real
    time. Star tracker: ``q_NS`` (scalar first, as transmitted: not renormalised) only when the fix is fresh
    (valid, no older than star_tracker_max_age_s, a norm within 10 % of one), else None; ``q_NS_norm`` its
    norm (1.0 when there is no valid fix), ``st_latency_s`` its age at ``t_s``. Wheels: speed [rad/s] and
    fault flags (RWn_STATUS bits), NaN and -1 for a wheel that reported nothing this cycle, flags 0 for one
    heard only through corrupt frames (a bus fault, not the wheel's). Magnetometer (``flight_software.
    magnetic_devices``): ``mag_S_T`` the field in sensor axes [T] of this cycle's valid MAG_FIELD, NaN without
    one; sun sensors: ``css_mA`` the fitted cells' outputs [mA] of this cycle's CSS_CURRENTS, no cells without
    one."""

    tick: int
    t_s: float
    dt_s: float                   # the cycle period [s]
    realtime: bool                # paced on the monotonic clock (no lockstep CYCLE_DONE)
    gyro_B: np.ndarray            # (n, 3) body rates [rad/s] sampled evenly over the cycle, the last now
    imu_valid: bool               # a valid gyro sample arrived this cycle (in real time: none older than 2.5 cycles)
    st_heard: bool                # the star tracker answered, valid or blind
    st_blind_source: int          # 0 none, 1 Sun, 2 Moon, 3 rate (0 when the tracker did not answer)
    st_fresh: bool                # ``q_NS`` is a usable fix
    q_NS: np.ndarray | None
    q_NS_norm: float
    st_latency_s: float
    wheel_speed_rad_s: np.ndarray
    wheel_fault: np.ndarray       # int64 flags per wheel
    imu_corrupt: int              # IMU frames rejected by E2E since the last cycle
    st_corrupt: int               # star tracker frames rejected by E2E since the last cycle
    mag_S_T: np.ndarray = NAN3    # magnetometer field in sensor axes [T] (NaN: none this cycle)
    css_mA: np.ndarray = NO_CELLS  # sun sensor cell outputs [mA] (no cells: none this cycle)

    @classmethod
    def of_measurements(cls, dt_s: float, gyro_B: np.ndarray, q_NS: np.ndarray | None, st_latency_s: float = 0.0,
                        q_NS_norm: float = 1.0) -> SensorSnapshot:
        """The estimator's measurements alone (studies, tests, the start-up warm-up): gyro rows (n, 3)
        [rad/s] and a fresh fix ``q_NS`` of norm ``q_NS_norm``, or None; no wheel and no bus error."""
        fresh = q_NS is not None
        return cls(0, 0.0, dt_s, False, gyro_B, gyro_B.shape[0] > 0, fresh, 0, fresh, q_NS, q_NS_norm, st_latency_s,
                   np.zeros(0), np.zeros(0, dtype=np.int64), 0, 0)


class AttitudeEstimate(NamedTuple):
    """The estimator's output for one cycle: attitude ``q_NB`` (scalar first; identity until the first fix)
    and body rate ``omega_BN_B`` [rad/s], whether the attitude is known, and the star tracker's innovation
    [deg] (NaN: no fix this cycle) for FDIR."""

    q_NB: np.ndarray
    omega_BN_B: np.ndarray
    initialized: bool
    innovation_deg: float


@dataclass
class GuidanceOutput:
    """One cycle's guidance: the body-rate command ``omega_cmd_BN_B`` [rad/s] and what the mode knows of the
    geometry (errors and margins [deg], zone bodies, directions in N), NaN or empty where it does not apply."""

    omega_cmd_BN_B: np.ndarray
    mode: str
    safe_phase: str = "NONE"
    active_zone: int = -1
    eps: float = float("nan")
    eps_max: float = float("nan")
    margins_deg: list[float] = field(default_factory=list)
    margin_min_deg: float = float("nan")
    pointing_error_deg: float = float("nan")
    att_error_deg: float = float("nan")
    roll_error_deg: float = float("nan")
    boresight_N: np.ndarray = field(default_factory=lambda: NAN3)
    target_N: np.ndarray = field(default_factory=lambda: NAN3)
    q_target_NB: np.ndarray = field(default_factory=lambda: NAN4)
    zones_merged: bool = False
    assumptions_ok: bool = True
    sun_N: np.ndarray = field(default_factory=lambda: NAN3)
    moon_N: np.ndarray = field(default_factory=lambda: NAN3)
    zone_count: int = 0
    zone_bodies: list[str] = field(default_factory=list)


@dataclass
class ControlOutput:
    """One cycle of the rate loop: body torque [N m] in B, each wheel's motor torque [N m], the factor that
    scaled them into the wheels' limits, and the shaped rate command [rad/s]."""

    torque_cmd_B_Nm: np.ndarray
    wheel_torque_cmd_Nm: np.ndarray
    torque_scale: float
    omega_cmd_shaped_BN_B: np.ndarray


@dataclass
class CycleRecord:
    """Last cycle's outputs (for tests, bench and SIL summaries)."""

    t: float
    mode: str
    q_est_NB: np.ndarray
    omega_cmd_BN_B: np.ndarray
    wheel_torque_cmd_Nm: np.ndarray
    margins_deg: list
    margin_min_deg: float
    pointing_error_deg: float
    att_error_deg: float
    exec_time_ms: float


__all__ = ["NAN3", "NAN4", "AttitudeEstimate", "ControlOutput", "CycleRecord", "GuidanceOutput", "SensorSnapshot",
           "new_record"]
