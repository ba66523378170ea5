"""imm-cv-ct: the IMM with a coordinated-turn mode, its CT model (models.turn) and the
maneuvering-1d scenario's planar turn."""

import numpy as np
import pytest

from radarbench.bench.params import build_params
from radarbench.bench.sweep.rng import TrialRNG
from radarbench.methods.kinematic.imm import IMMCVCA
from radarbench.methods.kinematic.imm_ct import IMMCVCT
from radarbench.models.turn import ct_jacobian, ct_transition
from radarbench.scenarios.cv_turn_cv import ct_transition as scenario_ct_transition
from radarbench.scenarios.maneuvering import Maneuvering


def _turn_batch(n, seed=21, **values):
    params = build_params(Maneuvering.Params, {"dims": 2, "profile": "turn", **values})
    return Maneuvering().generate(params, 0.0, n, TrialRNG(seed, 0, 0, range(n)))


def _position_rmse(out, batch):
    return np.sqrt(((out.estimate - batch.truth)[..., [0, 3]] ** 2).sum(-1).mean(axis=1))


@pytest.mark.parametrize("omega", [0.3, -0.05, 1e-3])
def test_ct_transition_is_the_exact_turn(omega):
    np.testing.assert_allclose(ct_transition(omega, 2.0), scenario_ct_transition(omega, 2.0), rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("omega", [0.2, -0.07, 1e-6, 0.0])
def test_ct_jacobian_is_the_derivative(omega):
    """The Jacobian's turn-rate column against central differences (the series below
    |Omega T| = 1e-4 included); Omega = 0 is the CV transition."""
    x = np.array([100.0, 150.0, -40.0, 80.0, omega])
    f, J = ct_jacobian(x, 1.5)
    h = 1e-6
    for j in range(5):
        e = np.zeros(5)
        e[j] = h
        numeric = (ct_jacobian(x + e, 1.5)[0] - ct_jacobian(x - e, 1.5)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, j], numeric, rtol=1e-6, atol=1e-6)
    if omega == 0.0:
        np.testing.assert_allclose(f[:4], [100 + 1.5 * 150, 150, -40 + 1.5 * 80, 80])


def test_turn_profile_holds_speed_and_turns_by_rate_times_duration():
    b = _turn_batch(3, turn_rate_deg_s=3.0)
    v = b.truth[..., [1, 4]]
    speed = np.linalg.norm(v, axis=-1)
    np.testing.assert_allclose(speed, speed[:, :1] * np.ones_like(speed), rtol=1e-12)
    heading = np.unwrap(np.arctan2(v[..., 1], v[..., 0]), axis=1)
    np.testing.assert_allclose(heading[:, 60] - heading[:, 40], np.deg2rad(3.0) * 20, rtol=1e-12)
    assert b.scene.maneuver_onset_steps.tolist() == [[40]] * 3
    # the acceleration of a turning step is centripetal: perpendicular to the velocity
    a = b.truth[:, 45][..., [2, 5]]
    np.testing.assert_allclose((a * v[:, 45]).sum(-1), 0.0, atol=1e-9)


def test_is_step_by_step_filterpy_imm_estimator():
    """The compiled IMM with a CT mode against FilterPy's IMMEstimator whose CT filter predicts
    by the same EKF step."""
    b = _turn_batch(3)
    params = build_params(IMMCVCT.Params, {})
    ours, ref = IMMCVCT().run(b, params), IMMCVCT().reference_run(b, params)
    np.testing.assert_allclose(ours.estimate, ref.estimate, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(ours.covariance, ref.covariance, rtol=1e-8, atol=1e-6)
    np.testing.assert_allclose(ours.traces["mode"], ref.traces["mode"], atol=1e-9)


def test_beats_imm_cv_ca_on_a_constant_turn():
    """60 trials of a 3 deg/s turn at a fixed seed: the paired per-trial position RMSE
    difference imm-cv-ct - imm-cv-ca lies below 0 by more than 3 standard errors of its
    mean; the CT mode's probability rises inside the turn."""
    b = _turn_batch(60)
    ct = IMMCVCT().run(b, build_params(IMMCVCT.Params, {}))
    ca = IMMCVCA().run(b, build_params(IMMCVCA.Params, {}))
    diff = _position_rmse(ct, b) - _position_rmse(ca, b)
    assert diff.mean() + 3.0 * diff.std(ddof=1) / np.sqrt(len(diff)) < 0.0
    mode = ct.traces["mode"].mean(axis=0)
    assert mode[45:60].mean() > 2 * mode[10:40].mean()


def test_refuses_a_one_axis_scene():
    params = build_params(IMMCVCT.Params, {})
    one_axis = build_params(Maneuvering.Params, {})
    assert "dims = 2" in IMMCVCT().check_scenario(params, one_axis)
    assert IMMCVCT().check_scenario(params, build_params(Maneuvering.Params, {"dims": 2})) is None


def test_turn_profile_needs_two_axes():
    from radarbench.bench.errors import ConfigError
    with pytest.raises(ConfigError, match="dims"):
        build_params(Maneuvering.Params, {"profile": "turn"})
