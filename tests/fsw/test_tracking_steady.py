"""A moving target (nadir, a ground point) takes the steady compiled POINTING cycle: the law is given the
target's new direction as data (`PointingGuidance._retarget_law`) instead of being rebuilt every cycle, and
the commands are those of the rebuild every cycle (the guidance with `_retarget_law` refusing every time),
also while the target's separation sets eps and while it crosses a zone's eps-layer (a substitute target)."""
from __future__ import annotations

import numpy as np
import pytest

from fsw.guidance import Guidance
from fsw.guidance.pointing import PointingGuidance
from test_guidance_earth_targets import _cfg, _q_with_boresight, _step

FIELDS = ("omega_cmd_BN_B", "target_N", "pointing_error_deg", "margin_min_deg", "active_zone", "eps")


def _zone_ahead(seconds: float, half_angle_deg: float) -> dict:
    ahead = -Guidance(_cfg({"target_kind": "nadir"})).ephem.position_N_km(seconds)
    return {"name": "no", "body": "inertial", "direction_N": list(ahead / np.linalg.norm(ahead)),
            "geometry": {"shape": "cone", "half_angle_deg": half_angle_deg}}


def _fly_counting(g: Guidance, seconds: float, dt: float = 0.1) -> tuple[list, int]:
    """Closed kinematic loop; the outputs and how many times the law was rebuilt."""
    rebuilds: list[int] = []
    rebuild = g._rebuild_sky_law
    g._rebuild_sky_law = lambda *a: (rebuilds.append(1), rebuild(*a))[1]
    q = _q_with_boresight(-g.ephem.position_N_km(0.0))
    outs = []
    for k in range(int(round(seconds / dt))):
        out = g.step(k * dt, dt, q, np.zeros(3))
        outs.append({f: np.copy(getattr(out, f)) for f in FIELDS})
        q = _step(q, out.omega_cmd_BN_B, dt)
    return outs, len(rebuilds)


@pytest.mark.parametrize("zone_s, half_angle_deg, eps_max_used", [(400.0, 5.0, 0.5), (400.0, 5.0, 0.005),
                                                                   (60.0, 1.5, 0.5)])
def test_tracking_gives_the_commands_of_a_rebuild_every_cycle(monkeypatch, zone_s, half_angle_deg,
                                                              eps_max_used) -> None:
    """(400 s, 5 deg): a zone far from nadir for the 120 s flown, eps set by the target's separation, or
    capped by eps_max_used (the law's table kept); (60 s, 1.5 deg): one nadir sweeps through at 60 s, its
    eps set by the target's separation on the way in and a substitute inside."""
    cfg = _cfg({"target_kind": "nadir", "zones": [_zone_ahead(zone_s, half_angle_deg)]},
               law={"k1": 0.2, "margin_deg": 1.0, "eps_max_used": eps_max_used})
    fast, fast_rebuilds = _fly_counting(Guidance(cfg), 120.0)
    monkeypatch.setattr(PointingGuidance, "_retarget_law", lambda self, aim: False)
    slow, slow_rebuilds = _fly_counting(Guidance(cfg), 120.0)
    for k, (a, b) in enumerate(zip(fast, slow)):
        for f in FIELDS:
            assert np.allclose(a[f], b[f], rtol=0.0, atol=1e-12, equal_nan=True), (k, f, a[f], b[f])
    assert slow_rebuilds >= 1199  # every cycle, as before
    # far from the zone only the first cycle builds the law; the sweep rebuilds while the target is in
    # the layer (the substitute), not while its separation only sets eps
    assert fast_rebuilds <= (1 if zone_s == 400.0 else 0.8 * slow_rebuilds)
    if zone_s == 60.0:
        assert max(o["pointing_error_deg"] for o in fast) > 2.0  # it did hold short while the zone covered nadir
