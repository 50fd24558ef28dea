"""`keepout truth`: the truth models alone. The angular momentum it records obeys dH_N/dt = R_NB tau_B:
conserved with no external torque, and with a constant body torque equal to its integral along the
recorded attitude (a check the recorder cannot pass by copying the model)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.integrate import trapezoid
from scipy.spatial.transform import Rotation

from cli.main import main

ROOT = Path(__file__).resolve().parents[2]
MISSION = ROOT / "config" / "missions" / "demo-pointing.yaml"


def _mission(tmp_path: Path, constant_B_Nm: list[float]) -> Path:
    data = yaml.safe_load(MISSION.read_text())
    data["spacecraft"]["disturbance"] = {"constant_B_Nm": constant_B_Nm}
    data["initial_state"]["omega_BN_B_rad_s"] = [0.01, -0.005, 0.004]  # tumbling: the body axes sweep round
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _fly(tmp_path: Path, torque: list[float], duration: str = "300") -> dict:
    out = tmp_path / "truth.npz"
    assert main(["truth", str(_mission(tmp_path, torque)), "--duration", duration, "--out", str(out)]) == 0
    return dict(np.load(out))


def test_without_external_torque_angular_momentum_is_conserved(tmp_path: Path) -> None:
    truth = _fly(tmp_path, [0.0, 0.0, 0.0])
    h = truth["H_N_Nms"]
    q = truth["q_NB"]
    assert 2 * np.degrees(np.arccos(min(1.0, abs(float(q[-1] @ q[0]))))) > 30.0  # a tumble, not a rest
    assert np.abs(h - h[0]).max() < 1e-9 * np.linalg.norm(h[0])
    assert truth["t_s"][-1] == pytest.approx(300.0) and not truth["cycle_done"].any()
    # demo-pointing is geostationary near the equinox of its epoch: in full Sun for these 300 s
    assert truth["sunlit_fraction"].shape == truth["t_s"].shape and np.all(truth["sunlit_fraction"] == 1.0)


def test_a_constant_body_torque_adds_its_integral_along_the_attitude(tmp_path: Path) -> None:
    tau_B = np.array([2e-4, -1e-4, 5e-5])
    truth = _fly(tmp_path, tau_B.tolist())
    q = truth["q_NB"]  # scalar first
    tau_N = Rotation.from_quat(np.c_[q[:, 1:], q[:, :1]]).apply(tau_B)
    expected = trapezoid(tau_N, truth["t_s"], axis=0)
    got = truth["H_N_Nms"][-1] - truth["H_N_Nms"][0]
    # the body turned under the torque: its integral is not tau * t along the first attitude
    assert np.linalg.norm(expected - tau_N[0] * truth["t_s"][-1]) > 0.1 * np.linalg.norm(expected)
    assert got == pytest.approx(expected, abs=1e-4 * np.linalg.norm(expected))


def test_bad_arguments_are_one_line_errors(tmp_path: Path, capsys) -> None:
    assert main(["truth", str(MISSION), "--out", str(tmp_path / "t.csv")]) == 2
    assert ".npz" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["truth", str(MISSION), "--duration", "nan", "--out", str(tmp_path / "t.npz")])
    assert "not a positive number" in capsys.readouterr().err
