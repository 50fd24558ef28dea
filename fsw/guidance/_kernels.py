"""Compiled per-cycle arithmetic of the guidance (one call each instead of a dozen numpy calls on 3-vectors).

A GNC cycle's guidance is mostly small-vector arithmetic: at ~1 us per numpy call on a 3-vector the calls
cost more than the sums. These kernels do that arithmetic in one compiled call each, with the expressions
of the numpy code they replace (elementwise operations are bit-identical; sums of three products may differ
from numpy's dot in the last bit, since numpy's dot may use fused multiply-adds).

* `boresight_nb`: ``y_N = R_NB(q) b_B``;
* `pointing_command_nb`: POINTING's body-rate command from the law's ``u``: ``b^x R^T k1 u``, the rate
  limit and the governor's rate, the pointing error, and the roll law about the boresight;
* `aim_index_nb`: `PathFollower.aim_index` (pure pursuit along the planned path);
* `pointing_step_nb`: a whole POINTING cycle in steady state (the sky directions, the zones' drifts,
  the boresight, the aim, then `pointing_law_nb`: the star law on the packed law zones, the margins on the
  packed physical zones, the governor and `pointing_command_nb`); it stops after the sky and the boresight
  when a zone must be rebuilt, the law is stale or the aim moves on, and the guidance finishes in Python.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gnc._sky_ephemeris_nb import sky_directions_nb
from gnc._zone_polygon import polygon_box, signed_separation_one_boxed
from gnc.attitude import pointing_rate_command_nb, quat_to_dcm_nb
from gnc.zones import _cone_signed


@njit(cache=True)
def _dot3(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def boresight_nb(q, b):
    """``R_NB(q) b``: the instrument boresight in N."""
    R = quat_to_dcm_nb(q)
    y = np.empty(3)
    for i in range(3):
        y[i] = R[i, 0] * b[0] + R[i, 1] * b[1] + R[i, 2] * b[2]
    return y


@njit(cache=True)
def _scale_into(w, limit):
    """``w`` scaled down to norm ``limit`` when longer (`common._saturate`), in place."""
    n = math.sqrt(_dot3(w, w))
    if n > limit:
        s = limit / n
        for i in range(3):
            w[i] = w[i] * s


@njit(cache=True)
def roll_error_nb(q, y, b, roll_axis_B, roll_ref_N):
    """Angle [rad] about the boresight ``b`` from ``roll_axis_B``'s projection to the roll reference's
    (``roll_ref_N``, or a coordinate axis when the reference is within ~18 deg of the boresight ``y``)."""
    ref = roll_ref_N.copy()
    if abs(_dot3(ref, y)) > 0.95:  # reference nearly along the boresight: use another axis
        ref[:] = 0.0
        if abs(y[0]) < 0.9:
            ref[0] = 1.0
        else:
            ref[1] = 1.0
    R = quat_to_dcm_nb(q)
    r_B = np.empty(3)
    for i in range(3):
        r_B[i] = R[0, i] * ref[0] + R[1, i] * ref[1] + R[2, i] * ref[2]
    ab = _dot3(roll_axis_B, b)
    rb = _dot3(r_B, b)
    a = roll_axis_B - ab * b
    r = r_B - rb * b
    ax0 = a[1] * r[2] - a[2] * r[1]
    ax1 = a[2] * r[0] - a[0] * r[2]
    ax2 = a[0] * r[1] - a[1] * r[0]
    return math.atan2(b[0] * ax0 + b[1] * ax1 + b[2] * ax2, _dot3(a, r))


@njit(cache=True)
def pointing_command_nb(q, y, b, u_law, k1, max_rate, governor_rate, target, roll_axis_B, roll_ref_N, roll_gain):
    """POINTING's command from the law's ``u_law`` (S^2, N frame) for attitude ``q`` and boresight ``y``.

    ``omega = b^x R^T (k1 u_law)`` scaled into ``max_rate`` and then into ``governor_rate`` (negative: no
    governor this cycle); the roll rate about the boresight gets what the rate limit leaves (at most half
    of it). Returns [omega_cmd_BN_B (3), |law rate after the limits|, pointing error deg, roll error rad].
    """
    w = pointing_rate_command_nb(q, b, k1 * u_law)
    _scale_into(w, max_rate)
    if governor_rate >= 0.0:
        _scale_into(w, governor_rate)
    out = np.empty(6)
    ww = _dot3(w, w)
    out[3] = math.sqrt(ww)
    out[4] = math.degrees(math.acos(max(-1.0, min(1.0, _dot3(y, target)))))
    roll = roll_error_nb(q, y, b, roll_axis_B, roll_ref_N)
    out[5] = roll
    omega_roll = roll_gain * roll * b
    room = math.sqrt(max(0.0, max_rate ** 2 - ww))
    _scale_into(omega_roll, min(room, 0.5 * max_rate))
    for i in range(3):
        out[i] = w[i] + omega_roll[i]
    return out


@njit(cache=True)
def _row_dot(path, k, y):
    c = 0.0
    for i in range(y.shape[0]):
        c += path[k, i] * y[i]
    return c


@njit(cache=True)
def aim_index_nb(path, start, y, cos_ahead):
    """(nearest index from ``start`` on, aim index): the first path point at or after ``start`` with the
    largest cosine to ``y``, then the first point from there whose cosine is below ``cos_ahead`` (the
    path's last index when none is). Any dimension: S^2 (boresight paths) and S^3 (attitude paths)."""
    best_k, best_c = start, -math.inf
    for k in range(start, path.shape[0]):
        c = _row_dot(path, k, y)
        if c > best_c:
            best_k, best_c = k, c
    for k in range(best_k, path.shape[0]):
        if _row_dot(path, k, y) < cos_ahead:
            return best_k, k
    return best_k, path.shape[0] - 1


# ------------------------------------------------------------------------------------------------
# POINTING in one call (design note 15): the zones as arrays, the sky update's drifts, the law, the
# margins, the governor and the command.
#
# A zone set (the slots' physical zones, or the law's merged zones) is packed by `pack_zones` into a
# table with a row per zone, and an arc array with the polygons' arcs (9 columns), arc midpoints (3) and
# plane vertices (2) stacked: ZT_KIND 0 cone, 1 polygon; ZT_START/ZT_COUNT its rows in the arc array;
# ZT_REACH; ZT_C the plane's centre point c; ZT_B the plane basis B (3 x 2, row-major); ZT_NORMAL /
# ZT_OFFSET the plane; ZT_AXIS / ZT_HALF a cone's axis and half-angle; for the law's zones, ZT_CAP_AXIS /
# ZT_CAP_COS the bounding-cap screen and ZT_KERNEL (k1 / kappa) g of `gnc.laws.StarShapedLaw`. The kernels
# call the zones' own compiled separations (`gnc.zones._cone_signed`,
# `gnc._zone_polygon.signed_separation_one_boxed`, its box precheck in ZT_BOX) on these rows: the same numbers.
ZT_KIND, ZT_START, ZT_COUNT, ZT_REACH, ZT_C, ZT_B = 0, 1, 2, 3, 4, 7
ZT_NORMAL, ZT_OFFSET, ZT_AXIS, ZT_HALF = 13, 16, 17, 20
ZT_CAP_AXIS, ZT_CAP_COS, ZT_KERNEL = 21, 24, 25
ZT_BOX = 28  # a polygon's plane-vertex box (`gnc._zone_polygon.polygon_box`, 4)
ZT_WIDTH = 32
ARC_WIDTH = 14


@njit(cache=True)
def zone_signed_nb(x, tab, arcs, z, clamp):
    """Signed separation of ``x`` from packed zone ``z`` (``clamp``: 0 inside, as ``separation``)."""
    if tab[z, ZT_KIND] == 0.0:
        return _cone_signed(x, tab[z, ZT_AXIS:ZT_AXIS + 3], tab[z, ZT_HALF], clamp)
    s = int(tab[z, ZT_START])
    e = s + int(tab[z, ZT_COUNT])
    B = np.empty((3, 2))
    for i in range(3):
        B[i, 0] = tab[z, ZT_B + 2 * i]
        B[i, 1] = tab[z, ZT_B + 2 * i + 1]
    return signed_separation_one_boxed(x, arcs[s:e, 0:9], arcs[s:e, 9:12], tab[z, ZT_REACH], arcs[s:e, 12:14],
                                       tab[z, ZT_BOX:ZT_BOX + 4], tab[z, ZT_C:ZT_C + 3], B,
                                       tab[z, ZT_NORMAL:ZT_NORMAL + 3], tab[z, ZT_OFFSET], clamp)


@njit(cache=True)
def zone_separations_nb(x, tab, arcs):
    """``separation(x)`` (0 inside) of every packed zone."""
    out = np.empty(tab.shape[0])
    for z in range(tab.shape[0]):
        out[z] = zone_signed_nb(x, tab, arcs, z, True)
    return out


def pack_zones(zones: list) -> tuple[np.ndarray, np.ndarray] | None:
    """(table, arcs) of cones and polygon star zones on S^2; None when a zone is of another kind (those
    keep the Python law)."""
    tab = np.zeros((len(zones), ZT_WIDTH))
    arcs = [np.zeros((0, ARC_WIDTH))]
    start = 0
    for i, z in enumerate(zones):
        if getattr(z, "dim", 0) != 3:
            return None
        if isinstance(getattr(z, "half_angle", None), float) and hasattr(z, "_axis"):
            tab[i, ZT_KIND] = 0.0
            tab[i, ZT_AXIS:ZT_AXIS + 3] = z._axis
            tab[i, ZT_HALF] = z.half_angle
            continue
        if getattr(z, "shape", None) != "polygon":
            return None
        e, m, reach, v, c, B, normal, offset = z._poly_args
        n = e.shape[0]
        tab[i, ZT_KIND] = 1.0
        tab[i, ZT_START], tab[i, ZT_COUNT], tab[i, ZT_REACH] = start, n, reach
        tab[i, ZT_C:ZT_C + 3] = c
        tab[i, ZT_B:ZT_B + 6] = np.asarray(B).reshape(6)
        tab[i, ZT_NORMAL:ZT_NORMAL + 3] = normal
        tab[i, ZT_OFFSET] = offset
        tab[i, ZT_BOX:ZT_BOX + 4] = polygon_box(v)
        arcs.append(np.hstack([e, m, v]))
        start += n
    return tab, np.ascontiguousarray(np.concatenate(arcs))


# inputs of `pointing_step_nb` (one float vector, so that the compiled call unboxes few arguments): per
# cycle first, then what changes seldom: the commanded target and the roll law's axes (rewritten when the
# guidance replaces them), the ephemeris rows (every EPHEMERIS_NODE_S)
(FP_T, FP_F, FP_STEADY, FP_START, FP_AIM_K, FP_NPREV, FP_U0, FP_N, FP_RADIUS, FP_K1, FP_MAX_RATE, FP_ROLL_GAIN,
 FP_ACCEL, FP_BANDWIDTH, FP_EPS, FP_COS_AHEAD, FP_FOLLOW) = range(17)
FP_LAW_TARGET, FP_B, FP_TARGET, FP_ROLL_AXIS, FP_ROLL_REF = 17, 20, 23, 26, 29
FP_EPH = 32  # 6 rows of 3: p_hat, q_hat, Sun and Moon at the two ephemeris nodes (`sky_directions_nb`)
FP_PREV = 50  # then last cycle's margins (FP_NPREV of them), for the governor; the law kernel writes its own
# then one flag per slot, 1 where the slot's zone is disarmed (`PointingGuidance._update_arming`): its margin NaN
FP_WIDTH = 50  # plus two per slot

# result layout of `pointing_step_nb`
(R_DIRS, R_Y, R_COMPLETE, R_WORST, R_WORST_KIND, R_NEAREST, R_AIM, R_OMEGA, R_LAW_RATE, R_ERROR, R_ROLL,
 R_ZONE, R_GOVERNOR, R_MARGIN_MIN, R_LAW_ERROR) = 0, 9, 12, 13, 14, 15, 16, 17, 20, 21, 22, 23, 24, 25, 26
R_AIM_DONE = 27  # 1 when R_NEAREST and R_AIM are this cycle's
R_DRIFT = 28  # then the slots' drifts, then their margins

# slot rows of `pointing_step_nb`'s ``slot_geo`` (n, 4, 3)
SG_FIXED, SG_BUILT, SG_BUILT_LAW, SG_BODY = 0, 1, 2, 3

LAW_REBUILD_TRIGGER_DEG = 0.08
PHYS_REBUILD_TOL_DEG = 0.5
BRAKING_RESERVE_DEG = 0.5  # slew_limits.BRAKING_RESERVE_DEG (tested equal)
LAG_TIME_CONSTANTS = 1.5  # slew_limits.LAG_TIME_CONSTANTS (tested equal)


@njit(cache=True)
def angle_deg_nb(a, b):
    """`common._angle_deg`: the angle [deg] between unit vectors."""
    return math.degrees(math.acos(max(-1.0, min(1.0, a[0] * b[0] + a[1] * b[1] + a[2] * b[2]))))


@njit(cache=True)
def d_s_to_deg_nb(d_s):
    """`common.d_s_to_deg`."""
    mag = math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - abs(d_s)))))
    return mag if d_s >= 0 else -mag


@njit(cache=True)
def rate_for_distance_nb(distance_deg, accel_deg_s2, bandwidth_rad_s):
    """`slew_limits.rate_for_distance_deg_s`."""
    if not distance_deg > 0.0 or not accel_deg_s2 > 0.0:
        return 0.0
    lag = LAG_TIME_CONSTANTS / bandwidth_rad_s
    return accel_deg_s2 * (math.sqrt(lag * lag + 2.0 * distance_deg / accel_deg_s2) - lag)


@njit(cache=True)
def star_law_nb(y, eps, law_target, tab, arcs, u):
    """`gnc.laws.StarShapedLaw.control_and_zone` (k1 = 1, the guidance's law) on packed zones: fills ``u``,
    returns the active zone (-1 outside every eps-layer), -2 when ``y`` is not a unit vector."""
    n2 = 0.0
    for k in range(3):
        n2 += y[k] * y[k]
    if not abs(n2 - 1.0) <= 2.0 * 1e-6:
        return -2
    best_i, best_d = -1, np.inf
    for i in range(tab.shape[0]):
        c = 0.0
        for k in range(3):
            c += y[k] * tab[i, ZT_CAP_AXIS + k]
        if c >= tab[i, ZT_CAP_COS]:
            d = zone_signed_nb(y, tab, arcs, i, True)
            if d < best_d:
                best_i, best_d = i, d
    if best_d > eps:
        for k in range(3):
            u[k] = 1.0 * law_target[k]
        return -1
    a = best_d / eps
    b = 1.0 - a
    for k in range(3):
        u[k] = a * (1.0 * law_target[k]) - b * tab[best_i, ZT_KERNEL + k]
    return best_i


@njit(cache=True)
def pointing_law_nb(q, y, fp, law_tab, law_arcs, phys_tab, phys_arcs, drift, res):
    """The law's ``u`` and zone, the slots' margins (less their ``drift``), the governor's rate and the
    command (`pointing_command_nb`, target and roll axes from ``fp``) into ``res`` (layout R_*; the margins
    at ``res[R_DRIFT + n:]``, and at ``fp[FP_PREV:]`` for the next cycle's governor)."""
    n = phys_tab.shape[0]
    u = np.empty(3)
    zone = star_law_nb(y, fp[FP_EPS], fp[FP_LAW_TARGET:FP_LAW_TARGET + 3], law_tab, law_arcs, u)
    res[R_LAW_ERROR] = 1.0 if zone == -2 else 0.0
    if zone == -2:
        return
    res[R_ZONE] = zone
    m0 = R_DRIFT + n
    mmin = np.nan
    for i in range(n):
        if fp[FP_PREV + n + i] != 0.0:  # disarmed: no keep-out, so no margin (nor a zone the governor nears)
            m = np.nan
        else:
            m = d_s_to_deg_nb(zone_signed_nb(y, phys_tab, phys_arcs, i, False)) - drift[i]
        res[m0 + i] = m
        if m == m and not mmin <= m:  # the smallest of the armed zones' margins
            mmin = m
    res[R_MARGIN_MIN] = mmin
    # the governor (`Guidance._governor_rate`): the nearest zone being approached
    governor = -1.0
    if fp[FP_NPREV] == n:
        found = False
        closest = 0.0
        for i in range(n):
            m = res[m0 + i]
            if m < fp[FP_PREV + i] and (not found or m < closest):
                closest, found = m, True
        if found:
            room = 1.0 * closest - BRAKING_RESERVE_DEG
            governor = math.radians(rate_for_distance_nb(room, fp[FP_ACCEL], fp[FP_BANDWIDTH]))
    res[R_GOVERNOR] = governor
    for i in range(n):
        fp[FP_PREV + i] = res[m0 + i]
    c = pointing_command_nb(q, y, fp[FP_B:FP_B + 3], u, fp[FP_K1], fp[FP_MAX_RATE], governor,
                            fp[FP_TARGET:FP_TARGET + 3], fp[FP_ROLL_AXIS:FP_ROLL_AXIS + 3],
                            fp[FP_ROLL_REF:FP_ROLL_REF + 3], fp[FP_ROLL_GAIN])
    for k in range(3):
        res[R_OMEGA + k] = c[k]
    res[R_LAW_RATE] = c[3]
    res[R_ERROR] = c[4]
    res[R_ROLL] = c[5]


@njit(cache=True)
def pointing_step_nb(q, fp, slot_geo, path, law_tab, law_arcs, phys_tab, phys_arcs, res):
    """One POINTING cycle in steady state (`PointingGuidance._pointing`): the sky directions, every slot's
    drift and the rebuild it calls for, the boresight, the path follower's aim; then, when no zone needs a
    rebuild, the law is current (``fp[FP_STEADY]``) and the aim stays, `pointing_law_nb`
    (``res[R_COMPLETE]`` = 1). Otherwise the guidance finishes the cycle in Python (``res[R_COMPLETE]`` = 0).
    Fills ``res`` (R_DRIFT + 2 n, the caller's: no array to box on the way back) and returns
    ``res[R_COMPLETE]``.

    ``slot_geo`` (n, 4, 3): per slot the fixed centre, the centres its physical and law zones were built
    at, and its body (row 3, column 0: 0 Sun, 1 Moon, 2 Earth, 3 fixed)."""
    n = slot_geo.shape[0]
    e = FP_EPH
    d = sky_directions_nb(fp[FP_T], fp[FP_U0], fp[FP_N], fp[FP_RADIUS], fp[e:e + 3], fp[e + 3:e + 6], fp[FP_F],
                          fp[e + 6:e + 9], fp[e + 9:e + 12], fp[e + 12:e + 15], fp[e + 15:e + 18])
    for i in range(3):
        for k in range(3):
            res[R_DIRS + 3 * i + k] = d[i, k]
    # `_update_sky`: every slot's drift; the largest drift past its trigger is rebuilt (in Python)
    worst, worst_kind, worst_slot = 0.0, -1, -1
    for s in range(n):
        body = int(slot_geo[s, SG_BODY, 0])
        c = slot_geo[s, SG_FIXED] if body == 3 else d[body]
        phys = angle_deg_nb(c, slot_geo[s, SG_BUILT])
        res[R_DRIFT + s] = phys
        law_drift = angle_deg_nb(c, slot_geo[s, SG_BUILT_LAW]) / LAW_REBUILD_TRIGGER_DEG
        phys_drift = phys / PHYS_REBUILD_TOL_DEG
        if law_drift >= 1.0 and law_drift > worst:
            worst, worst_kind, worst_slot = law_drift, 0, s
        if phys_drift >= 1.0 and phys_drift > worst:
            worst, worst_kind, worst_slot = phys_drift, 1, s
    res[R_WORST] = worst_slot
    res[R_WORST_KIND] = worst_kind
    y = boresight_nb(q, fp[FP_B:FP_B + 3])
    for k in range(3):
        res[R_Y + k] = y[k]
    res[R_COMPLETE] = 0.0
    res[R_NEAREST] = fp[FP_START]
    res[R_AIM] = fp[FP_AIM_K]
    res[R_AIM_DONE] = 0.0
    if worst_slot >= 0 or fp[FP_STEADY] == 0.0:
        return 0.0
    if fp[FP_FOLLOW] != 0.0:
        nearest, aim = aim_index_nb(path, int(fp[FP_START]), y, fp[FP_COS_AHEAD])
        res[R_NEAREST] = nearest
        res[R_AIM] = aim
        res[R_AIM_DONE] = 1.0
        if aim != int(fp[FP_AIM_K]):
            return 0.0
    pointing_law_nb(q, y, fp, law_tab, law_arcs, phys_tab, phys_arcs, res[R_DRIFT:R_DRIFT + n], res)
    res[R_COMPLETE] = 1.0
    return 1.0
