"""Plots a person reads: a unit on every axis, one RA convention (0-360 deg, increasing to the left) in the
SIL's and the campaign's sky maps, and a sky view that stays readable at a celestial pole."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from hil_sim.sil import skyplot

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "sil"))


@pytest.fixture
def figures(monkeypatch):
    """Every figure saved while the test runs (captured at savefig, before it is closed)."""
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure
    saved: list = []
    original = Figure.savefig

    def capture(self, *args, **kw):
        saved.append((str(args[0]) if args else "?", self))
        return original(self, *args, **kw)

    monkeypatch.setattr(Figure, "savefig", capture)
    return saved


def _assert_units_on_every_axis(saved):
    assert saved
    for name, fig in saved:
        for ax in fig.axes:
            if not ax.get_visible():
                continue
            if hasattr(ax, "_colorbar"):  # a colour bar: its one label carries the unit
                label = ax.get_ylabel() or ax.get_xlabel()
                assert "[" in label, (name, label)
                continue
            # stacked panels sharing their x axis: the bottom one carries its label
            x_labels = [a.get_xlabel() for a in ax.get_shared_x_axes().get_siblings(ax)]
            for label in (max(x_labels, key=len), ax.get_ylabel()):
                assert "[" in label and label.rstrip().endswith("]"), (name, ax.get_title(), label)


def _ra_tick_labels(ax) -> list[float]:
    fmt = ax.xaxis.get_major_formatter()
    return [float(fmt(x, None).rstrip("\N{DEGREE SIGN}")) for x in np.radians([-150, -90, -30, 30, 90, 150])]


def test_ra_convention_zero_to_360_increasing_to_the_left():
    ra = np.radians([10.0, 90.0, 180.0, 270.0, 350.0])
    v = np.stack([np.cos(ra), np.sin(ra), np.zeros_like(ra)], axis=1)
    lon, lat = skyplot.mollweide_lon_lat(v)
    assert np.all(np.diff(lon) < 0)  # larger RA further left
    assert skyplot.ra_dec_deg(v)[0].tolist() == pytest.approx([10.0, 90.0, 180.0, 270.0, 350.0])


def test_a_path_over_the_pole_is_continuous_and_a_polar_zone_round_in_the_local_view():
    # boresight crossing the north celestial pole; RA jumps by 180 deg there, true angles do not
    t = np.radians(np.linspace(60.0, 120.0, 121))
    path = np.stack([np.cos(t), np.zeros_like(t), np.sin(t)], axis=1)
    center, radius = skyplot.local_view(path)
    x, y = skyplot.local_xy_deg(path, center)
    steps = np.hypot(np.diff(x), np.diff(y))
    assert steps.max() == pytest.approx(0.5, abs=1e-6) and radius == pytest.approx(35.0, abs=1e-6)
    ra, _ = skyplot.ra_dec_deg(path)
    assert np.abs(np.diff(ra)).max() > 170.0  # what an RA/Dec rectangle would draw
    # a 20 deg cap about the pole is a circle of radius 20 deg, not a band over 360 deg of RA
    phi = np.linspace(0, 2 * np.pi, 200)
    r = math.radians(20.0)
    cap = np.stack([np.sin(r) * np.cos(phi), np.sin(r) * np.sin(phi), np.full_like(phi, np.cos(r))], axis=1)
    x, y = skyplot.local_xy_deg(cap, [0.0, 0.0, 1.0])
    assert np.hypot(x, y) == pytest.approx(20.0, abs=1e-9)


def test_sil_plots_have_units_on_every_axis_and_the_sky_convention(tmp_path, figures):
    from test_summary_table import _drifting_run

    from hil_sim.sil.plots import write_plots
    run_dir, mission = _drifting_run(tmp_path, "demo-pointing", duration_s=310.0)  # its third target near Dec 0
    written = write_plots(run_dir, mission)
    assert {p.name for p in written} >= {"sky.png", "margins.png", "wheels.png"}
    _assert_units_on_every_axis(figures)
    sky = next(fig for name, fig in figures if name.endswith("sky.png"))
    full = next(ax for ax in sky.axes if ax.name == "mollweide")
    assert _ra_tick_labels(full) == [330.0, 270.0, 210.0, 150.0, 90.0, 30.0]  # RA increases to the left
    local = next(ax for ax in sky.axes if ax.name == "rectilinear" and not hasattr(ax, "_colorbar"))
    assert local.get_xlim()[0] > local.get_xlim()[1]  # east to the left there too
    assert local.get_aspect() == 1.0  # true angles
    # the targets' labels leave the RA tick labels readable (they used to sit on them)
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    renderer = FigureCanvasAgg(sky).get_renderer()  # (a closed figure's canvas may be the base one)
    labels = [t.get_window_extent(renderer) for t in full.texts if t.get_text().startswith("target")]
    ticks = [t.get_window_extent(renderer) for t in full.get_xticklabels() if t.get_text()]
    assert labels and ticks
    assert not [(a, b) for a in labels for b in ticks if a.overlaps(b)]


def test_campaign_report_plots_have_units_and_the_same_ra_convention(tmp_path, figures):
    from campaign_kit import toy_plan, write_toy

    from hil_sim.campaign.runner import finalize, prepare_out_dir, run_campaign
    path = write_toy(tmp_path, runs=8)
    plan, base = toy_plan(path)
    out = tmp_path / "out"
    prepare_out_dir(out, plan, path, base)
    finalize(plan, out, run_campaign(plan, out, workers=1).records)
    _assert_units_on_every_axis(figures)
    skies = [ax for _, fig in figures for ax in fig.axes if ax.name == "mollweide"]
    assert skies
    for ax in skies:
        assert _ra_tick_labels(ax) == [330.0, 270.0, 210.0, 150.0, 90.0, 30.0]
    md = (out / "report.md").read_text()
    assert "min_margin_deg > 0 deg" in md  # the requirement table gives units
