"""Scenario glint: discretisation, control and prior, draws (chunking, common random numbers), scene."""

import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg

from radarbench.bench.core import SceneError
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import build_params
from radarbench.bench.registry import get_scenario
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.bench.tasks.tracking import TrackingScene
from radarbench.models.glint import GlintModel
from radarbench.models.spherical import los_basis, measure, measurement_residual, spherical
from radarbench.scenarios.glint import (POSITION_INDEX, STATE_LABELS, Glint, discretisation, spherical_components,
                             transition_matrices)


def make(snr_db=0.0, n=6, seed=1, trials=None, **values):
    params = build_params(Glint.Params, values)
    trials = range(n) if trials is None else trials
    return Glint().generate(params, snr_db, len(trials), TrialRNG(seed, 0, 0, trials))


def noise(batch):
    """z - h(truth), bearing wrapped: the realised measurement noise (n, K, m)."""
    return measurement_residual(batch.z, measure(batch.truth[..., :3], batch.scene.model.sensor))


def test_registered_and_summary():
    assert get_scenario("glint") is Glint
    assert Glint.tasks == ("tracking",)
    assert Glint.summary().startswith("Damped target with known control")


@pytest.mark.parametrize("sensor, m", [("passive", 2), ("active", 3)])
def test_shapes_and_scene(sensor, m):
    b = make(n=5, sensor=sensor, steps=40)
    assert b.t.shape == (40,) and b.truth.shape == (5, 40, 6) and b.z.shape == (5, 40, m)
    np.testing.assert_allclose(b.t, 0.1 * np.arange(40))
    sc = b.scene
    assert type(sc) is TrackingScene
    assert sc.position_index == POSITION_INDEX == (0, 1, 2)
    assert sc.state_labels == STATE_LABELS
    assert len(sc.measurement_labels) == m and sc.measurement_labels[-2:] == ("bearing", "elevation")
    assert sc.measurements_xy.shape == (5, 40, 2)
    assert sc.outlier_flags.shape == (5, 40, m) and sc.outlier_flags.dtype == bool
    assert sc.realised_snr_db.shape == (5,)
    assert sc.divergence_bound_m == 500.0 and sc.derived_components is spherical_components
    assert isinstance(sc.snr_definition, str) and "10^(-snr_db/20)" in sc.snr_definition
    model = sc.model
    assert isinstance(model, GlintModel) and model.measurement_labels == sc.measurement_labels
    assert model.sigma.shape == model.eta.shape == model.noise_variance.shape == (m,)
    assert model.dt_s == 0.1 and model.x0.shape == (6,) and model.P0.shape == (6, 6)
    np.testing.assert_allclose(model.Bu, model.G @ model.u)
    np.testing.assert_allclose(model.Q, model.process_noise_m_s2 ** 2 * model.G @ model.G.T)
    np.testing.assert_array_equal(b.trials, np.arange(5))
    assert np.all(np.isfinite(b.z)) and np.all(np.isfinite(b.truth))


def _scene_fields(b) -> dict:
    return {f.name: getattr(b.scene, f.name) for f in dataclasses.fields(b.scene)}


def test_a_misspelt_or_misshapen_scene_field_fails_naming_it():
    """The scene and its model are built in generate(): a misspelt keyword, a
    missing field or a wrong shape fails there, naming the field."""
    b = make(n=3, steps=20, sensor="active")
    fields = _scene_fields(b)
    TrackingScene(**fields)                                             # as generated: fine
    with pytest.raises(TypeError, match="glint_outlier"):
        TrackingScene(**{**fields, "glint_outlier": fields["outlier_flags"]})
    for field, bad in (("outlier_flags", fields["outlier_flags"].astype(int)), ("divergence_bound_m", -1.0),
                       ("state_labels", ["x", "y"]), ("derived_components", "range")):
        with pytest.raises(SceneError, match=f"TrackingScene.{field}: expected") as err:
            TrackingScene(**{**fields, field: bad})
        assert err.value.field == field
    for field, bad in (("state_labels", STATE_LABELS[:4]), ("outlier_flags", fields["outlier_flags"][..., :2])):
        with pytest.raises(SceneError, match=f"TrackingScene.{field}"):
            dataclasses.replace(b, scene=TrackingScene(**{**fields, field: bad}))
    model = {f.name: getattr(b.scene.model, f.name) for f in dataclasses.fields(GlintModel)}
    with pytest.raises(TypeError, match="sigmas"):
        GlintModel(**{**model, "sigmas": model["sigma"]})
    missing = {k: v for k, v in model.items() if k != "los_rotation"}
    with pytest.raises(TypeError, match="los_rotation"):
        GlintModel(**missing)
    with pytest.raises(ValueError, match=r"GlintModel.sigma: expected an array of shape \(3,\)"):
        GlintModel(**{**model, "sigma": model["sigma"][:2]})
    with pytest.raises(ValueError, match="GlintModel.measurement_labels"):
        GlintModel(**{**model, "measurement_labels": ("bearing", "elevation")})


def test_discretisation_matches_matrix_exponential():
    """Zero-order hold of d/dt [p, v] = [[0, 1], [0, -mu]] [p, v] + [0, 1] (u + w):
    expm([[A, B], [0, 0]] T) = [[F, G], [0, I]]; per axis F = [[1, P1], [0, a]], G = [P2, P1]."""
    for mu, T in ((0.4, 0.1), (2.0, 0.5), (1e-9, 0.1), (0.0, 0.3)):
        M = np.zeros((3, 3))
        M[0, 1], M[1, 1], M[1, 2] = 1.0, -mu, 1.0
        E = scipy.linalg.expm(M * T)
        a, P1, P2 = discretisation(mu, T)
        np.testing.assert_allclose([[1.0, P1], [0.0, a]], E[:2, :2], rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose([P2, P1], E[:2, 2], rtol=1e-7, atol=1e-15)
        F, G = transition_matrices(mu, T)
        np.testing.assert_allclose(F, np.kron(E[:2, :2], np.eye(3)), rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(G, np.kron(E[:2, 2:], np.eye(3)), rtol=1e-7, atol=1e-15)
    a, P1, P2 = discretisation(0.4, 0.1)
    assert P1 == pytest.approx((1 - math.exp(-0.04)) / 0.4) and P2 == pytest.approx((0.04 - 1 + math.exp(-0.04)) / 0.16)


def test_truth_follows_the_dynamics():
    """x_{k+1} - F x_k - G u = G sigma_w w_k: its position part is P2/P1 times its velocity part."""
    b = make(n=3, steps=50, process_noise_m_s2=2.0)
    m = b.scene.model
    resid = b.truth[:, 1:] - b.truth[:, :-1] @ m.F.T - m.Bu
    _, P1, P2 = discretisation(0.4, 0.1)
    np.testing.assert_allclose(resid[..., :3], P2 / P1 * resid[..., 3:], atol=1e-9)
    # velocity increments sigma_w P1 w_k: the sample std of N = 441 of them is within 4 standard
    # errors (1/sqrt(2N) relative) of 2 P1
    ratio = np.std(resid[..., 3:]) / (2.0 * P1)
    assert abs(ratio - 1.0) < 4.0 / np.sqrt(2 * resid[..., 3:].size)
    quiet = make(n=3, steps=50, process_noise_m_s2=0.0)
    m = quiet.scene.model
    np.testing.assert_allclose(quiet.truth[:, 1:], quiet.truth[:, :-1] @ m.F.T + m.Bu, atol=1e-9)


def test_control_mapping_and_prior():
    p = build_params(Glint.Params, {"initial_bearing_deg": 30.0, "initial_elevation_deg": 10.0})
    m = Glint.model(p)
    R = m.los_rotation
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(R @ m.u, p.control_m_s2, atol=1e-12)
    r, b, e = spherical(m.x0[:3])
    assert r == pytest.approx(5000.0) and b == pytest.approx(math.radians(30)) and e == pytest.approx(math.radians(10))
    np.testing.assert_allclose(R[0], m.x0[:3] / 5000.0, atol=1e-12)
    P_los = R @ m.P0[:3, :3] @ R.T
    np.testing.assert_allclose(np.diag(P_los), [100.0 ** 2, 20.0 ** 2, 20.0 ** 2], rtol=1e-9)
    # bearing increases clockwise from north: the bearing direction at bearing 0 is east (+x)
    np.testing.assert_allclose(los_basis(0.0, 0.0), [[0, 1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)


def test_trial_streams_do_not_depend_on_chunking():
    whole = make(n=6, steps=30, sensor="active")
    part = make(trials=range(3, 6), steps=30, sensor="active")
    np.testing.assert_array_equal(whole.z[3:], part.z)
    np.testing.assert_array_equal(whole.truth[3:], part.truth)
    np.testing.assert_array_equal(whole.scene.outlier_flags[3:], part.scene.outlier_flags)


def test_common_random_numbers_across_snr_epsilon_and_sensor():
    """Same trial: same truth, same outliers at every SNR; the noise scales by
    10^(-snr/20); raising eps only adds outliers; passive = active's angles."""
    a = make(0.0, steps=80, sensor="active", epsilon=0.2)
    b = make(20.0, steps=80, sensor="active", epsilon=0.2)
    np.testing.assert_array_equal(a.truth, b.truth)
    np.testing.assert_array_equal(a.scene.outlier_flags, b.scene.outlier_flags)
    np.testing.assert_allclose(noise(b), 0.1 * noise(a), rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(b.scene.model.sigma, 0.1 * a.scene.model.sigma)
    np.testing.assert_array_equal(b.scene.realised_snr_db, np.full(6, 20.0))
    low = make(0.0, steps=80, sensor="active", epsilon=0.05)
    assert np.all(a.scene.outlier_flags >= low.scene.outlier_flags)
    assert a.scene.outlier_flags.sum() > low.scene.outlier_flags.sum()
    passive = make(0.0, steps=80, sensor="passive", epsilon=0.2)
    np.testing.assert_array_equal(passive.z, a.z[..., 1:])
    none = make(None, steps=80, sensor="active", epsilon=0.2)
    np.testing.assert_array_equal(none.z, a.z)


def test_epsilon_zero_is_gaussian_and_outliers_use_the_glint_part():
    g = make(steps=200, sensor="active", epsilon=0.0)
    assert not g.scene.outlier_flags.any()
    one = make(steps=200, sensor="active", epsilon=1.0)
    assert one.scene.outlier_flags.all()
    # with eps = 0 the additive model (core + spikes) is the same Gaussian noise, same draws
    add = make(steps=200, sensor="active", epsilon=0.0, glint_model="additive")
    np.testing.assert_allclose(noise(add), noise(g), atol=1e-9)


def test_z_xy_is_the_horizontal_projection():
    b = make(steps=20, sensor="active")
    r, br, el = b.z[..., 0], b.z[..., 1], b.z[..., 2]
    np.testing.assert_allclose(b.scene.measurements_xy,
                               np.stack([r * np.cos(el) * np.sin(br), r * np.cos(el) * np.cos(br)], -1))
    p = make(steps=20, sensor="passive")
    rng_true = np.linalg.norm(p.truth[..., :3], axis=-1)
    np.testing.assert_allclose(np.hypot(*np.moveaxis(p.scene.measurements_xy, -1, 0)), rng_true * np.cos(p.z[..., 1]))


def test_bearing_wraps_near_south():
    b = make(steps=60, initial_bearing_deg=180.0, initial_cross_range_std_m=50.0, sensor="active")
    bearing = b.z[..., 1]
    assert np.all((bearing > -np.pi) & (bearing <= np.pi))
    assert (bearing > 3.0).any() and (bearing < -3.0).any()          # both sides of the cut
    assert np.abs(noise(b)[..., 1]).max() < 0.5                      # residuals wrapped


@pytest.mark.parametrize("values, field", [
    ({"sensor": "radar"}, "sensor"), ({"epsilon": 1.5}, "epsilon"), ({"sigma_bearing_rad": 0.0}, "sigma_bearing_rad"),
    ({"initial_range_std_m": 2000.0}, "initial_range_std_m"), ({"control_m_s2": [1.0, 2.0]}, "control_m_s2"),
    ({"glint_model": "sum"}, "glint_model")])
def test_bad_params_name_the_field(values, field):
    with pytest.raises(ConfigError) as err:
        build_params(Glint.Params, values)
    assert err.value.field == field


def test_paper_parameters_as_printed():
    """The preset's paper config carries Song & Sun's printed section-3 values."""
    import importlib.resources
    import math
    import tomllib

    from radarbench.bench.params import build_params

    sweep = tomllib.loads((importlib.resources.files("radarbench.bench") / "presets" / "glint-tracking.toml").read_text())
    entry = next(s for s in sweep["scenarios"] if s.get("label") == "paper-passive")
    p = build_params(Glint.Params, entry["params"])
    m = Glint.model(p, 0.0)
    np.testing.assert_allclose(m.sigma ** 2, [4e-4, 4e-4])
    np.testing.assert_allclose(m.eta, [0.03, 0.03])
    assert m.epsilon == 0.05 and m.sensor == "passive"
    np.testing.assert_allclose(m.process_noise_los ** 2, [7.0, 0.07, 0.07])
    np.testing.assert_allclose(m.control_los, [1.5, 0.07, 0.06])
    assert p.dt_s == 0.1 and p.damping_per_s == 0.4
    # the prior mean is at 0.76 rad bearing and elevation, moving at 0.05 / 0.04 rad/s
    x0 = m.x0
    r, b, e = (float(v) for v in spherical(x0[:3]))
    assert math.isclose(b, 0.76, abs_tol=1e-12) and math.isclose(e, 0.76, abs_tol=1e-12)
    dt = 1e-6
    r2, b2, e2 = (float(v) for v in spherical(x0[:3] + dt * x0[3:]))
    np.testing.assert_allclose([(b2 - b) / dt, (e2 - e) / dt], [0.05, 0.04], rtol=1e-4)
    # the angular prior std is 0.1 rad (variance 0.01): cross-range std r0 cos(e0) 0.1 and r0 0.1
    Rl = m.los_rotation
    P_los = Rl @ m.P0[:3, :3] @ Rl.T
    np.testing.assert_allclose(np.sqrt(np.diag(P_los))[1:], [r * math.cos(e) * 0.1, r * 0.1], rtol=1e-9)
    # the disturbance is diagonal in the line-of-sight frame: Q = G Sw G'
    Sw = Rl.T @ np.diag([7.0, 0.07, 0.07]) @ Rl
    np.testing.assert_allclose(m.Q, m.G @ Sw @ m.G.T, rtol=1e-12, atol=1e-15)


def test_line_of_sight_process_noise_drives_the_truth():
    """The truth's disturbance has the configured stds along the line-of-sight directions."""
    params = {"steps": 400, "process_noise_los_m_s2": [3.0, 0.5, 0.0], "initial_bearing_deg": 30.0,
              "initial_elevation_deg": 20.0, "damping_per_s": 0.0}
    b = make(n=20, **params)
    m = b.scene.model
    drive = (b.truth[:, 1:, 3:] - b.truth[:, :-1, 3:] @ m.F[3:, 3:].T) / m.G[3, 0] - m.u
    los = drive @ m.los_rotation.T
    std = los.reshape(-1, 3).std(axis=0)
    # 7980 draws per direction: the std's relative sampling error is ~1/sqrt(2 N) = 0.8%
    np.testing.assert_allclose(std[:2], [3.0, 0.5], rtol=0.04)
    assert std[2] < 1e-9


def test_invalid_line_of_sight_noise_names_the_field():
    from radarbench.bench.errors import ConfigError
    from radarbench.bench.params import build_params

    with pytest.raises(ConfigError, match="process_noise_los_m_s2"):
        build_params(Glint.Params, {"process_noise_los_m_s2": [1.0, 2.0]})


def test_derived_spherical_components_are_scored_per_step():
    """The tracking task scores range, bearing and elevation (the paper's Fig. 4
    components) from the scenario's ``derived_components``, against the truth's."""
    from radarbench.bench.tasks.tracking.metrics import tracking_trial_metrics
    from radarbench.scenarios.glint import spherical_components
    rng = np.random.default_rng(0)
    truth = np.concatenate([rng.uniform(100, 1000, (4, 5, 3)), rng.normal(size=(4, 5, 3))], axis=-1)
    estimate = truth.copy()
    estimate[..., 0] += 1.0                      # 1 m east everywhere
    m = tracking_trial_metrics(estimate, truth, position_index=(0, 1, 2), labels=list("xyzuvw"),
                               covariance=None, divergence_bound_m=np.inf, derived=spherical_components)
    r_true = np.linalg.norm(truth[..., :3], axis=-1)
    np.testing.assert_allclose(m["true_range_m"], r_true)
    np.testing.assert_allclose(m["est_range_m"], np.linalg.norm(estimate[..., :3], axis=-1))
    np.testing.assert_allclose(m["true_bearing_rad"], np.arctan2(truth[..., 0], truth[..., 1]))
    assert np.all(m["sq_err_elevation_rad"] > 0) and m["sq_err_x"].max() == 1.0
