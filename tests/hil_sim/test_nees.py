"""MEKF consistency: the normalised estimation error squared (NEES) of the attitude, judged on truth against
the filter's own covariance (hil_sim.sil.consistency), over the 600 s pointing demo and over a campaign
(config/campaigns/nees.yaml: seeds, initial conditions, gyro bias, epoch and target dispersed, the sensor
models known exactly), in the campaign's fast mode (the real flight software and truth models).

The standard tests (Bar-Shalom, Li and Kirubarajan, Estimation with Applications to Tracking and Navigation,
sec. 5.4): the time-averaged NEES of each run, and the NEES averaged over the campaign's runs and samples,
lie inside their two-sided 95 % chi-square intervals; the fraction of samples inside the 95 % band lies
inside the binomial 95 % interval for that many samples. "95 % of the samples in the band" is what a
consistent filter reaches on average, not a bound it can keep, so it is not a test here. The intervals
are for independent samples; one run's are correlated (the star tracker's roll error over ~20 s, the gyro
bias over hundreds of seconds), so the tests use samples INDEPENDENT_SPACING_S (20 s) apart. That removes
the fast correlation only: passing is necessary for consistency, not a proof of it. An over-confident
filter (the one before the latency-aware update: mean NEES 7.2) fails every one of these.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np
import pytest
from numba import njit
from scipy.spatial.transform import Rotation
from scipy.stats import binom, chi2

from hil_sim.sil.consistency import (attitude_nees, band_fraction, band_fraction_interval, nees_band, thinned,
                                 time_average_interval)

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "config" / "missions" / "demo-pointing.yaml"
CAMPAIGN = ROOT / "config" / "campaigns" / "nees.yaml"


@contextlib.contextmanager
def _nees_series():
    """The per-cycle NEES of every fast-mode run flown inside the block, read where fast mode computes its
    metrics (one array per run, in order)."""
    from hil_sim.campaign.fast import _EstimateRows

    series: list[np.ndarray] = []
    original = _EstimateRows.metrics

    def keep(self, truth):
        keep = self.rows[:self.n] < len(truth["q_NB"])
        rows = self.rows[:self.n][keep]
        series.append(attitude_nees(truth["q_NB"][rows], self.q[:self.n][keep], self.P[:self.n][keep]))
        return original(self, truth)

    mp = pytest.MonkeyPatch()
    mp.setattr(_EstimateRows, "metrics", keep)
    try:
        yield series
    finally:
        mp.undo()


def test_nees_of_errors_drawn_from_the_covariance_is_chi_square_3():
    """Independent check of the NEES arithmetic: errors drawn from P (scipy Rotation builds the truth
    from the estimate) give chi-square(3) statistics, whatever the attitude and the covariance's shape."""
    rng = np.random.default_rng(7)
    n = 20000
    L = rng.normal(size=(n, 3, 3)) * 1e-4
    P = L @ np.transpose(L, (0, 2, 1)) + np.eye(3) * 1e-10
    e = np.einsum("nij,nj->ni", np.linalg.cholesky(P), rng.normal(size=(n, 3)))
    est = Rotation.random(n, random_state=3)
    true = est * Rotation.from_rotvec(e)  # q_true = q_est (x) exp(e): the body-frame error
    q = lambda r: np.roll(r.as_quat(), 1, axis=1)  # noqa: E731 - scalar first
    nees = attitude_nees(q(true), q(est), P)
    assert abs(nees.mean() - 3.0) < 0.1
    assert abs(band_fraction(nees) - 0.95) < 0.006
    lo, hi = nees_band()
    assert (lo, hi) == pytest.approx((chi2.ppf(0.025, 3), chi2.ppf(0.975, 3)))
    assert nees_band(runs=8) == pytest.approx((chi2.ppf(0.025, 24) / 8, chi2.ppf(0.975, 24) / 8))
    assert band_fraction(4.0 * nees) < 0.8  # a covariance 4 x too small is caught


def test_lagged_update_is_the_kalman_update_with_the_bias_seen_through_the_latency():
    """A star-tracker sample ``lag`` old, bridged with the bias-corrected gyro rate, also measures the
    bias error times the lag: H = [I, lag I]. The compiled update equals the dense Kalman update with
    that H, and a bias error alone (no attitude error) is corrected in the bias, not in the attitude."""
    from fsw.estimation import mekf_update_lagged

    @njit
    def mekf_update(q, bias, P, dtheta, R):
        """The plain update (H = [I 0]) as the flight code had it before the lagged one replaced it."""
        return mekf_update_lagged(q, bias, P, dtheta, R, 0.0)

    rng = np.random.default_rng(5)
    A = rng.normal(size=(6, 6))
    P = A @ A.T * 1e-8 + np.diag([1e-9] * 3 + [1e-6] * 3)  # a bias known to 1e-3 rad/s, as at start-up
    R = np.diag([2e-10, 6e-10, 6e-10])
    q, bias, dtheta, lag = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(3), rng.normal(size=3) * 3e-5, 0.1
    H = np.hstack([np.eye(3), lag * np.eye(3)])
    K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
    _, b, Pn = mekf_update_lagged(q, bias, P, dtheta, R, lag)
    np.testing.assert_allclose(b, (K @ dtheta)[3:], rtol=1e-9)
    np.testing.assert_allclose(Pn, (np.eye(6) - K @ H) @ P, rtol=1e-7, atol=1e-22)
    # lag 0 is the plain update
    for got, want in zip(mekf_update_lagged(q, bias, P, dtheta, R, 0.0), mekf_update(q, bias, P, dtheta, R)):
        np.testing.assert_array_equal(got, want)
    # a pure bias error db seen through a 0.1 s lag: the update attributes it to the bias
    P0 = np.diag([1e-12] * 3 + [1e-6] * 3)
    db = np.array([2e-4, -1e-4, 5e-5])
    q1, b1, _ = mekf_update_lagged(q, bias, P0, db * lag, np.eye(3) * 1e-14, lag)
    np.testing.assert_allclose(b1, db, rtol=1e-3)
    assert np.linalg.norm(q1[1:]) < 1e-3 * np.linalg.norm(db * lag)


@pytest.mark.slow
def test_mekf_is_consistent_over_the_demo():
    from hil_sim.campaign.fast import run_fast
    from hil_sim.mission.model import load_mission

    mission = load_mission(DEMO)
    with _nees_series() as series:
        run_fast(mission, mission.seed)
    _assert_consistent(thinned(series[0], mission.flight_software.gnc_period_s), "\ndemo 600 s")


def _assert_consistent(samples: np.ndarray, label: str) -> None:
    """Independent NEES samples: their average in its chi-square interval, their in-band fraction in its
    binomial interval."""
    lo, hi = time_average_interval(samples.size)
    f_lo, f_hi = band_fraction_interval(samples.size)
    inside = band_fraction(samples)
    print(f"{label}: {samples.size} samples 20 s apart, NEES mean {samples.mean():.2f} in [{lo:.2f}, {hi:.2f}], "
          f"inside the band {inside:.3f} in [{f_lo:.3f}, {f_hi:.3f}]")
    assert lo <= samples.mean() <= hi
    assert f_lo <= inside <= f_hi


@pytest.mark.slow
def test_mekf_is_consistent_over_a_campaign():
    from hil_sim.campaign.execute import execute_run
    from hil_sim.campaign.runner import build_plan

    plan, _ = build_plan(CAMPAIGN)
    runs = plan.campaign.runs
    with _nees_series() as series:  # each run's per-cycle NEES
        records = [execute_run(plan, i) for i in range(runs)]
    assert all(r.status == "pass" for r in records), [(r.run, r.status, r.error) for r in records]
    from hil_sim.campaign.spec import resolve_base_mission
    from hil_sim.mission.model import load_mission

    period = load_mission(resolve_base_mission(CAMPAIGN, plan.campaign)).flight_software.gnc_period_s
    thin = [thinned(s, period) for s in series]
    print()
    outside = 0
    for k, t in enumerate(thin):  # each run's time average against its chi-square interval
        lo, hi = time_average_interval(t.size)
        outside += not lo <= t.mean() <= hi
        print(f"run {k}: {t.size} samples 20 s apart, NEES mean {t.mean():.2f} in [{lo:.2f}, {hi:.2f}]")
    # each run's interval holds with 95 %, so a consistent filter leaves about 1 run in 20 outside: the count
    # of runs outside must lie within the binomial(runs, 0.05) 95 % interval (for 8 runs: at most 2)
    assert outside <= binom.interval(0.95, runs, 0.05)[1], outside
    # the ensemble: every run's samples together, averaged, in the interval for all of them
    _assert_consistent(np.concatenate(thin), f"ensemble of {runs} runs")


def test_the_intervals_are_the_chi_square_and_binomial_ones():
    """Checked by hand: the binomial interval from the probability mass function summed with math.comb, the
    chi-square interval of an average from the gamma law's own quantiles in scipy."""
    import math

    from scipy.stats import gamma

    n, p = 30, 0.95
    cdf = lambda k: sum(math.comb(n, j) * p**j * (1 - p) ** (n - j) for j in range(k + 1))  # noqa: E731
    lo_k = min(k for k in range(n + 1) if cdf(k) >= 0.025)
    hi_k = min(k for k in range(n + 1) if cdf(k) >= 0.975)
    assert band_fraction_interval(n) == pytest.approx((lo_k / n, hi_k / n))
    # the average of n chi-square(3) samples is gamma(shape 3 n / 2, scale 2 / n)
    lo, hi = time_average_interval(n)
    assert (lo, hi) == pytest.approx((gamma.ppf(0.025, 1.5 * n, scale=2.0 / n), gamma.ppf(0.975, 1.5 * n, scale=2.0 / n)))
    # an over-confident filter (covariance 2.4 x too small, mean NEES 7.2) is far outside
    assert 7.2 > hi
    assert thinned(np.arange(6000.0), 0.1).size == 30
