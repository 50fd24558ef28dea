"""``keepout export RUN --format csv|mat|parquet [--out DIR]``: a run's records as tables other tools read.

A run folder (``keepout sil run``, or ``keepout sim`` on a bench) keeps the truth as ``truth.npz`` and the
ground's telemetry as JSON lines; this command writes five tables, one row per sample, one column per
scalar (a vector ``q_NB`` becomes ``q_NB_0 .. q_NB_3``; every name carries its unit as the project's keys do):

- ``truth``: the simulator's truth at every tick (every key of ``truth.npz``) and the instrument boresight
  in N it implies (``boresight_N_x/y/z``);
- ``margins``: the signed angle [deg] from the boresight to each physical keep-out zone on the truth
  ephemeris, one column per zone (``margin_<zone>_deg``): the numbers the run's judge uses;
- ``estimates``: the flight software's estimate as telemetered (quaternion, rate, gyro bias, covariance
  trace, sensor validity, pointing error, its margin to the nearest physical zone as it estimates it);
- ``commands``: what it commanded (mode, target, rate command, body and wheel torques);
- ``events``: its events (time, name, severity, message, arguments as JSON).

CSV and Parquet give one file per table; MATLAB gets one ``run.mat`` (``scipy.io.savemat``) holding a
struct per table, each field a column (``load('run.mat'); plot(truth.t_s, margins.margin_sun_deg)``).
The run folder's files and the keys of ``truth.npz`` are described in docs/running.md.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path
from typing import Any

from cli import description_of

FORMATS = ("csv", "mat", "parquet")
TABLES = ("truth", "margins", "estimates", "commands", "events")
MAT_FILE = "run.mat"
EXIT_BAD_RUN = 2  # the folder given is not a run folder (nothing was written)
# Telemetry channels of the GNC packet in each table, by name prefix
ESTIMATE_CHANNELS = ("q_est_NB_", "omega_est_BN_B_", "bias_est_B_", "cov_trace", "st_valid", "imu_valid", "st_age_s",
                     "st_blind_source", "att_error_deg", "pointing_error_deg", "roll_error_deg", "margin_min_deg",
                     "boresight_N_")
COMMAND_CHANNELS = ("mode", "safe_phase", "target_N_", "q_target_NB_", "omega_cmd_BN_B_", "torque_cmd_B_Nm_",
                    "wheel_torque_cmd_Nm_", "torque_scale", "rate_norm_deg_s")


def add_cli(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "export", help="write a run's truth, estimates, commands, margins and events as CSV, MATLAB or Parquet",
        description=description_of(__doc__), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", type=Path, metavar="RUN", help="a run folder (runs/<mission>-<stamp>)")
    p.add_argument("--format", choices=FORMATS, default="csv", help="csv (default), mat or parquet")
    p.add_argument("--out", type=Path, default=None, help="output folder (default: RUN/export)")
    p.set_defaults(func=_export)


def _export(args: argparse.Namespace) -> int:
    try:
        tables = run_tables(args.run)
    except (FileNotFoundError, ValueError) as exc:
        print(f"keepout export: {exc}", file=sys.stderr)
        return EXIT_BAD_RUN
    out = args.out if args.out is not None else args.run / "export"
    for path in write_tables(tables, out, args.format):
        print(f"wrote {path}")
    empty = [name for name, df in tables.items() if df.empty]
    if empty:
        print(f"empty: {', '.join(empty)} ({args.run} holds no such record, e.g. a `keepout sim` folder has no "
              "ground telemetry)")
    return 0


def run_tables(run_dir: Path) -> dict[str, Any]:
    """The five tables of a run folder as pandas DataFrames (empty where the run has no such record)."""
    import numpy as np
    import pandas as pd

    from hil_sim.mission.model import load_mission
    from hil_sim.sil.orchestrator import CONFIG_FILE, TRUTH_FILE
    from hil_sim.sil.judge import attitude_zone_series, boresight_N, lifted_quaternions, sky_zone_series

    run_dir = Path(run_dir)
    if not (run_dir / TRUTH_FILE).is_file() or not (run_dir / CONFIG_FILE).is_file():
        raise FileNotFoundError(f"{run_dir} is not a run folder: it needs {TRUTH_FILE} and {CONFIG_FILE} (written by "
                                "`keepout sil run` and `keepout sim`)")
    mission = load_mission(run_dir / CONFIG_FILE)
    with np.load(run_dir / TRUTH_FILE) as data:
        truth = {k: data[k] for k in data.files}
    y_N = boresight_N(truth["q_NB"], np.asarray(mission.spacecraft.instrument_boresight_B, dtype=float))
    truth_table = _columns({**truth, "boresight_N": y_N})
    zones = sky_zone_series(mission, truth, y_N) if mission.flight_software.pointing.zones else []
    if mission.flight_software.quaternion.zones:
        zones += attitude_zone_series(mission, lifted_quaternions(mission, truth))
    margins = {"t_s": truth["t_s"], **{f"margin_{_identifier(z.name)}_deg": z.margin_deg for z in zones}}
    gnc, events = _telemetry(run_dir / "ground" / "tm_decoded.jsonl")
    n_wheels = len(mission.spacecraft.wheels)
    return {"truth": pd.DataFrame(truth_table), "margins": pd.DataFrame(margins),
            "estimates": _select(gnc, ESTIMATE_CHANNELS, n_wheels), "commands": _select(gnc, COMMAND_CHANNELS, n_wheels),
            "events": events}


def _columns(arrays: dict[str, Any]) -> dict[str, Any]:
    """One column per scalar: a (n, k) array ``name`` becomes ``name_0 .. name_{k-1}`` (``_x/_y/_z`` for
    3-vectors named ``..._N``/``..._B``, as the telemetry names them)."""
    out = {}
    for name, values in arrays.items():
        if values.ndim == 1:
            out[name] = values
            continue
        xyz = values.shape[1] == 3 and re.search(r"_(N|B)(_|$)", name)
        for j in range(values.shape[1]):
            out[f"{name}_{'xyz'[j] if xyz else j}"] = values[:, j]
    return out


def _identifier(name: str) -> str:
    """A zone name as part of a column name every tool takes (MATLAB fields: letters, digits, _)."""
    return re.sub(r"\W+", "_", name).strip("_") or "zone"


def _telemetry(path: Path):
    """(GNC packets, events) of the ground's decoded archive, on onboard time ``time_s``."""
    import pandas as pd

    gnc, events = [], []
    if path.is_file():
        with open(path, encoding="utf-8") as f:
            for line in f:
                try:
                    rec = json.loads(line)
                except json.JSONDecodeError:
                    continue  # a line cut short by a crash: the rest is still exported
                if rec.get("kind") == "channels" and rec.get("packet") == "GNC":
                    gnc.append({"time_s": rec.get("time_s"),
                                **{k: _number(v) for k, v in rec.get("values", {}).items()}})
                elif rec.get("kind") == "event":
                    events.append({"time_s": rec.get("time_s"), "event": rec.get("event", ""),
                                   "severity": rec.get("severity", ""), "message": rec.get("message", ""),
                                   "args": json.dumps(rec.get("args", {}), sort_keys=True)})
    return pd.DataFrame(gnc), pd.DataFrame(events, columns=["time_s", "event", "severity", "message", "args"])


_NON_FINITE = {"nan": float("nan"), "inf": float("inf"), "-inf": float("-inf")}


def _number(value: Any) -> Any:
    """A telemetry value; the archive writes a non-finite number as the text "nan"/"inf" (JSON has none)."""
    return _NON_FINITE.get(value.lower(), value) if isinstance(value, str) else value


def _select(gnc, prefixes: tuple[str, ...], n_wheels: int):
    """The GNC channels named by ``prefixes`` (per-wheel channels only for the wheels the spacecraft has)."""
    if gnc.empty:
        return gnc
    keep = ["time_s"]
    for col in gnc.columns:
        if col == "time_s" or not col.startswith(prefixes):
            continue
        wheel = re.fullmatch(r"wheel_\w+_(\d+)", col)
        if wheel and int(wheel.group(1)) >= n_wheels:
            continue
        keep.append(col)
    return gnc[keep].sort_values("time_s", kind="stable").reset_index(drop=True)


def write_tables(tables: dict[str, Any], out: Path, fmt: str) -> list[Path]:
    """Write ``tables`` into ``out`` in format ``fmt``; returns the files written."""
    import numpy as np

    out.mkdir(parents=True, exist_ok=True)
    if fmt == "csv":
        paths = [out / f"{name}.csv" for name in tables]
        for path, df in zip(paths, tables.values()):
            df.to_csv(path, index=False, float_format="%.17g")  # every digit: a CSV read back equals the run
        return paths
    if fmt == "parquet":
        paths = [out / f"{name}.parquet" for name in tables]
        for path, df in zip(paths, tables.values()):
            df.to_parquet(path, index=False)
        return paths
    if fmt == "mat":
        from scipy.io import savemat

        structs = {}
        for name, df in tables.items():
            fields = {}
            for col in df.columns:
                values = df[col].to_numpy()
                if values.dtype == object:  # strings (mode names, messages): MATLAB cell arrays
                    values = np.array(["" if v is None else str(v) for v in values], dtype=object)
                elif values.dtype == bool:
                    values = values.astype(np.uint8)  # MATLAB logical arrays load as uint8 from savemat
                fields[_identifier(col)] = values.reshape(-1, 1)
            structs[name] = fields
        path = out / MAT_FILE
        savemat(path, structs, long_field_names=True, do_compression=True, oned_as="column")
        return [path]
    raise ValueError(f"unknown format {fmt!r}: one of {', '.join(FORMATS)}")
