"""`keepout export`: a run's tables read back from CSV, MATLAB and Parquet equal the run's own records."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.io import loadmat

from cli import main as cli, export as export_cli
from hil_sim.mission.model import load_mission, world_params
from hil_sim.sil.orchestrator import TruthRecorder
from hil_sim.sil.judge import evaluate
from hil_sim.world.world import World

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture
def run_dir(tmp_path) -> Path:
    """A run folder as `keepout sil run` writes it: the mission used, the truth of a spacecraft turning
    slowly past the Sun zone, and a ground archive with GNC packets (one with a non-finite value) and events."""
    source = ROOT / "config" / "missions" / "demo-pointing.yaml"
    mission = load_mission(source)
    world = World(world_params(mission), seed=3)
    n_wheels = len(mission.spacecraft.wheels)
    recorder = TruthRecorder(40, n_wheels)
    torque = np.array([0.02, -0.02, 0.02, -0.02])
    recorder.record(world, torque, True)
    for _ in range(40):
        world.step(0.5, torque)
        recorder.record(world, torque, True)
    run = tmp_path / "demo-pointing-20260425-120000-abcdef"
    (run / "ground").mkdir(parents=True)
    shutil.copy(source, run / "mission.yaml")
    recorder.save(run / "truth.npz")
    lines = []
    for k in range(5):
        values = {"cycle": k, "mode": "POINTING", "q_est_NB_0": 1.0, "q_est_NB_1": 0.1 * k, "q_est_NB_2": 0.0,
                  "q_est_NB_3": 0.0, "cov_trace": "nan" if k == 0 else 1e-6 * k, "st_valid": k > 0,
                  "omega_cmd_BN_B_x": 0.001 * k, "wheel_torque_cmd_Nm_0": 0.01, "wheel_torque_cmd_Nm_5": 0.0,
                  "exec_time_ms": 0.5}
        lines.append({"apid": 16, "seq": k, "time_s": 0.1 * k, "kind": "channels", "packet": "GNC", "values": values})
    lines.append({"apid": 17, "seq": 0, "time_s": 0.0, "kind": "channels", "packet": "HK", "values": {"cycles": 1}})
    lines.append({"apid": 18, "seq": 0, "time_s": 0.2, "kind": "event", "packet": "EVENT", "event": "TARGET_REACHED",
                  "severity": "ACTIVITY_HI", "message": "target reached, error 0.0092 deg", "args": {"error_deg": 0.0092}})
    (run / "ground" / "tm_decoded.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines) + '{"cut sho')
    return run


def _truth(run: Path) -> dict[str, np.ndarray]:
    with np.load(run / "truth.npz") as data:
        return {k: data[k] for k in data.files}


def _assert_truth_equal(columns, truth: dict[str, np.ndarray]) -> None:
    """Every key of truth.npz rebuilt from its columns (name, name_0.., name_x/_y/_z) equals the record."""
    for key, values in truth.items():
        if values.ndim == 1:
            got = np.asarray(columns[key]).reshape(-1)
        else:
            suffixes = "xyz" if f"{key}_x" in columns else [str(j) for j in range(values.shape[1])]
            got = np.column_stack([np.asarray(columns[f"{key}_{s}"]).reshape(-1) for s in suffixes])
        if values.dtype == bool:  # CSV and Parquet: booleans; MATLAB: 0/1
            got = got.astype(str) == "True" if got.dtype.kind in "OU" else got.astype(bool)
        np.testing.assert_array_equal(got, values, err_msg=key)


def test_csv_and_mat_read_back_equal_truth_npz(run_dir, tmp_path, capsys):
    truth = _truth(run_dir)
    assert cli.main(["export", str(run_dir), "--format", "csv", "--out", str(tmp_path / "csv")]) == 0
    assert cli.main(["export", str(run_dir), "--format", "mat", "--out", str(tmp_path / "mat")]) == 0
    written = capsys.readouterr().out
    assert all(f"wrote {tmp_path / 'csv' / name}.csv" in written for name in export_cli.TABLES)

    csv = {name: pd.read_csv(tmp_path / "csv" / f"{name}.csv", float_precision="round_trip") for name in export_cli.TABLES}
    _assert_truth_equal(csv["truth"], truth)
    mat = loadmat(tmp_path / "mat" / "run.mat", simplify_cells=True)
    assert set(export_cli.TABLES) <= set(mat)
    _assert_truth_equal(mat["truth"], truth)

    # the boresight column is the instrument axis turned by the true attitude
    from gnc.attitude import quat_rotate
    b = quat_rotate(truth["q_NB"][-1], np.array([0.0, 0.0, 1.0]))
    assert np.allclose(csv["truth"][["boresight_N_x", "boresight_N_y", "boresight_N_z"]].to_numpy()[-1], b)

    # margins: the judge's own numbers (its minimum per zone is the summary's requirement row)
    summary, _ = evaluate(run_dir, load_mission(run_dir / "mission.yaml"))
    for zone in ("sun", "moon"):
        row = next(r for r in summary["requirements"] if r["name"] == f"keep-out margin {zone}")
        for margins in (csv["margins"][f"margin_{zone}_deg"], mat["margins"][f"margin_{zone}_deg"]):
            assert float(f"{np.min(margins):.4g}") == pytest.approx(row["value"])
    np.testing.assert_array_equal(csv["margins"]["t_s"], truth["t_s"])

    # telemetry: estimates and commands split by channel, on onboard time; the text "nan" is a number again
    est, cmd = csv["estimates"], csv["commands"]
    assert list(est["time_s"]) == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4])
    assert np.isnan(est["cov_trace"][0]) and est["cov_trace"][4] == pytest.approx(4e-6)
    assert "q_est_NB_1" in est and "omega_cmd_BN_B_x" not in est and "exec_time_ms" not in est
    assert "omega_cmd_BN_B_x" in cmd and "mode" in cmd and "q_est_NB_1" not in cmd
    assert "wheel_torque_cmd_Nm_0" in cmd and "wheel_torque_cmd_Nm_5" not in cmd  # the spacecraft has 4 wheels
    assert list(mat["commands"]["mode"]) == ["POINTING"] * 5
    assert np.allclose(mat["estimates"]["q_est_NB_1"], est["q_est_NB_1"])
    events = csv["events"]
    assert list(events["event"]) == ["TARGET_REACHED"] and json.loads(events["args"][0]) == {"error_deg": 0.0092}
    assert mat["events"]["message"] == "target reached, error 0.0092 deg"


def test_parquet_keeps_types(run_dir, tmp_path):
    assert cli.main(["export", str(run_dir), "--format", "parquet", "--out", str(tmp_path)]) == 0
    truth = pd.read_parquet(tmp_path / "truth.parquet")
    assert truth["cycle_done"].dtype == bool
    _assert_truth_equal(truth, _truth(run_dir))
    assert pd.read_parquet(tmp_path / "estimates.parquet")["st_valid"].tolist() == [False, True, True, True, True]


def test_default_folder_and_a_run_without_ground_telemetry(run_dir, capsys):
    shutil.rmtree(run_dir / "ground")  # as `keepout sim` leaves it
    assert cli.main(["export", str(run_dir)]) == 0
    out = capsys.readouterr().out
    assert (run_dir / "export" / "truth.csv").is_file() and "empty: estimates, commands, events" in out


def test_a_folder_that_is_not_a_run_is_refused(tmp_path, capsys):
    assert cli.main(["export", str(tmp_path)]) == export_cli.EXIT_BAD_RUN
    assert "is not a run folder: it needs truth.npz and mission.yaml" in capsys.readouterr().err
    assert not (tmp_path / "export").exists()
