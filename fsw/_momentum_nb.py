"""Compiled backend of `fsw.momentum`: one cycle of the cross-product unloading law, from the wheel speeds and
the magnetometer's field to the rods' dipoles. On 3-vectors numpy's per-call overhead (cross, norm, pinv
products, the saturation's max) cost more than the arithmetic; the kernel writes the sums out in the order
of the numpy expressions it replaces (`gnc.magnetic.unloading_dipole` and `saturate_dipole` onto the rods;
tests/fsw/test_momentum.py holds them equal)."""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True)
def unloading_step_nb(G, Js, wheel_speed, bias, R_BS, b_S, gain, rods_pinv, max_Am2, out):
    """One unloading cycle. Returns ``(|h_excess| [N m s], finite)``; when ``finite`` (field and momentum
    both finite), ``out`` holds the rods' dipoles [A m^2], else it is left as it was.

    ``G`` (3, n) wheel axes, ``Js`` (n) spin inertias [kg m^2], ``wheel_speed`` (n) [rad/s], ``bias`` (3)
    the momentum kept [N m s], ``R_BS`` (3, 3) the magnetometer's mounting, ``b_S`` (3) its field [T],
    ``gain`` [1/s], ``rods_pinv`` (n_rods, 3) body dipole onto the rods, ``max_Am2`` (n_rods)."""
    h0 = 0.0
    h1 = 0.0
    h2 = 0.0
    for j in range(G.shape[1]):
        hj = Js[j] * wheel_speed[j]
        h0 += G[0, j] * hj
        h1 += G[1, j] * hj
        h2 += G[2, j] * hj
    h0 -= bias[0]
    h1 -= bias[1]
    h2 -= bias[2]
    norm = math.sqrt(h0 * h0 + h1 * h1 + h2 * h2)
    finite = (math.isfinite(h0) and math.isfinite(h1) and math.isfinite(h2) and math.isfinite(b_S[0])
              and math.isfinite(b_S[1]) and math.isfinite(b_S[2]))
    if not finite:
        return norm, False
    # the field in body axes, the torque asked of it, and the dipole (B x tau) / |B|^2 that gives its part
    # normal to B
    b0 = R_BS[0, 0] * b_S[0] + R_BS[0, 1] * b_S[1] + R_BS[0, 2] * b_S[2]
    b1 = R_BS[1, 0] * b_S[0] + R_BS[1, 1] * b_S[1] + R_BS[1, 2] * b_S[2]
    b2 = R_BS[2, 0] * b_S[0] + R_BS[2, 1] * b_S[1] + R_BS[2, 2] * b_S[2]
    t0 = -gain * h0
    t1 = -gain * h1
    t2 = -gain * h2
    bb = b0 * b0 + b1 * b1 + b2 * b2
    if bb <= 0.0:
        m0 = m1 = m2 = 0.0
    else:
        m0 = (b1 * t2 - b2 * t1) / bb
        m1 = (b2 * t0 - b0 * t2) / bb
        m2 = (b0 * t1 - b1 * t0) / bb
    # onto the rods, then scaled down as a whole until every rod is within its limit (NaN: left as is,
    # as np.max's NaN fails the test)
    ratio = 0.0
    for i in range(rods_pinv.shape[0]):
        d = rods_pinv[i, 0] * m0 + rods_pinv[i, 1] * m1 + rods_pinv[i, 2] * m2
        out[i] = d
        r = abs(d) / max_Am2[i]
        if r != r or ratio != ratio:
            ratio = math.nan
        elif r > ratio:
            ratio = r
    if ratio > 1.0:
        for i in range(rods_pinv.shape[0]):
            out[i] = out[i] / ratio
    return norm, True
