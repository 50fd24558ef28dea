"""Guidance: the modes (SAFE, POINTING, QUATERNION), the keep-out zones, and the paper's laws.

Each GNC cycle the active mode turns the attitude estimate into a body-rate command ``omega_cmd_BN_B``:

* POINTING: the instrument boresight ``y_N = R_NB b_B`` is the state on S^2. Sun, Moon and Earth zones
  are rebuilt from the onboard ephemeris (`gnc.sky_zones`), inflated by ``law.margin_deg``; the
  `gnc.laws.StarShapedLaw` gives ``u`` and `gnc.attitude.pointing_rate_command` gives
  ``omega = b^x R^T u`` (no component about the boresight). A separate proportional roll law turns
  about the boresight so that ``roll_axis_B`` lines up with the roll reference in the plane normal to
  the boresight: ``roll_reference_N``, or the Sun, the orbit's velocity or normal by the rule
  ``pointing.roll_reference`` (it cannot move the boresight, so it cannot affect keep-out).
* QUATERNION: the state is the attitude quaternion on S^3, zones are forbidden-attitude sets on S^3.
  `GradientLaw` when every zone is a cone (and law is 'auto' or 'gradient'), else `StarShapedLaw`;
  ``omega = 2 A(q)^T u``.
* SAFE: rate damping (omega_cmd = 0) until the rate stays below a threshold for 1 s, then the
  configured body axis is turned to the Sun (same S^2 map without zones).


Where each behaviour lives (one module per concern):

* `fsw.guidance.core`: `Guidance`, the mode switch, telecommanded targets and gains, the assumption-check
  hand-over; `step` runs once per GNC cycle and calls the active mode;
* `gnc.sky_ephemeris`: `SkyEphemeris`, the onboard Sun, Moon and Earth directions (re-exported here);
* `fsw.guidance.zone_merging`: `ZoneGeometry` and `merge_zones`, close zones merged into one for the law,
  the admissible eps, the substitute (retreat) target;
* `fsw.guidance.pointing`: POINTING on S^2, the sky zones rebuilt as they move, margins, roll;
* `fsw.guidance.path_planning`: the shortest slew path round the zones (visibility graph);
* `fsw.guidance.path_following`: the law's aim moved along that path, replanned when a zone moves onto it;
* `fsw.guidance.watchdog`: the guidance watchdog, a slew standing still reported and replanned;
* `fsw.guidance.quaternion`: QUATERNION on S^3, forbidden-attitude zones, the double-cover lift;
* `fsw.guidance.attitude_planning`: QUATERNION slews planned on S^3 round the zones' bounding balls;
* `fsw.guidance.safe`: SAFE (rate damping, Sun acquisition) and the no-fix acquisition rotation;
* `fsw.guidance.common`: the per-cycle output record and small vector helpers.

Keep-out margin: how to choose ``law.margin_deg``. The law guarantees d_s(y, U_infl) > 0 only for the
kinematic system ydot = P(y)u. The real loop lags it, so the boresight can cross into the inflated layer
by the lag error; the requirement is judged on the physical zones, so choose

    margin_deg >= ephemeris error + estimation error + tracking overshoot + rebuild tolerance

* ephemeris: Moon 0.3 deg (gnc.ephemeris, max), Sun 0.01 deg, Earth (onboard orbit) as good as the orbit;
* estimation: 3 sigma of the attitude estimate, sqrt(cov_trace) (~0.01 deg with a star tracker; grows
  while coasting: the estimator's coasting time bounds it);
* tracking overshoot: when the law turns the rate command in the eps-layer, the rate loop needs about
  ``1 / rate_bandwidth`` seconds to follow and the wheels decelerate at most at ``alpha = tau_eff / J``,
  so the boresight can run past the kinematic path by at most about
  ``omega_max^2 / (2 alpha) + omega_max / rate_bandwidth`` (rad): ~1 deg + ~1 deg for 1 deg/s, 1 rad/s,
  0.5 deg/s^2. That bound is pessimistic because the law turns gradually across its layer. Measured
  (bench/fsw.py margin study; 120 deg slew at 1 deg/s past a star-shaped Sun zone and a Moon cone,
  hil_sim spacecraft 20/25/15 kg m^2, four 0.2 N m wheels, noisy gyro and star tracker, 10 Hz):

      margin_deg   kinematic-law minimum   real-loop minimum   consumed by the loop
         0.0              2.68 deg             2.69 deg              0.0 deg
         1.0              3.39                 3.36                  0.03
         2.0              4.09                 3.86                  0.23
         3.0              4.78                 4.42                  0.35
         5.0              6.14                 5.50                  0.64

  (the kinematic law itself stays ~2.7 deg outside the inflated boundary here; a grazing path can come
  arbitrarily close, so the law's standoff must not be counted on);
* nothing for the zone rebuild tolerance: zones are rebuilt only when their centre has moved by
  ``ZONE_REBUILD_TOL_DEG`` (0.1 deg; in LEO the Earth moves 0.06 deg/s, so about every 2 s instead of
  every cycle), and the law's zones carry that tolerance as extra inflation, while the physical margins
  are corrected by the drift since the build (moving a set by d changes a distance by at most d).

Rule: margin_deg = 0.3 (Moon ephemeris) + 3 sigma attitude (sqrt(cov_trace), longest expected coast)
+ the larger of the measured loop consumption and half the overshoot bound above, rounded up; 2-3 deg for
the default spacecraft at 1 deg/s. Re-measure with ``bench/fsw.py --skip-cycle --skip-realtime`` after
changing the rate limit, k1, the rate bandwidth or the wheels; the tracking term grows with
omega_max^2 / alpha. ``KEEP_OUT_MARGIN_LOW`` (yellow limit) tells
operations when the loop eats more of the margin than budgeted.
"""
from __future__ import annotations

from fsw.guidance.common import GuidanceOutput, d_s_to_deg, signed_margin_deg
from fsw.guidance.core import Guidance
from gnc.sky_ephemeris import EPHEMERIS_NODE_S, SkyEphemeris
from fsw.guidance.pointing import LAW_REBUILD_TRIGGER_DEG, PHYS_REBUILD_TOL_DEG, ZONE_REBUILD_TOL_DEG
from fsw.guidance.zone_merging import ZoneGeometry, merge_zones

__all__ = [
    "EPHEMERIS_NODE_S", "LAW_REBUILD_TRIGGER_DEG", "PHYS_REBUILD_TOL_DEG", "ZONE_REBUILD_TOL_DEG",
    "Guidance", "GuidanceOutput", "SkyEphemeris", "ZoneGeometry", "d_s_to_deg", "merge_zones",
    "signed_margin_deg",
]
