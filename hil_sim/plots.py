"""PNG plots of a SIL run (written into the run folder by the orchestrator).

* ``sky.png`` (missions with sky zones): the instrument boresight path on the celestial sphere
  (right ascension / declination), the physical zones drawn as they moved (outlines fade with time),
  the targets; ``attitude.png`` (missions with S^3 zones): the lifted attitude quaternion against time
  (as the paper plots it) and the attitude error;
* ``margins.png``: signed margin to every physical zone against time with the requirement limit and the
  law's inflation margin, and the truth pointing/attitude error;
* ``wheels.png``: wheel speeds (with limits) and applied wheel torques;
* ``estimation.png``: flight-software attitude estimate against truth (error angle) with the
  estimator's own 3-sigma from its covariance trace.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def _ra_dec_deg(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    v = np.atleast_2d(v)
    ra = np.degrees(np.arctan2(v[:, 1], v[:, 0])) % 360.0
    dec = np.degrees(np.arcsin(np.clip(v[:, 2], -1.0, 1.0)))
    return ra, dec


def _cut_ra(samples: list[np.ndarray]) -> float:
    """RA [deg] in the widest empty gap of everything drawn: the map wraps there, not through a zone."""
    ra = np.sort(np.concatenate([r[np.isfinite(r)] for r in samples if len(r)]) % 360.0)
    if len(ra) < 2:
        return 180.0
    gaps = np.diff(np.concatenate([ra, ra[:1] + 360.0]))
    k = int(np.argmax(gaps))
    return float((ra[k] + gaps[k] / 2.0) % 360.0)


def _break_wraps(ra: np.ndarray, dec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Insert NaNs where the RA wraps through 0/360 so lines do not cross the whole map."""
    if len(ra) < 2:
        return ra, dec
    jumps = np.nonzero(np.abs(np.diff(ra)) > 180.0)[0] + 1
    return np.insert(ra.astype(float), jumps, np.nan), np.insert(dec.astype(float), jumps, np.nan)


def write_plots(run_dir: Path, mission, series: dict | None = None) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    from hil_sim.summary import evaluate

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

    if sky_zones or mission.flight_software.pointing.zones or any(s.mode == "POINTING" for s in series["segments"]):
        fig, ax = plt.subplots(figsize=(10, 5.5))
        colors = plt.cm.tab10.colors
        path_ra, path_dec = _ra_dec_deg(series["y_N"])
        targets = [s.target for s in series["segments"] if s.mode == "POINTING"]
        cut = _cut_ra([path_ra] + [_ra_dec_deg(pts)[0] for z in sky_zones for _, pts in z.boundary_history]
                      + [_ra_dec_deg(x)[0] for x in targets])
        unwrap = lambda ra: (ra - cut) % 360.0 + cut  # noqa: E731  (values in [cut, cut + 360))
        for k, z in enumerate(sky_zones):
            n = len(z.boundary_history)
            for j, (tz, pts) in enumerate(z.boundary_history):
                ra, dec = _ra_dec_deg(np.vstack([pts, pts[:1]]))
                ra, dec = _break_wraps(unwrap(ra), dec)
                alpha = 0.25 + 0.75 * (j + 1) / n
                ax.plot(ra, dec, color=colors[k % 10], alpha=alpha, lw=1.2,
                        label=f"zone {z.name} (as it moved)" if j == n - 1 else None)
        sc = ax.scatter(unwrap(path_ra), path_dec, c=t, s=3, cmap="viridis", zorder=3)
        fig.colorbar(sc, ax=ax, label="time [s]")
        for s in series["segments"]:
            if s.mode == "POINTING":
                tra, tdec = _ra_dec_deg(s.target)
                ax.plot(unwrap(tra), tdec, marker="*", ms=14, color="k", ls="none", zorder=4)
                ax.annotate(f"target @{s.t_start_s:.0f} s", (unwrap(tra)[0], tdec[0]), textcoords="offset points",
                            xytext=(6, 6), fontsize=8)
        ax.plot(unwrap(path_ra[:1]), path_dec[:1], marker="o", color="k", ls="none", label="start")
        ax.xaxis.set_major_formatter(matplotlib.ticker.FuncFormatter(lambda v, _: f"{v % 360:.0f}"))
        ax.set_xlim(cut + 360.0, cut)  # sky maps: RA increases to the left
        ax.set_ylim(-90, 90)
        ax.set_xlabel("right ascension [deg]")
        ax.set_ylabel("declination [deg]")
        ax.set_title(f"{mission.name}: instrument boresight on the sky (truth) and physical keep-out zones")
        ax.grid(alpha=0.3)
        ax.legend(loc="lower left", fontsize=8)
        written.append(_save(fig, run_dir / "sky.png"))

    if att_zones or any(s.mode == "QUATERNION" for s in series["segments"]):
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
        q = series["q_lift"]
        for i, name in enumerate(("eta", "q1", "q2", "q3")):
            ax1.plot(t, q[:, i], label=name)
        for s in series["segments"]:
            if s.mode == "QUATERNION":
                for i in range(4):
                    ax1.hlines(s.target[i], s.t_start_s, s.t_end_s, colors=f"C{i}", linestyles=":", lw=1)
        ax1.set_ylabel("q_NB (lifted, truth)")
        ax1.legend(ncol=4, fontsize=8)
        ax1.set_title(f"{mission.name}: attitude on S^3 (dotted: targets)")
        ax2.semilogy(t, np.maximum(series["error_deg"], 1e-4))
        ax2.set_ylabel("attitude error [deg]")
        ax2.set_xlabel("time [s]")
        for ax in (ax1, ax2):
            ax.grid(alpha=0.3)
        written.append(_save(fig, run_dir / "attitude.png"))

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
    for z in series["zones"]:
        ax1.plot(t, z.margin_deg, label=f"{z.name} ({z.kind})")
    ax1.axhline(mission.requirements.min_keepout_margin_deg, color="r", lw=1.5, label="requirement")
    ax1.axhline(mission.flight_software.law.margin_deg, color="orange", ls="--", lw=1,
                label=f"law inflation {mission.flight_software.law.margin_deg:g} deg")
    ax1.set_ylabel("signed margin to physical zone [deg]")
    ax1.set_title(f"{mission.name}: keep-out margins (truth) and error to target")
    if series["zones"]:
        ax1.legend(fontsize=8)
        top = max(float(np.nanmax(z.margin_deg)) for z in series["zones"])
        ax1.set_ylim(min(-1.0, min(float(np.nanmin(z.margin_deg)) for z in series["zones"]) - 1), min(top, 90) + 2)
    ax2.semilogy(t, np.maximum(series["error_deg"], 1e-4))
    ax2.axhline(mission.requirements.settling_tolerance_deg, color="g", ls="--", lw=1, label="settling tolerance")
    ax2.set_ylabel("truth error to target [deg]")
    ax2.set_xlabel("time [s]")
    ax2.legend(fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    written.append(_save(fig, run_dir / "margins.png"))

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7), sharex=True)
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
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    written.append(_save(fig, run_dir / "wheels.png"))

    est = _estimation_error(run_dir, truth)
    if est is not None:
        te, err_deg, sigma3_deg = est
        fig, ax = plt.subplots(figsize=(10, 4))
        ax.semilogy(te, np.maximum(err_deg, 1e-5), label="|estimate - truth| (attitude angle)")
        ax.semilogy(te, np.maximum(sigma3_deg, 1e-5), ls="--", label="3-sigma from cov_trace")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("[deg]")
        ax.set_title(f"{mission.name}: attitude estimation error (flight software telemetry vs truth)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        written.append(_save(fig, run_dir / "estimation.png"))
    return written


def _estimation_error(run_dir: Path, truth: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Estimation error at each GNC telemetry sample: onboard time = simulated time in the SIL."""
    from ground.archive import read_channels
    from gnc.attitude import attitude_error_angle

    archive = run_dir / "ground"
    if not (archive / "tm_raw.bin").exists():
        return None
    gnc = read_channels(archive, "GNC")
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
