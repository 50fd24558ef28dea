"""Estimator consistency judged on truth: the normalised estimation error squared (NEES) of the MEKF.

At each GNC cycle the attitude error is the small rotation from the estimate to the truth in body axes,
``q_true = q_est (x) [1, e/2]`` (the filter's own error-state convention, fsw.estimation), and

    NEES = e^T P_att^-1 e

with ``P_att`` the attitude block (3 x 3) of the filter's covariance. For a consistent filter (errors
zero-mean Gaussian with the covariance the filter claims) NEES is chi-square with 3 degrees of freedom,
and the fraction of cycles inside its two-sided 95 % band [chi2(0.025, 3), chi2(0.975, 3)] =
[0.216, 9.35] is 95 % (Bar-Shalom, Li and Kirubarajan, Estimation with Applications to Tracking and
Navigation, sec. 5.4). An over-confident filter (covariance too small) sits above the band, an
over-cautious one below it. Cycles before the first star-tracker fix have no estimate and are left out.
"""
from __future__ import annotations

import numpy as np
from scipy.stats import chi2

ATTITUDE_DOF = 3


def nees_band(probability: float = 0.95, dof: int = ATTITUDE_DOF, runs: int = 1) -> tuple[float, float]:
    """Two-sided ``probability`` band of the NEES averaged over ``runs`` independent runs (N * mean is
    chi-square with N * dof degrees of freedom)."""
    tail = 0.5 * (1.0 - probability)
    return float(chi2.ppf(tail, runs * dof) / runs), float(chi2.ppf(1.0 - tail, runs * dof) / runs)


def attitude_nees(q_true_NB: np.ndarray, q_est_NB: np.ndarray, P_att: np.ndarray) -> np.ndarray:
    """NEES per sample: truth and estimate quaternions (n, 4), scalar first; attitude covariances (n, 3, 3)
    [rad^2]. The error is the exact rotation vector of q_est^* (x) q_true (sign fixed: q and -q are one
    attitude)."""
    qe, qt = np.asarray(q_est_NB, dtype=float), np.asarray(q_true_NB, dtype=float)
    w = qe[:, 0] * qt[:, 0] + np.einsum("ij,ij->i", qe[:, 1:], qt[:, 1:])
    v = qe[:, :1] * qt[:, 1:] - qt[:, :1] * qe[:, 1:] - np.cross(qe[:, 1:], qt[:, 1:])
    sign = np.where(w < 0.0, -1.0, 1.0)
    w, v = w * sign, v * sign[:, None]
    vn = np.linalg.norm(v, axis=1)
    scale = np.where(vn > 1e-12, 2.0 * np.arctan2(vn, w) / np.maximum(vn, 1e-300), 2.0)
    e = v * scale[:, None]
    return np.einsum("ij,ij->i", e, np.linalg.solve(np.asarray(P_att, dtype=float), e[:, :, None])[:, :, 0])


def band_fraction(nees: np.ndarray, probability: float = 0.95, dof: int = ATTITUDE_DOF) -> float:
    """Fraction of the samples inside the two-sided ``probability`` band of one run (nan when none)."""
    nees = np.asarray(nees, dtype=float)
    if not nees.size:
        return float("nan")
    lo, hi = nees_band(probability, dof)
    return float(np.mean((nees > lo) & (nees < hi)))


# Samples of one run are correlated: the star tracker's roll error over ~20 s, the gyro bias over hundreds of
# seconds. The chi-square and binomial intervals below are for independent samples, so they are applied to
# samples INDEPENDENT_SPACING_S apart. That removes the fast correlation, not the slow one: a pass says the
# filter's errors are consistent at that spacing, a necessary condition of consistency, not a proof of it.
INDEPENDENT_SPACING_S = 20.0


def thinned(nees: np.ndarray, period_s: float, spacing_s: float = INDEPENDENT_SPACING_S) -> np.ndarray:
    """Every sample ``spacing_s`` apart (``period_s``: the sampling period) of one run's NEES series."""
    step = max(1, int(round(spacing_s / period_s)))
    return np.asarray(nees, dtype=float)[::step]


def time_average_interval(n_samples: int, probability: float = 0.95, dof: int = ATTITUDE_DOF) -> tuple[float, float]:
    """Two-sided ``probability`` interval of the average of ``n_samples`` independent NEES samples
    (n times the average is chi-square with n dof degrees of freedom): the time-averaged NEES of one run,
    or the ensemble average over runs and samples."""
    return nees_band(probability, dof, runs=n_samples)


def band_fraction_interval(n_samples: int, probability: float = 0.95,
                           confidence: float = 0.95) -> tuple[float, float]:
    """Where the fraction of ``n_samples`` independent samples inside the ``probability`` band lies with
    ``confidence`` for a consistent filter: the binomial(n, probability) interval, as fractions. A fraction
    of 95 % is the expected value, not a bound: with 30 samples anything from 27/30 up passes."""
    from scipy.stats import binom

    lo, hi = binom.interval(confidence, n_samples, probability)
    return float(lo) / n_samples, float(hi) / n_samples
