"""The Earth's field as IGRF to degree N (spacecraft.disturbance.magnetic_field: {model: igrf}): the compiled
synthesis against ppigrf's own evaluation (the library the coefficients come from) and against Basilisk 2.12.1's
magneticFieldWMM (another model: a stated bound), the mission key, and the field reaching everything that
uses it (the residual dipole's torque in the dynamics, `keepout truth` and `keepout budget`, the
magnetometer), with the dipole the default and unchanged."""
from __future__ import annotations

import json
import math
import sys
from dataclasses import replace
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest
import yaml

from gnc.attitude import quat_to_dcm
from hil_sim.mission.loader import ConfigError
from hil_sim.mission.model import load_mission, magnetic_device_params, world_params
from hil_sim.world import dynamics as dyn
from hil_sim.world import environment as env
from hil_sim.world.geomagnetic import (IGRF_REFERENCE_RADIUS_KM, dipole_coefficients_T, earth_rotation_angle_rad,
                                       gauss_coefficients_T)
from hil_sim.world.params import DisturbanceParams
from test_srp import _spacecraft

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data" / "basilisk"
SMALLSAT = ROOT / "config" / "missions" / "smallsat-example.yaml"
EPOCH = datetime(2026, 4, 25, 12, tzinfo=timezone.utc)
DIPOLE_B_AM2 = [0.02, -0.01, 0.03]


def _rz(theta: float) -> np.ndarray:
    """R_z(theta): N vectors into the Earth-fixed frame turned by theta about z."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])


def ppigrf_field_N(r_N_km: np.ndarray, theta: np.ndarray | float, epoch: datetime = EPOCH,
                   degree: int = 13) -> np.ndarray:
    """(n, 3) ppigrf's geocentric IGRF [T] at positions r_N (n, 3) [km], the Earth turned by theta [rad]."""
    import ppigrf

    r_N = np.atleast_2d(r_N_km)
    th = np.broadcast_to(np.asarray(theta, dtype=float), (len(r_N),))
    r_E = np.einsum("kij,kj->ki", np.array([_rz(t) for t in th]), r_N)
    r = np.linalg.norm(r_E, axis=1)
    colat, lon = np.arccos(r_E[:, 2] / r), np.arctan2(r_E[:, 1], r_E[:, 0])
    br, bt, bp = (c[0] for c in ppigrf.igrf_gc(r, np.degrees(colat), np.degrees(lon), epoch.replace(tzinfo=None),
                                               max_degree=degree))
    e_r = np.stack([np.sin(colat) * np.cos(lon), np.sin(colat) * np.sin(lon), np.cos(colat)], axis=1)
    e_t = np.stack([np.cos(colat) * np.cos(lon), np.cos(colat) * np.sin(lon), -np.sin(colat)], axis=1)
    e_p = np.stack([-np.sin(lon), np.cos(lon), np.zeros_like(lon)], axis=1)
    b_E = 1e-9 * (br[:, None] * e_r + bt[:, None] * e_t + bp[:, None] * e_p)
    return np.einsum("kji,kj->ki", np.array([_rz(t) for t in th]), b_E)


def _field_B(degree: int | None, epoch: datetime = EPOCH) -> np.ndarray:
    """The dynamics' B of one spacecraft with a residual dipole in IGRF to ``degree`` (None: the dipole)."""
    dist = DisturbanceParams(residual_dipole_B_Am2=(0.8, -0.5, 1.2), geomagnetic_dipole_T=dipole_coefficients_T(epoch),
                             geomagnetic_gauss_T=gauss_coefficients_T(epoch, degree) if degree else ())
    inputs = json.loads((DATA / "magnetic_reference.json").read_text()) | {"solar_flux_W_m2": 1361.0, "facets": []}
    _, _, B, _ = dyn.pack_spacecraft([replace(_spacecraft(inputs, srp=False), disturbance=dist)])
    return B


def _positions(n: int, seed: int = 7) -> np.ndarray:
    """n positions [km] from 300 to 2000 km up, in random directions, the first two over the poles."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(n, 3))
    u[0], u[1] = (1e-9, 0.0, 1.0), (0.0, 0.0, -1.0)  # the poles, where the (r, theta, phi) form divides by 0
    return (IGRF_REFERENCE_RADIUS_KM + rng.uniform(300.0, 2000.0, (n, 1))) * u / np.linalg.norm(u, axis=1,
                                                                                                  keepdims=True)


@pytest.mark.parametrize("degree", [13, 6, 2])
def test_the_compiled_field_is_ppigrfs_igrf(degree) -> None:
    B = _field_B(degree)
    r = _positions(40)
    theta = np.random.default_rng(3).uniform(0.0, 2.0 * math.pi, len(r))
    ours = []
    for rk, th in zip(r, theta):
        B[env.ENV_ERA0] = th
        ours.append(env.earth_field_N(B, 0, *rk, 0.0))
    theirs = ppigrf_field_N(r[2:], theta[2:], degree=degree)
    # measured 2026-11-29 at degree 13: 5e-11 nT on fields up to 45,000 nT (rounding)
    assert np.abs(np.array(ours[2:]) - theirs).max() < 1e-12  # T: 0.001 nT
    # over the poles ppigrf divides by sin(theta) = 0: ours against its field 1 m away (the field changes by
    # ~0.02 nT over 1 m)
    for k in (0, 1):
        near = r[k] + np.array([1e-3, 0.0, 0.0])
        assert np.abs(np.array(ours[k]) - ppigrf_field_N(near, theta[k], degree=degree)[0]).max() < 1e-10


def test_the_earth_turns_the_field_at_omega_e() -> None:
    B = _field_B(13)
    B[env.ENV_ERA0] = 0.7
    r = _positions(5)[2]
    t = 3_000.0
    ours = env.earth_field_N(B, 0, *r, t)
    assert np.abs(np.array(ours) - ppigrf_field_N(r, 0.7 + env.EARTH_ROTATION_RAD_S * t)[0]).max() < 1e-12


def test_degree_one_is_the_centred_dipole() -> None:
    B1, Bd = _field_B(1), _field_B(None)
    for r in _positions(20):
        ours, dipole = np.array(env.earth_field_N(B1, 0, *r, 10.0)), np.array(env.dipole_field_N(Bd, 0, *r, 10.0))
        assert np.abs(ours - dipole).max() < 1e-12 * np.linalg.norm(dipole)


def test_igrf_is_within_20_nt_of_basilisks_wmm_where_the_dipole_is_15000_nt_off() -> None:
    """WMM2025 (degree 12, NOAA/BGS) and IGRF-14 (degree 13, IAGA) are two models of the same main field from
    overlapping data; their difference, not an integration error, sets the bound. Basilisk turns the Earth by
    the planet message's J20002Pfix, as keepout by its rotation angle: any slip of frames, epoch or
    normalisation would show as thousands of nT."""
    ref = np.loadtxt(DATA / "wmm_reference.csv", delimiter=",", skiprows=1)
    meta = json.loads((DATA / "wmm_reference.json").read_text())
    assert datetime.fromisoformat(meta["epoch_utc"]) == EPOCH and meta["wmm_file"] == "WMM2025.COF"
    r, theta, theirs = ref[:, 0:3], ref[:, 3], ref[:, 4:7]

    def ours(B: np.ndarray) -> np.ndarray:
        out = []
        for rk, th in zip(r, theta):
            B[env.ENV_ERA0] = th
            out.append(env.earth_field_N(B, 0, *rk, 0.0))
        return np.array(out)

    igrf = ours(_field_B(13))
    diff = 1e9 * np.linalg.norm(igrf - theirs, axis=1)  # nT
    cos = np.sum(igrf * theirs, axis=1) / (np.linalg.norm(igrf, axis=1) * np.linalg.norm(theirs, axis=1))
    altitude = np.linalg.norm(r, axis=1) - IGRF_REFERENCE_RADIUS_KM
    # measured 2026-11-29 on 720 geometries: 17.5 nT at most (400 km), 12.3 nT at 550 km, 5.7 nT at 1200 km,
    # rms 5.7 nT; 0.027 deg of direction. The centred dipole: 14,600 nT and 33 deg.
    assert diff.max() < 20.0 and diff[altitude > 500.0].max() < 14.0 and np.sqrt(np.mean(diff ** 2)) < 7.0
    assert np.degrees(np.arccos(np.clip(cos.min(), -1.0, 1.0))) < 0.04
    dipole = 1e9 * np.linalg.norm(ours(_field_B(None)) - theirs, axis=1)
    assert dipole.max() > 10_000.0


def test_ten_days_of_secular_variation_are_a_few_nt_at_550_km() -> None:
    """The coefficients are taken once, at the epoch (the docs say so): this is what that leaves out."""
    r = _positions(2000, seed=11)[2:]  # not over the poles, where ppigrf divides by 0
    r = (IGRF_REFERENCE_RADIUS_KM + 550.0) * r / np.linalg.norm(r, axis=1, keepdims=True)
    drift = 1e9 * np.linalg.norm(ppigrf_field_N(r, 0.0, EPOCH + timedelta(days=10)) - ppigrf_field_N(r, 0.0),
                                 axis=1)
    # measured 2026-11-29: 4.0 nT at most over ten days (the longest mission), 0.40 nT a day
    assert 1.0 < drift.max() < 5.0


# ----------------------------------------------------------------------------------------- the mission key
def _mission(tmp_path: Path, field: dict | None, **spacecraft) -> object:
    data = yaml.safe_load(SMALLSAT.read_text())
    data["epoch_utc"] = EPOCH.isoformat().replace("+00:00", "Z")
    data["spacecraft"]["disturbance"]["residual_dipole_B_Am2"] = DIPOLE_B_AM2
    if field is not None:
        data["spacecraft"]["disturbance"]["magnetic_field"] = field
    data["spacecraft"].update(spacecraft)
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return load_mission(path)


def test_the_dipole_is_the_default_and_packs_no_more_rows(tmp_path) -> None:
    default, said = _mission(tmp_path, None), _mission(tmp_path, {"model": "dipole"})
    for mission in (default, said):
        d = world_params(mission).spacecraft.disturbance
        assert d.geomagnetic_gauss_T == ()
        _, _, B, _ = dyn.pack_spacecraft([world_params(mission).spacecraft])
        assert B.shape[0] == env.ENV_FACETS and B[env.ENV_FIELD_DEGREE, 0] == 0.0
    igrf = world_params(_mission(tmp_path, {"model": "igrf", "degree": 8})).spacecraft
    assert igrf.disturbance.geomagnetic_gauss_T == gauss_coefficients_T(EPOCH, 8)
    _, _, B, _ = dyn.pack_spacecraft([igrf])
    assert B[env.ENV_FIELD_DEGREE, 0] == 8.0 and B.shape[0] == env.ENV_FACETS + 2 * 44


@pytest.mark.parametrize("field, says", [
    ({"model": "igrf", "degree": 14}, "magnetic_field.degree: Input should be less than or equal to 13"),
    ({"model": "igrf", "degree": 0}, "magnetic_field.degree: Input should be greater than or equal to 1"),
    ({"model": "wmm"}, "magnetic_field.model: Input should be 'dipole' or 'igrf'"),
    ({"model": "dipole", "degree": 5}, "magnetic_field: degree applies to model: igrf"),
])
def test_a_bad_field_model_is_refused_at_its_key(tmp_path, field, says) -> None:
    with pytest.raises(ConfigError) as info:
        _mission(tmp_path, field)
    (line,) = str(info.value).splitlines()
    assert says in line
    where = line.split(" ")[0].split(":")
    assert where[0].endswith("m.yaml") and where[1].isdigit() and where[2].isdigit()  # file:line:col


# ------------------------------------------------------------------------------- the field reaches its users
def _body(q_NB: np.ndarray, v_N: np.ndarray) -> np.ndarray:
    return quat_to_dcm(q_NB).T @ v_N


def test_truth_and_the_dynamics_turn_the_residual_dipole_in_igrf(tmp_path) -> None:
    """`keepout truth`'s dipole torque (the dynamics' own kernel) is m x B with B ppigrf's IGRF at the recorded
    position, the Earth turned by its rotation angle at the epoch (itself checked against ERFA)."""
    from cli.truth import propagate

    mission = _mission(tmp_path, {"model": "igrf"})
    truth = propagate(mission, 600.0, 60.0)
    t = truth["t_s"]
    b_N = ppigrf_field_N(truth["r_sc_N_km"], earth_rotation_angle_rad(EPOCH) + env.EARTH_ROTATION_RAD_S * t)
    expected = np.array([np.cross(DIPOLE_B_AM2, _body(q, b)) for q, b in zip(truth["q_NB"], b_N)])
    assert np.abs(truth["dipole_torque_B_Nm"] - expected).max() < 1e-9 * np.abs(expected).max()
    dipole = propagate(_mission(tmp_path, None), 600.0, 60.0)
    # the two fields' torques differ by a good part of themselves, and the attitude drifts apart
    assert np.abs(dipole["dipole_torque_B_Nm"] - expected).max() > 0.05 * np.abs(expected).max()
    assert not np.array_equal(dipole["q_NB"][-1], truth["q_NB"][-1])


def test_the_budget_counts_the_residual_dipole_in_igrf(tmp_path) -> None:
    """Its row's peak torque is the largest |m x B| over the orbit's samples, B ppigrf's IGRF, the attitude held."""
    from hil_sim.world.budget import SAMPLE_S, budget
    from hil_sim.world.orbit import orbit_elements_array, orbit_position_row_N_km

    mission = _mission(tmp_path, {"model": "igrf"})
    row = next(r for r in budget(mission) if r.effect == "residual magnetic dipole" and r.span == "orbit")
    wp = world_params(mission)
    t = np.linspace(0.0, row.span_s, int(math.ceil(row.span_s / SAMPLE_S)) + 1)
    orbit, r = orbit_elements_array(wp.orbit)[None, :], np.empty((t.size, 3))
    for k, tk in enumerate(t.tolist()):
        orbit_position_row_N_km(orbit, 0, tk, r[k])
    b_N = ppigrf_field_N(r, earth_rotation_angle_rad(EPOCH) + env.EARTH_ROTATION_RAD_S * t)
    tau = np.cross(DIPOLE_B_AM2, b_N @ quat_to_dcm(np.asarray(wp.spacecraft.q_NB0)))
    assert row.peak_torque_Nm == pytest.approx(np.linalg.norm(tau, axis=1).max(), rel=1e-9)


def test_budget_and_truth_say_which_field_they_used(tmp_path, capsys) -> None:
    from cli.main import main

    _mission(tmp_path, {"model": "igrf", "degree": 10})
    assert main(["budget", str(tmp_path / "m.yaml"), "--json", str(tmp_path / "b.json")]) == 0
    assert json.loads((tmp_path / "b.json").read_text())["magnetic_field"] == "IGRF-14 to degree 10 at the epoch"
    assert main(["truth", str(tmp_path / "m.yaml"), "--duration", "10", "--out", str(tmp_path / "t.npz")]) == 0
    assert "residual magnetic dipole in IGRF-14 to degree 10 at the epoch: torque up to" in capsys.readouterr().out


def test_the_magnetometer_reads_igrf_and_flies_without_a_torque(tmp_path) -> None:
    """A magnetometer and no residual dipole nor rods: the world carries the field (no effect on: the dynamics
    as with the dipole, bit for bit) and the magnetometer reads IGRF there."""
    from comms.bus import Icd
    from hil_sim.devices.magnetic import MagneticNodes
    from hil_sim.world.world import World

    def world_of(field):
        data = yaml.safe_load(SMALLSAT.read_text())
        data["epoch_utc"] = EPOCH.isoformat().replace("+00:00", "Z")
        data["spacecraft"]["magnetometer"] = {"noise_std_T": 0.0}
        if field:
            data["spacecraft"]["disturbance"]["magnetic_field"] = field
        path = tmp_path / "mag.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False))
        mission = load_mission(path)
        world = World(world_params(mission), seed=1)
        for _ in range(30):
            world.step(1.0, np.zeros(len(mission.spacecraft.wheels)))
        return world, MagneticNodes(Icd(), magnetic_device_params(mission))

    (igrf, nodes), (dipole, dipole_nodes) = world_of({"model": "igrf"}), world_of(None)
    assert igrf.batch.B[env.ENV_FLAGS, 0] == 0.0 and igrf.batch.B[env.ENV_FIELD_DEGREE, 0] == 13.0
    assert np.array_equal(igrf.batch.X, dipole.batch.X)
    b = igrf.batch
    expected = _body(b.q_NB[0], ppigrf_field_N(b.r_sc_N_km[0], earth_rotation_angle_rad(EPOCH)
                                               + env.EARTH_ROTATION_RAD_S * igrf.t)[0])
    env.compile_field_kernels()  # what `keepout warmup` compiles: the run then compiles nothing more
    warmed = list(env.earth_field_N.signatures)
    assert np.abs(nodes.field_B_T(igrf) - expected).max() < 1e-12
    assert env.earth_field_N.signatures == warmed
    assert np.abs(dipole_nodes.field_B_T(dipole) - expected).max() > 1e-7  # the dipole is 100s of nT off


def test_a_missing_ppigrf_is_one_line_and_exit_3(tmp_path, monkeypatch, capsys) -> None:
    from cli.main import main

    path = tmp_path / "igrf.yaml"
    data = yaml.safe_load(SMALLSAT.read_text())
    data["spacecraft"]["disturbance"].update(residual_dipole_B_Am2=DIPOLE_B_AM2, magnetic_field={"model": "igrf"})
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    for name in ("ppigrf", "ppigrf.ppigrf"):
        monkeypatch.setitem(sys.modules, name, None)  # import raises ModuleNotFoundError, as if not installed
    assert main(["budget", str(path)]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["keepout: this command needs the Python package 'ppigrf', which is not installed "
                   "(pip install ppigrf)"]
