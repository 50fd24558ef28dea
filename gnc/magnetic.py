"""Magnetic attitude control and coarse Sun sensing: the laws a small satellite flies on magnetorquers,
a magnetometer and cosine-law sun sensors.

* B-dot (detumbling): ``m = -k dB/dt`` in body axes. The field seen from a tumbling body turns at about the
  body rate, so the dipole opposes the rotation; torque ``m x B`` removes rotational energy (the torque is
  always perpendicular to B, so the rate about the field line is left alone for a part of an orbit, and the
  orbit's turning of B brings it back into reach).
* Cross-product momentum unloading: the wheels' momentum excess ``dh`` (stored minus bias) is dumped by
  asking the field for the torque ``-k dh``; the part of a torque a dipole can give is the part normal to
  B, reached with ``m = (B x tau) / |B|^2`` (then ``m x B = tau - (tau . b) b``). The wheels keep the
  attitude, so the external torque leaves through their momentum.
* Rods saturate each on its own axis; a command is scaled down as a whole (its direction, and so the torque's,
  is kept) until every rod is within its limit.
* Coarse Sun sensors: a cell with unit normal n gives ``I = I_max max(0, n . s)`` (cosine law). With three or
  more lit cells spanning the sky the Sun direction is the least-squares solution of ``N s = I / I_max``.

Pure functions of numpy arrays, no state: the flight software owns the filters and the duty cycle.
"""
from __future__ import annotations

import numpy as np


def saturate_dipole(m_Am2: np.ndarray, max_Am2: np.ndarray) -> np.ndarray:
    """``m`` scaled down as a whole so that every rod is within its limit (``max_Am2`` per axis, > 0)."""
    m = np.asarray(m_Am2, dtype=float)
    ratio = float(np.max(np.abs(m) / np.asarray(max_Am2, dtype=float)))
    return m / ratio if ratio > 1.0 else m


def bdot_dipole(b_dot_B_T_s: np.ndarray, gain_Am2_s_T: float, max_Am2: np.ndarray) -> np.ndarray:
    """B-dot detumbling dipole [A m^2] from the body-frame field rate [T/s]: ``-k dB/dt``, saturated."""
    return saturate_dipole(-gain_Am2_s_T * np.asarray(b_dot_B_T_s, dtype=float), max_Am2)


def dipole_for_torque(tau_B_Nm: np.ndarray, b_B_T: np.ndarray) -> np.ndarray:
    """The dipole whose torque ``m x B`` is the part of ``tau`` normal to the field: ``(B x tau) / |B|^2``."""
    b = np.asarray(b_B_T, dtype=float)
    b2 = float(b @ b)
    if b2 <= 0.0:
        return np.zeros(3)
    return np.cross(b, np.asarray(tau_B_Nm, dtype=float)) / b2


def unloading_dipole(h_excess_B_Nms: np.ndarray, b_B_T: np.ndarray, gain_1_s: float,
                     max_Am2: np.ndarray) -> np.ndarray:
    """Cross-product unloading: the saturated dipole [A m^2] that asks the field for ``-k dh``."""
    return saturate_dipole(dipole_for_torque(-gain_1_s * np.asarray(h_excess_B_Nms, dtype=float), b_B_T), max_Am2)


def magnetic_torque(m_B_Am2: np.ndarray, b_B_T: np.ndarray) -> np.ndarray:
    """Torque [N m] on a dipole ``m`` in the field ``B`` (both in body axes): ``m x B``."""
    return np.cross(np.asarray(m_B_Am2, dtype=float), np.asarray(b_B_T, dtype=float))


def css_sun_direction(normals_B: np.ndarray, currents: np.ndarray, scale: float = 1.0,
                      lit_fraction: float = 0.05) -> np.ndarray | None:
    """Sun direction in body axes from cosine-law cells, or None when the lit cells cannot fix it.

    A cell counts as lit above ``lit_fraction`` of full scale (below it, noise and the cosine law's knee
    give no direction). The lit cells' normals must span three dimensions (rank 3); otherwise the Sun is
    only known to lie on a cone or a circle and None is returned, never a guess.
    """
    n = np.asarray(normals_B, dtype=float)
    y = np.asarray(currents, dtype=float) / scale
    lit = y > lit_fraction
    if int(lit.sum()) < 3 or np.linalg.matrix_rank(n[lit], tol=1e-6) < 3:
        return None
    s, *_ = np.linalg.lstsq(n[lit], y[lit], rcond=None)
    norm = float(np.linalg.norm(s))
    return s / norm if norm > 0.0 else None


def css_sun_fix(normals_B: np.ndarray, currents: np.ndarray, scale: float = 1.0,
                lit_fraction: float = 0.05, min_brightness: float = 0.9) -> np.ndarray | None:
    """Sun direction in body axes from cosine-law cells that see the whole hemisphere (90 deg field of
    view), using the dark cells too; None in eclipse or when the cells cannot fix it.

    A Sun-pointed spacecraft lights one or two cells, never three, so `css_sun_direction` cannot fix the Sun
    just when SAFE needs it. A dark cell says ``n . s <= lit_fraction``: a dark cell whose normal is within
    ``asin(lit_fraction)`` of the lit cells' solution's horizon bounds the Sun's component along it to
    about zero. The lit cells (``N s = I / scale``) and those near-horizon dark cells (``n . s = 0``) are
    solved together by least squares when they span three dimensions; the error is then at most about
    ``asin(lit_fraction)`` (2.9 deg at 0.05) plus the cells' noise. In the penumbra the whole Sun is dimmed
    and a cell's dark reading no longer bounds its angle: a solution dimmer than ``min_brightness`` of full
    Sun gives None (it came out of the shadow 17 deg off, before this test).
    """
    n = np.asarray(normals_B, dtype=float)
    y = np.asarray(currents, dtype=float) / scale
    lit = y > lit_fraction
    if not lit.any():
        return None
    s0, *_ = np.linalg.lstsq(n[lit], y[lit], rcond=None)
    bound = ~lit & (n @ s0 > -lit_fraction)
    rows = lit | bound
    if np.linalg.matrix_rank(n[rows], tol=1e-6) < 3:
        return None
    s, *_ = np.linalg.lstsq(n[rows], np.where(lit, y, 0.0)[rows], rcond=None)
    norm = float(np.linalg.norm(s))
    return s / norm if norm >= min_brightness else None
