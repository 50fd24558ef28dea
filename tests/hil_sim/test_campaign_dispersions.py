"""Dispersion sampling against the distributions' known laws, key paths, and read-back."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats
from scipy.spatial.transform import Rotation

from hil_sim.campaign import dispersions as dsp
from hil_sim.campaign.execute import execute_run
from hil_sim.campaign.spec import Campaign

from campaign_kit import ToyMission, toy_plan, toy_run_clamping, write_toy

N = 4000


def _disp(**kw):
    spec = Campaign.model_validate({"schema_version": 1, "name": "t", "base_mission": "x.yaml", "runs": 1,
                                    "master_seed": 0, "dispersions": [kw],
                                    "criteria": [{"name": "c", "metric": "m", "op": ">", "limit": 0}]})
    return spec.dispersions[0]


def _sample(d, nominal, n=N, seed=1):
    rng = np.random.default_rng(seed)
    return [dsp.realize(d, dsp.draw(d, rng, nominal), nominal) for _ in range(n)]


def test_uniform_so3_rotation_angle_follows_haar_law():
    # Haar measure on SO(3): the rotation angle has CDF (theta - sin theta) / pi (independent of the nominal).
    nominal = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_quat(scalar_first=True).tolist()
    qs = np.array(_sample(_disp(name="a", path="q", kind="attitude"), nominal))
    assert np.allclose(np.linalg.norm(qs, axis=1), 1.0)
    angles = Rotation.from_quat(qs, scalar_first=True).magnitude()
    assert stats.kstest(angles, lambda t: (t - np.sin(t)) / np.pi).pvalue > 1e-3
    # and the absolute attitude is uniform too: its angle from identity follows the same law
    ident = Rotation.from_quat(qs, scalar_first=True).magnitude()
    assert stats.kstest(ident, lambda t: (t - np.sin(t)) / np.pi).pvalue > 1e-3


def test_bounded_attitude_stays_within_angle_of_nominal():
    nominal = [math.cos(0.3), math.sin(0.3), 0.0, 0.0]
    qs = np.array(_sample(_disp(name="a", path="q", kind="attitude", max_angle_deg=5.0), nominal, n=500))
    rel = Rotation.from_quat(nominal, scalar_first=True).inv() * Rotation.from_quat(qs, scalar_first=True)
    angles = np.degrees(rel.magnitude())
    assert angles.max() <= 5.0 + 1e-9
    assert stats.kstest(angles, "uniform", args=(0.0, 5.0)).pvalue > 1e-3


def test_uniform_direction_z_is_uniform_archimedes():
    d = _disp(name="d", path="v", kind="direction")
    v = np.array(_sample(d, [0.0, 0.0, 1.0]))
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0)
    for axis in range(3):  # Archimedes: each coordinate of a uniform point on S^2 is uniform on [-1, 1]
        assert stats.kstest(v[:, axis], "uniform", args=(-1.0, 2.0)).pvalue > 1e-3


def test_direction_in_cap_has_uniform_cosine():
    nominal = np.array([1.0, 2.0, 2.0]) / 3.0
    d = _disp(name="d", path="v", kind="direction", cone_half_angle_deg=20.0)
    v = np.array(_sample(d, nominal.tolist()))
    cosines = v @ nominal
    c0 = math.cos(math.radians(20.0))
    assert cosines.min() >= c0 - 1e-12
    assert stats.kstest(cosines, "uniform", args=(c0, 1.0 - c0)).pvalue > 1e-3


def test_clipped_normal_puts_the_tails_on_the_bounds():
    d = _disp(name="s", path="x", kind="scalar",
              distribution={"dist": "clipped_normal", "mean": 1.0, "sigma": 0.1, "low": 0.9, "high": 1.15})
    x = np.array(_sample(d, 0.0, n=20000))
    assert x.min() == pytest.approx(0.9) and x.max() == pytest.approx(1.15)
    assert np.mean(x == 0.9) == pytest.approx(stats.norm.cdf(-1.0), abs=0.01)
    assert np.mean(x == 1.15) == pytest.approx(stats.norm.sf(1.5), abs=0.01)


def test_scalar_apply_modes_and_vector_components():
    mult = _disp(name="s", path="x", kind="scalar", distribution={"dist": "uniform", "low": 0.5, "high": 2.0},
                 apply="multiply")
    x = np.array(_sample(mult, 10.0, n=2000))
    assert 5.0 <= x.min() and x.max() <= 20.0
    assert stats.kstest(x, "uniform", args=(5.0, 15.0)).pvalue > 1e-3
    vec = _disp(name="v", path="x", kind="vector",
                distribution=[{"dist": "normal", "sigma": 1.0}, {"dist": "normal", "sigma": 2.0},
                              {"dist": "normal", "mean": 3.0, "sigma": 0.5}])
    v = np.array(_sample(vec, [10.0, 0.0, 0.0], n=4000))
    assert v.mean(axis=0) == pytest.approx([10.0, 0.0, 3.0], abs=0.1)
    assert v.std(axis=0) == pytest.approx([1.0, 2.0, 0.5], rel=0.06)


def test_inertia_dispersion_scales_eigenvalues_and_rotates_axes():
    J = np.diag([20.0, 25.0, 15.0]).tolist()
    d = _disp(name="j", path="J", kind="inertia", scale={"dist": "uniform", "low": 0.9, "high": 1.1},
              misalignment_sigma_deg=2.0)
    rng = np.random.default_rng(3)
    for _ in range(50):
        params = dsp.draw(d, rng, J)
        Jn = np.asarray(dsp.realize(d, params, J))
        assert np.allclose(Jn, Jn.T)
        # a similarity transform keeps the spectrum: eigenvalues are exactly the scaled nominal ones
        assert np.sort(np.linalg.eigvalsh(Jn)) == pytest.approx(np.sort([15.0, 20.0, 25.0]) * params["scale"])
        # the principal axis of the largest moment moved by at most the misalignment angle
        w, vecs = np.linalg.eigh(Jn)
        angle = math.degrees(math.acos(min(1.0, abs(vecs[:, -1][1]))))
        assert angle <= math.degrees(np.linalg.norm([params["rx"], params["ry"], params["rz"]])) + 1e-6


def test_epoch_within_window_and_choice_frequencies():
    d = _disp(name="e", path="t", kind="epoch", start_utc="2026-01-01T00:00:00Z", end_utc="2026-07-01T00:00:00Z")
    values = _sample(d, "2026-03-20T12:00:00Z", n=500)
    assert all("2026-01-01T00:00:00Z" <= v <= "2026-07-01T00:00:00Z" for v in values)
    c = _disp(name="c", path="m", kind="choice", values=["A", "B", "C"], probabilities=[0.5, 0.3, 0.2])
    picks = _sample(c, "A", n=5000)
    counts = [picks.count(k) for k in "ABC"]
    assert stats.chisquare(counts, [2500, 1500, 1000]).pvalue > 1e-3


def test_wheel_failure_respects_cap_and_appends_faults():
    d = _disp(name="w", path="faults", kind="wheel_failure", n_wheels=4, probability=0.5, max_failed=1,
              start_s={"dist": "uniform", "low": 10, "high": 20})
    faults = _sample(d, [], n=400)
    assert all(len(f) <= 1 for f in faults)
    hit = [f for f in faults if f]
    assert len(hit) == pytest.approx(400 * (1 - 0.5 ** 4), abs=40)
    assert {f[0]["message"] for f in hit} == {"RW1_CMD", "RW2_CMD", "RW3_CMD", "RW4_CMD"}
    assert all(10 <= f[0]["start_s"] <= 20 for f in hit)


def test_wheel_failure_draws_each_wheels_kind_and_onset_when_asked():
    kinds = ["drop", "silent", "wheel_stuck", "wheel_no_torque"]
    d = _disp(name="w", path="faults", kind="wheel_failure", n_wheels=4, probability=1.0, max_failed=2,
              fault_kinds=kinds, independent_starts=True, start_s={"dist": "uniform", "low": 10, "high": 500})
    base = [{"kind": "drop", "message": "IMU_RATE", "start_s": 1.0, "end_s": 2.0}]
    faults = _sample(d, base, n=400)
    assert all(f[0] == base[0] and len(f) == 3 for f in faults)  # composed with the base mission's own
    added = [g for f in faults for g in f[1:]]
    assert {g["kind"] for g in added} == set(kinds)
    for g in added:  # a lost status silences the wheel's node; every other kind names its command frame
        assert g["message"].endswith("_STATUS" if g["kind"] == "silent" else "_CMD")
    assert all(f[1]["message"][:3] != f[2]["message"][:3] for f in faults)  # two different wheels
    gaps = [abs(f[1]["start_s"] - f[2]["start_s"]) for f in faults]
    assert min(gaps) < 5.0 and max(gaps) > 300.0  # onsets drawn apart, not one shared time
    # the nominal run has no failure, whatever was drawn
    drawn = dsp.draw(d, np.random.default_rng(3), base)
    assert dsp.realize(d, dsp.nominal_params(d, base, drawn), base) == base


def test_a_criterion_with_only_if_judges_only_the_runs_it_names():
    spec = Campaign.model_validate({"schema_version": 1, "name": "t", "base_mission": "x.yaml", "runs": 1,
                                    "master_seed": 0, "dispersions": [],
                                    "criteria": [{"name": "keep_out", "metric": "min_margin_deg", "op": ">",
                                                  "limit": 0, "only_if": {"metric": "wheels_lost", "op": "<=",
                                                                          "limit": 1}}]})
    c = spec.criteria[0]
    assert c.judged({"min_margin_deg": 2.0, "wheels_lost": 1.0})
    assert not c.judged({"min_margin_deg": -2.0, "wheels_lost": 1.0})
    assert c.judged({"min_margin_deg": -2.0, "wheels_lost": 2.0})  # not this criterion's run
    assert not c.judged({"min_margin_deg": -2.0})  # no condition metric: the run is judged
    assert "where wheels_lost <= 1" in c.text()


def test_realize_of_nominal_params_is_the_nominal():
    q = Rotation.from_euler("z", 40, degrees=True).as_quat(scalar_first=True).tolist()
    for d, nominal in ((_disp(name="a", path="q", kind="attitude"), q),
                       (_disp(name="d", path="v", kind="direction"), [0.0, 0.6, 0.8]),
                       (_disp(name="j", path="J", kind="inertia", misalignment_sigma_deg=3.0),
                        [[3.0, 0.1, 0.0], [0.1, 4.0, 0.0], [0.0, 0.0, 5.0]])):
        drawn = dsp.draw(d, np.random.default_rng(0), nominal)
        assert np.allclose(dsp.realize(d, dsp.nominal_params(d, nominal, drawn), nominal), nominal)


def test_key_paths_parse_and_report_missing_keys():
    assert dsp.parse_path("timeline[1].target_N") == ("timeline", 1, "target_N")
    assert dsp.parse_path("spacecraft.wheels.0.axis_B") == ("spacecraft", "wheels", 0, "axis_B")
    with pytest.raises(dsp.DispersionError):
        dsp.parse_path("a..b")
    m = ToyMission.model_validate({"schema_version": 1, "name": "x"})
    assert dsp.read_path(m, ("law", "k1")) == 0.2
    with pytest.raises(dsp.DispersionError, match="no key 'kapa'.*kappa"):
        dsp.read_path(m, ("law", "kapa"))


def test_unknown_dispersion_path_is_reported_at_load(tmp_path):
    from campaign_kit import TOY_CAMPAIGN_YAML
    text = TOY_CAMPAIGN_YAML.format(runs=2, settle_limit=100).replace("path: law.k1", "path: law.k_one")
    path = write_toy(tmp_path, campaign_text=text)
    with pytest.raises(dsp.DispersionError, match="dispersion 'gain'.*no key 'k_one'.*keys there: eps, k1, kappa"):
        toy_plan(path)


def test_a_dispersion_that_does_not_land_is_an_error(tmp_path):
    # The faulty set-up clamps k1 at 0.25 while the campaign draws k1 = 0.2 * U(0.8, 1.2) up to 0.24 -> make
    # the draws exceed the clamp so the read-back differs from the drawn value.
    from campaign_kit import TOY_CAMPAIGN_YAML
    text = TOY_CAMPAIGN_YAML.format(runs=3, settle_limit=100).replace("{dist: uniform, low: 0.8, high: 1.2}",
                                                                      "{dist: uniform, low: 1.5, high: 2.0}")
    plan, _ = toy_plan(write_toy(tmp_path, campaign_text=text), run_function=toy_run_clamping)
    record = execute_run(plan, 0)
    assert record.status == "error"
    assert "did not land" in record.error and "law.k1" in record.error
    assert record.used["law.k1"] == 0.25 and record.values["law.k1"] > 0.29


def test_dispersion_draws_do_not_depend_on_the_other_dispersions(tmp_path):
    from campaign_kit import TOY_CAMPAIGN_YAML
    plan_all, _ = toy_plan(write_toy(tmp_path, runs=5))
    text = TOY_CAMPAIGN_YAML.format(runs=5, settle_limit=100)
    start = text.index("  - name: inertia")
    end = text.index("  - name: gain")
    plan_less, _ = toy_plan(write_toy(tmp_path, campaign_text=text[:start] + text[end:]))
    for i in range(5):
        a, b = plan_all.draw(i), plan_less.draw(i)
        assert "inertia" in a and "inertia" not in b
        assert all(a[k] == b[k] for k in b)
