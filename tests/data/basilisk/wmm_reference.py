"""Basilisk 2.12.1 reference for the Earth's main field beyond the dipole: magneticFieldWMM (the World Magnetic
Model 2025, degree 12, the WMM2025.COF Basilisk's support data ships) at the epoch 2026-04-25T12:00Z, on
geometries a low-orbit spacecraft sees. Writes

* wmm_reference.csv: 720 geometries, each the spacecraft's position in N [km], the angle theta [rad] the
  Earth is turned by about z (the planet message's J20002Pfix; keepout's Earth rotation angle) and Basilisk's
  field in N [T]: 6 angles x 120 positions (random directions at 400, 550, 800 and 1200 km above a
  6371.2 km sphere, and 8 within 0.1 deg of the poles);
* wmm_reference.json: every input and the provenance.

keepout's IGRF-14 is another model from other data: the test holds the two within a stated bound (the models'
difference), not to rounding.

    python tests/data/basilisk/wmm_reference.py [WMM2025.COF]   # with Basilisk (pip install bsk==2.12.1)

Without an argument the COF file comes from Basilisk's own support-data fetcher (a download); pass a copy of
Basilisk's ``supportData/MagneticField/WMM2025.COF`` where there is no network.
"""
from __future__ import annotations

import datetime
import hashlib
import json
import math
import sys
from pathlib import Path

import numpy as np
from Basilisk import __version__ as bsk_version
from Basilisk.architecture import messaging
from Basilisk.simulation import magneticFieldWMM
from Basilisk.utilities import SimulationBaseClass, macros

HERE = Path(__file__).resolve().parent
EPOCH = datetime.datetime(2026, 4, 25, 12, 0, tzinfo=datetime.timezone.utc)
RADIUS_KM = 6371.2
ALTITUDES_KM = (400.0, 550.0, 800.0, 1200.0)
PER_ALTITUDE = 28  # random directions at each altitude, plus 8 near the poles: 120 positions an angle
N_ANGLES = 6
SEED = 20261129


def _cof_path() -> Path:
    if len(sys.argv) > 1:
        return Path(sys.argv[1])
    from Basilisk.utilities.supportDataTools.dataFetcher import DataFile, get_path

    return Path(get_path(DataFile.MagneticFieldData.WMM))


def _positions(rng: np.random.Generator) -> np.ndarray:
    """(120, 3) positions [km] in the Earth-fixed frame."""
    rows = []
    for h in ALTITUDES_KM:
        u = rng.normal(size=(PER_ALTITUDE, 3))
        rows.append((RADIUS_KM + h) * u / np.linalg.norm(u, axis=1, keepdims=True))
    for k in range(8):  # within 0.1 deg of a pole, at 550 km
        lat = math.radians((90.0 - 0.1 * rng.random()) * (1 if k % 2 else -1))
        lon = rng.uniform(0.0, 2.0 * math.pi)
        rows.append((RADIUS_KM + 550.0) * np.array([[math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon),
                                                      math.sin(lat)]]))
    return np.vstack(rows)


def _fields_N(cof: Path, r_N_km: np.ndarray, theta_rad: float) -> np.ndarray:
    """Basilisk's WMM field in N [T] at each position, the Earth turned by theta about z."""
    sim = SimulationBaseClass.SimBaseClass()
    proc = sim.CreateNewProcess("p")
    proc.addTask(sim.CreateNewTask("t", macros.sec2nano(1.0)))
    field = magneticFieldWMM.MagneticFieldWMM()
    field.ModelTag = "wmm"
    field.configureWMMFile(str(cof))
    epoch = messaging.EpochMsgPayload()
    epoch.year, epoch.month, epoch.day = EPOCH.year, EPOCH.month, EPOCH.day
    epoch.hours, epoch.minutes, epoch.seconds = EPOCH.hour, EPOCH.minute, float(EPOCH.second)
    epoch_msg = messaging.EpochMsg().write(epoch)
    field.epochInMsg.subscribeTo(epoch_msg)
    c, s = math.cos(theta_rad), math.sin(theta_rad)
    planet = messaging.SpicePlanetStateMsgPayload()
    planet.PositionVector = [0.0, 0.0, 0.0]
    planet.J20002Pfix = [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]
    planet.PlanetName = "earth"
    planet_msg = messaging.SpicePlanetStateMsg().write(planet)
    field.planetPosInMsg.subscribeTo(planet_msg)
    keep = [planet_msg, epoch_msg]
    logs = []
    for r in r_N_km:
        state = messaging.SCStatesMsgPayload()
        state.r_BN_N = (1e3 * r).tolist()
        msg = messaging.SCStatesMsg().write(state)
        keep.append(msg)
        field.addSpacecraftToModel(msg)
    sim.AddModelToTask("t", field)
    for k in range(len(r_N_km)):
        logs.append(field.envOutMsgs[k].recorder())
        sim.AddModelToTask("t", logs[-1])
    sim.InitializeSimulation()
    sim.TotalSim.SingleStepProcesses()
    return np.array([log.magField_N[-1] for log in logs])


def main() -> None:
    cof = _cof_path()
    rng = np.random.default_rng(SEED)
    r_E = _positions(rng)
    rows = []
    for theta in rng.uniform(0.0, 2.0 * math.pi, N_ANGLES).tolist():
        c, s = math.cos(theta), math.sin(theta)
        r_N = r_E @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])  # N = R_z(theta) E
        b_N = _fields_N(cof, r_N, theta)
        rows += [[*r, theta, *b] for r, b in zip(r_N.tolist(), b_N.tolist())]
    with open(HERE / "wmm_reference.csv", "w") as f:
        f.write("r_x_km,r_y_km,r_z_km,theta_rad,b_x_T,b_y_T,b_z_T\n")
        for row in rows:
            f.write(",".join(repr(float(v)) for v in row) + "\n")
    (HERE / "wmm_reference.json").write_text(json.dumps({
        "basilisk": bsk_version, "generator": "tests/data/basilisk/wmm_reference.py",
        "generated_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"),
        "modules": "magneticFieldWMM (epochInMsg: the epoch; planetPosInMsg: the Earth at the origin turned by "
                   "theta about z)",
        "wmm_file": cof.name, "wmm_file_md5": hashlib.md5(cof.read_bytes()).hexdigest(),
        "wmm_header": cof.read_text().splitlines()[0].strip(),
        "epoch_utc": EPOCH.isoformat(), "radius_km": RADIUS_KM, "altitudes_km": list(ALTITUDES_KM),
        "seed": SEED, "frames": "r and b in N; the Earth-fixed frame is N turned by theta about z "
                                "(J20002Pfix = R_z(theta) maps N vectors into it); b in tesla",
    }, indent=1) + "\n")


if __name__ == "__main__":
    main()
