"""Generate eclipse_reference.csv/.json: Basilisk 2.12.1's eclipse module (conical Earth shadow) on a set
of geometries that cross the umbra and the penumbra of a 550 km orbit, and of a geostationary one.

    pip install bsk==2.12.1    # in a separate venv
    python tests/data/basilisk/eclipse_reference.py

The Sun is placed 1 AU from the Earth's centre along a fixed direction; the spacecraft on a circle of the
orbit's radius in a plane that contains the Sun direction, sampled every 0.5 deg and densely near the
shadow's edges.
Each row: the spacecraft's and the Sun's geocentric positions [km] and Basilisk's shadowFactor (0 umbra,
1 full Sun). Basilisk's radii (REQ_EARTH, REQ_SUN) are recorded in the JSON: the test passes them in.
"""
from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
from Basilisk import __version__ as bsk_version
from Basilisk.architecture import astroConstants, messaging
from Basilisk.simulation import eclipse

HERE = Path(__file__).resolve().parent
AU_KM = 149_597_870.7


def main() -> None:
    sun_dir = np.array([0.6, 0.7, 0.3]) / np.linalg.norm([0.6, 0.7, 0.3])
    sun_km = AU_KM * sun_dir
    e = eclipse.Eclipse()
    sun = messaging.SpicePlanetStateMsgPayload()
    sun.PositionVector = (sun_km * 1e3).tolist()
    sun.PlanetName = "sun"
    earth = messaging.SpicePlanetStateMsgPayload()
    earth.PositionVector = [0.0, 0.0, 0.0]
    earth.PlanetName = "earth"
    sc = messaging.SCStatesMsgPayload()
    sun_msg, earth_msg, sc_msg = messaging.SpicePlanetStateMsg().write(sun), messaging.SpicePlanetStateMsg().write(earth), messaging.SCStatesMsg()
    sc_msg.write(sc)
    e.sunInMsg.subscribeTo(sun_msg)
    e.addPlanetToModel(earth_msg)
    e.addSpacecraftToModel(sc_msg)
    e.Reset(0)
    # an orthonormal pair spanning a plane that contains the Sun direction
    u = np.cross(sun_dir, [0.0, 0.0, 1.0])
    p1, p2 = sun_dir, u / np.linalg.norm(u)
    rows = []
    for radius_km in (astroConstants.REQ_EARTH + 550.0, 42_164.0):
        coarse = np.linspace(0.0, 2 * np.pi, 721)[:-1]
        # the shadow's edges: the spacecraft at the Earth's radius from the Sun-Earth line, behind the Earth
        half = math.asin(astroConstants.REQ_EARTH / radius_km)
        fine = np.concatenate([np.linspace(th - 0.02, th + 0.02, 401) for th in (math.pi - half, math.pi + half)])
        for th in np.concatenate([coarse, fine]):
            r_km = radius_km * (math.cos(th) * p1 + math.sin(th) * p2)
            sc.r_BN_N = (r_km * 1e3).tolist()
            sc_msg.write(sc)
            e.UpdateState(0)
            rows.append([*r_km.tolist(), *sun_km.tolist(), e.eclipseOutMsgs[0].read().shadowFactor])
    with open(HERE / "eclipse_reference.csv", "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["r_sc_x_km", "r_sc_y_km", "r_sc_z_km", "r_sun_x_km", "r_sun_y_km", "r_sun_z_km", "shadow_factor"])
        out.writerows([[repr(v) for v in row] for row in rows])
    (HERE / "eclipse_reference.json").write_text(json.dumps({
        "basilisk": bsk_version, "module": "Basilisk.simulation.eclipse.Eclipse (shadowFactor)",
        "earth_radius_km": astroConstants.REQ_EARTH, "sun_radius_km": astroConstants.REQ_SUN,
        "rows": len(rows), "generator": "tests/data/basilisk/eclipse_reference.py"}, indent=1) + "\n")


if __name__ == "__main__":
    main()
