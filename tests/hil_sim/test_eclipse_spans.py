"""Eclipse stretches of a recorded run (hil_sim.world.eclipse.eclipse_spans) and their bands on the plots."""
import math

import numpy as np

from gnc.ephemeris import EARTH_RADIUS_KM
from hil_sim.sil.plots import shade_eclipses
from hil_sim.world.eclipse import eclipse_spans

R_KM = EARTH_RADIUS_KM + 550.0
PERIOD_S = 2 * math.pi * math.sqrt(R_KM**3 / 398_600.4418)


def _orbit(orbits: float, beta_deg: float = 0.0, step_s: float = 1.0):
    t = np.arange(0.0, orbits * PERIOD_S, step_s)
    u = 2 * math.pi * t / PERIOD_S
    r = R_KM * np.stack([np.cos(u), np.sin(u), np.zeros_like(u)], axis=1)
    b = math.radians(beta_deg)
    sun = np.tile([math.cos(b), 0.0, math.sin(b)], (len(t), 1))
    return t, r, sun


def test_one_shadow_per_orbit_as_long_as_the_earths_disc_hides_the_sun():
    t, r, sun = _orbit(3.0)
    spans = eclipse_spans(t, r, sun)
    assert len(spans) == 3
    cylindrical_s = PERIOD_S * math.asin(EARTH_RADIUS_KM / R_KM) / math.pi  # the shadow as a cylinder
    for t0, t1, least in spans:
        assert least == 0.0  # umbra
        assert 0.99 * cylindrical_s < t1 - t0 < 1.02 * cylindrical_s
        assert abs(0.5 * (t0 + t1) % PERIOD_S - PERIOD_S / 2) < 2.0  # centred behind the Earth


def test_no_shadow_in_a_dawn_dusk_orbit_or_without_an_orbit():
    t, r, sun = _orbit(1.0, beta_deg=80.0)
    assert eclipse_spans(t, r, sun) == []
    assert eclipse_spans(t, np.zeros_like(r), sun) == []


def test_each_shadow_is_one_band_on_every_axes():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t, r, sun = _orbit(2.0, step_s=5.0)
    fig, axes = plt.subplots(2, 1)
    try:
        assert shade_eclipses(axes, eclipse_spans(t, r, sun)) == 2
        assert [len(ax.patches) for ax in axes] == [2, 2]
        assert [h.get_label() for h in axes[0].get_legend_handles_labels()[0]] == ["Earth's shadow"]
    finally:
        plt.close(fig)
