"""PNG plots of a SIL run (written into the run folder by the orchestrator).

* ``sky.png`` (missions with sky zones): the instrument boresight path on the celestial sphere, full sky
  (Mollweide) and around the path (true angles, readable at the poles), RA/Dec as in ``hil_sim.sil.skyplot``,
  the physical zones drawn as they moved (outlines fade with time), the targets; ``attitude.png`` (missions with S^3 zones): the lifted attitude quaternion against time
  (as the paper plots it) and the attitude error;
* ``margins.png``: signed margin to every physical zone against time with the requirement limit and the
  law's inflation margin, and the truth pointing/attitude error;
* ``wheels.png``: wheel speeds (with limits) and applied wheel torques;
* ``estimation.png``: flight-software attitude estimate against truth (error angle) with the
  estimator's own 3-sigma from its covariance trace.

Every plot against time shades the stretches the spacecraft spent in the Earth's shadow (darker in umbra).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from hil_sim.world.eclipse import eclipse_spans


def write_plots(run_dir: Path, mission, series: dict | None = None) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hil_sim.sil.judge import evaluate

    run_dir = Path(run_dir)
    if series is None:
        _, series = evaluate(run_dir, mission)
    t = series["t_s"]
    truth = series["truth"]
    written: list[Path] = []
    if len(t) < 2:
        return written
    sky_zones = [z for z in series["zones"] if z.kind == "sky"]
    att_zones = [z for z in series["zones"] if z.kind == "attitude"]

    eclipses = eclipse_spans(t, truth["r_sc_N_km"], truth["sun_N"]) if "r_sc_N_km" in truth else []
    if sky_zones or mission.flight_software.pointing.zones or any(s.mode == "POINTING" for s in series["segments"]):
        written.append(_sky_plot(plt, run_dir, mission, series, t, sky_zones))
    if att_zones or any(s.mode == "QUATERNION" for s in series["segments"]):
        written.append(_attitude_plot(plt, run_dir, mission, series, t, eclipses))
    written.append(_margins_plot(plt, run_dir, mission, series, t, eclipses))
    written.append(_wheels_plot(plt, run_dir, mission, truth, t, eclipses))
    rods = mission.spacecraft.magnetorquers is not None
    telemetry = _telemetry(run_dir, ("GNC", "HK") if rods else ("GNC",))
    est = _estimation_error(telemetry.get("GNC", {}), truth)
    if est is not None:
        written.append(_estimation_plot(plt, run_dir, mission, *est, eclipses))
    if rods:
        written.append(_momentum_plot(plt, run_dir, mission, truth, t, eclipses, telemetry.get("HK", {})))
    return written


def wheel_momentum_B(wheels, wheel_speed_rad_s: np.ndarray) -> np.ndarray:
    """The wheels' stored momentum in body axes [N m s] at each sample: sum of J_i w_i a_i."""
    axes = np.array([w.axis_B for w in wheels], dtype=float)
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    spin = np.array([w.spin_inertia_kgm2 for w in wheels], dtype=float)
    return (np.asarray(wheel_speed_rad_s, dtype=float) * spin) @ axes


def _telemetry(run_dir: Path, packets: tuple[str, ...]) -> dict[str, dict]:
    """The packets' channels from the run's ground archive, read in one pass ({} when there is none)."""
    from ground.archive import read_packets

    archive = run_dir / "ground"
    return read_packets(archive, packets) if (archive / "tm_raw.bin").exists() else {}


def _momentum_plot(plt, run_dir: Path, mission, truth: dict, t: np.ndarray, eclipses: list, hk: dict) -> Path:
    """Momentum management at work: the wheels' momentum in body axes (truth; the onboard |h - bias| the law
    unloads, from housekeeping) above the dipole the flight software commanded on each rod."""
    fig, (ax1, ax2) = _two_time_axes(plt, eclipses)
    h = wheel_momentum_B(mission.spacecraft.wheels, truth["wheel_speed_rad_s"])
    for i, axis in enumerate("xyz"):
        ax1.plot(t, h[:, i], lw=1, label=f"h_{axis} (truth)")
    ax1.plot(t, np.linalg.norm(h, axis=1), "k", lw=1.2, label="|h| (truth)")
    th = np.asarray(hk.get("time_s", []), dtype=float)
    if "h_excess_Nms" in hk and np.isfinite(np.asarray(hk["h_excess_Nms"], dtype=float)).any():
        ax1.plot(th, hk["h_excess_Nms"], "k--", lw=1, label="|h - bias| (onboard)")
    for i in range(3):
        if f"mtq_dipole_cmd_Am2_{i}" in hk:
            ax2.plot(th, hk[f"mtq_dipole_cmd_Am2_{i}"], lw=1, label=f"rod {i + 1}")
    ax1.set_ylabel("wheel momentum [N m s]")
    ax1.legend(ncol=5, fontsize=8)
    ax1.set_title(f"{mission.name}: momentum management (wheel momentum, rod dipoles commanded)")
    ax2.set_ylabel("rod dipole commanded [A m^2]")
    ax2.set_xlabel("time [s]")
    if ax2.lines:
        ax2.legend(ncol=3, fontsize=8)
    return _save_gridded(fig, (ax1, ax2), run_dir / "momentum.png")


def _two_time_axes(plt, eclipses: list):
    """A figure of two time plots, one above the other, the Earth's shadow shaded on both."""
    fig, axes = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    shade_eclipses(axes, eclipses)
    return fig, axes


def _save_gridded(fig, axes, path: Path) -> Path:
    for ax in axes:
        ax.grid(alpha=0.3)
    return _save(fig, path)


def shade_eclipses(axes, eclipses: list[tuple[float, float, float]]) -> int:
    """Grey bands over each stretch in the Earth's shadow (umbra darker than penumbra only); the first
    axes' legend names them once. Returns the number of bands drawn per axes."""
    for k, ax in enumerate(axes):
        for i, (t0, t1, least_lit) in enumerate(eclipses):
            ax.axvspan(t0, t1, color="0.35" if least_lit == 0.0 else "0.7", alpha=0.25, lw=0,
                       label="Earth's shadow" if k == 0 and i == 0 else None)
    return len(eclipses)


def _attitude_plot(plt, run_dir: Path, mission, series: dict, t: np.ndarray, eclipses: list) -> Path:
    """The lifted attitude quaternion against time with the QUATERNION targets, and the attitude error."""
    fig, (ax1, ax2) = _two_time_axes(plt, eclipses)
    q = series["q_lift"]
    for i, name in enumerate(("eta", "q1", "q2", "q3")):
        ax1.plot(t, q[:, i], label=name)
    for s in series["segments"]:
        if s.mode == "QUATERNION":
            for i in range(4):
                ax1.hlines(s.target[i], s.t_start_s, s.t_end_s, colors=f"C{i}", linestyles=":", lw=1)
    ax1.set_ylabel("q_NB components (lifted, truth) [-]")
    ax1.legend(ncol=4, fontsize=8)
    ax1.set_title(f"{mission.name}: attitude on S^3 (dotted: targets)")
    ax2.semilogy(t, np.maximum(series["error_deg"], 1e-4))
    ax2.set_ylabel("attitude error [deg]")
    ax2.set_xlabel("time [s]")
    return _save_gridded(fig, (ax1, ax2), run_dir / "attitude.png")


def _margins_plot(plt, run_dir: Path, mission, series: dict, t: np.ndarray, eclipses: list) -> Path:
    """Signed margin to every physical zone with the requirement and the law's inflation, and the error."""
    fig, (ax1, ax2) = _two_time_axes(plt, eclipses)
    for z in series["zones"]:
        ax1.plot(t, z.margin_deg, label=f"{z.name} ({z.kind})")
    ax1.axhline(mission.requirements.min_keepout_margin_deg, color="r", lw=1.5, label="requirement")
    ax1.axhline(mission.flight_software.law.margin_deg, color="orange", ls="--", lw=1,
                label=f"law inflation {mission.flight_software.law.margin_deg:g} deg")
    ax1.set_ylabel("signed margin to physical zone [deg]")
    ax1.set_title(f"{mission.name}: keep-out margins (truth) and error to target")
    # a zone never armed (all NaN, drawn as a gap) has no extent to fit
    shown = [z.margin_deg for z in series["zones"] if np.isfinite(z.margin_deg).any()]
    if series["zones"]:
        ax1.legend(fontsize=8)
    if shown:
        top = max(float(np.nanmax(m)) for m in shown)
        ax1.set_ylim(min(-1.0, min(float(np.nanmin(m)) for m in shown) - 1), min(top, 90) + 2)
    ax2.semilogy(t, np.maximum(series["error_deg"], 1e-4))
    ax2.axhline(mission.requirements.settling_tolerance_deg, color="g", ls="--", lw=1, label="settling tolerance")
    ax2.set_ylabel("truth error to target [deg]")
    ax2.set_xlabel("time [s]")
    ax2.legend(fontsize=8)
    return _save_gridded(fig, (ax1, ax2), run_dir / "margins.png")


def _wheels_plot(plt, run_dir: Path, mission, truth: dict, t: np.ndarray, eclipses: list) -> Path:
    """Wheel speeds (with the requirement's limit) and the torques the wheel nodes applied."""
    fig, (ax1, ax2) = _two_time_axes(plt, eclipses)
    for i, w in enumerate(mission.spacecraft.wheels):
        ax1.plot(t, truth["wheel_speed_rad_s"][:, i], label=f"RW{i + 1}")
        ax2.plot(t, truth["wheel_torque_Nm"][:, i] * 1000.0, label=f"RW{i + 1}")
    lim = mission.requirements.max_wheel_speed_fraction * min(w.max_speed_rad_s for w in mission.spacecraft.wheels)
    for sign in (1, -1):
        ax1.axhline(sign * lim, color="r", ls="--", lw=1)
    ax1.set_ylabel("wheel speed [rad/s]")
    ax1.legend(ncol=6, fontsize=8)
    ax1.set_title(f"{mission.name}: reaction wheels (truth speeds, torques applied by the wheel nodes)")
    ax2.set_ylabel("wheel torque [mN m]")
    ax2.set_xlabel("time [s]")
    return _save_gridded(fig, (ax1, ax2), run_dir / "wheels.png")


def _estimation_plot(plt, run_dir: Path, mission, te: np.ndarray, err_deg: np.ndarray, sigma3_deg: np.ndarray,
                     eclipses: list) -> Path:
    """The flight software's attitude estimation error against truth, with its own 3-sigma."""
    fig, ax = plt.subplots(figsize=(10, 4))
    shade_eclipses((ax,), eclipses)
    ax.semilogy(te, np.maximum(err_deg, 1e-5), label="|estimate - truth| (attitude angle)")
    ax.semilogy(te, np.maximum(sigma3_deg, 1e-5), ls="--", label="3-sigma from cov_trace")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("attitude error [deg]")
    ax.set_title(f"{mission.name}: attitude estimation error (flight software telemetry vs truth)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, run_dir / "estimation.png")


def _sky_plot(plt, run_dir: Path, mission, series: dict, t: np.ndarray, sky_zones: list) -> Path:
    """Full sky (Mollweide) and a local view about the boresight's path (readable at any declination,
    the poles included), in the one RA convention of ``hil_sim.sil.skyplot``."""
    from hil_sim.sil import skyplot

    fig = plt.figure(figsize=(15, 5.8))
    ax_sky = fig.add_subplot(1, 2, 1, projection="mollweide")
    ax_loc = fig.add_subplot(1, 2, 2)
    colors = plt.cm.tab10.colors
    y_N = series["y_N"]
    targets = [np.asarray(s.target, dtype=float) for s in series["segments"] if s.mode == "POINTING"]
    center, radius = skyplot.local_view(np.vstack([y_N] + [x[None, :] for x in targets]))
    for k, z in enumerate(sky_zones):
        n = len(z.boundary_history)
        for j, (_, pts) in enumerate(z.boundary_history):
            closed = np.vstack([pts, pts[:1]])
            style = dict(color=colors[k % 10], alpha=0.25 + 0.75 * (j + 1) / n, lw=1.2,
                         label=f"zone {z.name} (as it moved)" if j == n - 1 else None)
            skyplot.sky_line(ax_sky, closed, **style)
            ax_loc.plot(*skyplot.local_xy_deg(closed, center), **style)
    skyplot.sky_points(ax_sky, y_N, c=t, s=3, cmap="viridis", zorder=3)
    sc = ax_loc.scatter(*skyplot.local_xy_deg(y_N, center), c=t, s=3, cmap="viridis", zorder=3)
    fig.colorbar(sc, ax=ax_loc, label="time [s]")
    for s in series["segments"]:
        if s.mode == "POINTING":
            label = f"target @{s.t_start_s:.0f} s"
            x, y = skyplot.mollweide_lon_lat(s.target)
            ax_sky.plot(x, y, marker="*", ms=14, color="k", ls="none", zorder=4)
            # the RA tick labels run along the equator: the label goes on the target's side of it, clear of them
            away = math.copysign(max(abs(y[0]) + math.radians(4.0), math.radians(14.0)), y[0] if y[0] else 1.0)
            ax_sky.annotate(label, (x[0], y[0]), xytext=(x[0], away), textcoords="data", fontsize=8,
                            ha="center", va="bottom" if away > 0 else "top", zorder=6,
                            bbox=dict(boxstyle="round,pad=0.15", fc="white", alpha=0.8, lw=0))
            x, y = skyplot.local_xy_deg(s.target, center)
            ax_loc.plot(x, y, marker="*", ms=14, color="k", ls="none", zorder=4)
            ax_loc.annotate(label, (x[0], y[0]), textcoords="offset points", xytext=(6, 6), fontsize=8)
    skyplot.sky_points(ax_sky, y_N[:1], marker="o", color="k", zorder=5, label="start")
    ax_loc.plot(*skyplot.local_xy_deg(y_N[:1], center), marker="o", color="k", ls="none", label="start")
    skyplot.format_full_sky(ax_sky)
    skyplot.format_local(ax_loc, center, radius)
    ax_sky.set_title("full sky (Mollweide)", fontsize=10)
    ax_loc.set_title("around the boresight's path (true angles)", fontsize=10)
    ax_loc.legend(loc="lower left", fontsize=8)
    fig.suptitle(f"{mission.name}: instrument boresight on the sky (truth) and physical keep-out zones")
    return _save(fig, run_dir / "sky.png")


def _estimation_error(gnc: dict, truth: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Estimation error at each GNC telemetry sample (``gnc``: the GNC packet's channels, {} without an
    archive): onboard time = simulated time in the SIL."""
    from gnc.attitude import attitude_error_angle

    if "q_est_NB_0" not in gnc or not len(gnc["time_s"]):
        return None
    te = np.asarray(gnc["time_s"], dtype=float)
    q_est = np.stack([np.asarray(gnc[f"q_est_NB_{i}"], dtype=float) for i in range(4)], axis=1)
    idx = np.clip(np.searchsorted(truth["t_s"], te - 1e-9), 0, len(truth["t_s"]) - 1)
    err = np.array([math.degrees(attitude_error_angle(qe, truth["q_NB"][i])) if np.all(np.isfinite(qe)) else np.nan
                    for qe, i in zip(q_est, idx)])
    cov = np.asarray(gnc.get("cov_trace", np.full(len(te), np.nan)), dtype=float)
    sigma3 = 3.0 * np.degrees(np.sqrt(np.clip(cov, 0, None)))  # trace = sum of the 3 axis variances
    return te, err, sigma3


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
