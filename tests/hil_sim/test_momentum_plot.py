"""The momentum-management plot of a run with magnetorquer rods: the wheels' momentum from the truth and the
rods' dipole the flight software commanded, from the run's own housekeeping."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_sky_plots import _assert_units_on_every_axis, figures  # noqa: F401  (the fixture)

ROOT = Path(__file__).resolve().parents[2]


def test_wheel_momentum_is_the_sum_of_each_wheels_spin_momentum_along_its_axis():
    from types import SimpleNamespace

    from hil_sim.sil.plots import wheel_momentum_B

    wheels = [SimpleNamespace(axis_B=[2.0, 0.0, 0.0], spin_inertia_kgm2=0.01),
              SimpleNamespace(axis_B=[0.0, 0.6, 0.8], spin_inertia_kgm2=0.02)]
    h = wheel_momentum_B(wheels, np.array([[100.0, 0.0], [10.0, -50.0]]))
    assert h == pytest.approx(np.array([[1.0, 0.0, 0.0], [0.1, -0.6, -0.8]]))


@pytest.mark.slow
def test_a_run_with_rods_plots_its_wheel_momentum_and_the_commanded_dipoles(tmp_path, figures,  # noqa: F811
                                                                             monkeypatch):
    from hil_sim.mission.model import load_mission
    from hil_sim.sil.plots import write_plots

    flown = subprocess.run([sys.executable, "-m", "cli", "sil", "run", "config/missions/detumble.yaml", "--duration",
                            "60", "--no-progress", "--out", str(tmp_path / "runs")], cwd=ROOT, capture_output=True,
                           text=True, timeout=600)
    run_dir = next((tmp_path / "runs").glob("detumble-*"))
    assert (run_dir / "momentum.png").exists(), flown.stdout[-2000:] + flown.stderr[-2000:]
    figures.clear()
    import ground.archive as archive

    passes = []
    real = archive.decode_archive
    monkeypatch.setattr(archive, "decode_archive", lambda *a, **k: passes.append(1) or real(*a, **k))
    written = write_plots(run_dir, load_mission(ROOT / "config" / "missions" / "detumble.yaml"))
    assert len(passes) == 1  # GNC (estimation) and HK (rods) from one pass over the archive
    both = archive.read_packets(run_dir / "ground", ("GNC", "HK"))
    for packet in ("GNC", "HK"):
        alone = archive.read_channels(run_dir / "ground", packet)
        assert alone.keys() == both[packet].keys() and len(alone["time_s"]) > 10
        assert all(np.array_equal(alone[k], both[packet][k], equal_nan=alone[k].dtype.kind == "f") for k in alone)
    assert run_dir / "momentum.png" in written
    fig = next(fig for name, fig in figures if name.endswith("momentum.png"))
    wheels, rods = fig.axes[:2]
    dipoles = [line for line in rods.lines if line.get_label().startswith("rod")]
    assert len(dipoles) == 3
    # detumbling: B-dot drives the rods while the wheels are held (their momentum stays where it started)
    assert max(np.abs(line.get_ydata()).max() for line in dipoles) > 0.01
    total = next(line for line in wheels.lines if line.get_label() == "|h| (truth)")
    assert np.asarray(total.get_ydata()).max() < 1e-3
    _assert_units_on_every_axis([(n, f) for n, f in figures if n.endswith("momentum.png")])
