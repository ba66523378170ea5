"""The batched Kalman filter against FilterPy, trial by trial, step by step."""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from radarbench.models.kalman import (LinearGaussianFilter, LinearGaussianModel, covariance_sequence, innovations,
                           kalman_filter, reference_innovations, steady_state, whiten)


def random_model(rng, d=4, m=2):
    """A random stable-ish model with full-rank Q and R."""
    F = np.eye(d) + 0.3 * rng.standard_normal((d, d))
    H = rng.standard_normal((m, d))
    A = rng.standard_normal((d, d))
    B = rng.standard_normal((m, m))
    return LinearGaussianModel(F=F, H=H, Q=0.1 * A @ A.T + 0.01 * np.eye(d),
                               R=B @ B.T + 0.1 * np.eye(m))


@pytest.fixture
def setup():
    rng = np.random.default_rng(12)
    model = random_model(rng)
    n, K = 5, 25
    z = rng.standard_normal((n, K, 2)) * 3.0
    x0 = rng.standard_normal((n, 4))
    A = rng.standard_normal((4, 4))
    P0 = 10.0 * A @ A.T + np.eye(4)          # far from steady state
    return model, z, x0, P0


def test_matches_filterpy_trial_by_trial(setup):
    model, z, x0, P0 = setup
    res = kalman_filter(model, z, x0, P0)
    n, K, _ = z.shape
    for i in range(n):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.H, kf.Q, kf.R = model.F, model.H, model.Q, model.R
        kf.x, kf.P = x0[i].reshape(4, 1).copy(), P0.copy()
        for k in range(K):
            np.testing.assert_allclose(res.x_prior[i, k], kf.x[:, 0], rtol=1e-9, atol=1e-12)
            kf.update(z[i, k])
            np.testing.assert_allclose(res.nu[i, k], kf.y[:, 0], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(res.S[k], kf.S, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(res.x_post[i, k], kf.x[:, 0], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(res.P_post[k], kf.P, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(res.gain[k], kf.K, rtol=1e-9, atol=1e-12)
            kf.predict()


def test_steady_state_is_limit_of_recursion(setup):
    model, _, _, P0 = setup
    P_prior, P_post, S, K = covariance_sequence(model, P0, 400)
    P_inf, P_post_inf, S_inf, K_inf = steady_state(model)
    np.testing.assert_allclose(P_prior[-1], P_inf, rtol=1e-8)
    np.testing.assert_allclose(P_post[-1], P_post_inf, rtol=1e-8)
    np.testing.assert_allclose(S[-1], S_inf, rtol=1e-8)
    np.testing.assert_allclose(K[-1], K_inf, rtol=1e-8, atol=1e-12)


def test_covariance_sequence_memo_is_exact_and_private(setup, monkeypatch):
    """The memoised sequence is bit for bit the recursion's; each call gets its own arrays (a caller
    writing one changes nothing for the next); another P0 or step count is another entry."""
    import radarbench.models.kalman as kalman

    model, _, _, P0 = setup
    monkeypatch.setattr(kalman, "_covariance_memo", type(kalman._covariance_memo)())
    fresh = kalman._covariance_sequence(model, P0, 30)
    first = covariance_sequence(model, P0, 30)
    for a in first:
        a[...] = np.nan
    for again, exact in zip(covariance_sequence(model, P0, 30), fresh):
        assert again.tobytes() == exact.tobytes()
    assert covariance_sequence(model, P0, 31)[0].shape[0] == 31
    assert covariance_sequence(model, 2 * P0, 30)[0][0].tobytes() == (2 * P0).tobytes()
    assert len(kalman._covariance_memo) == 3


def test_steady_start_gives_constant_gain(setup):
    model, z, x0, _ = setup
    P_inf = steady_state(model)[0]
    res = kalman_filter(model, z, x0, P_inf)
    np.testing.assert_allclose(res.P_prior, np.broadcast_to(P_inf, res.P_prior.shape), rtol=1e-8)


def test_whitening(setup):
    model, z, x0, P0 = setup
    res = kalman_filter(model, z, x0, P0)
    whitened, nis = whiten(res.nu, res.S)
    expected = np.einsum("nki,kij,nkj->nk", res.nu, np.linalg.inv(res.S), res.nu)
    np.testing.assert_allclose(nis, expected, rtol=1e-10)
    L = np.linalg.cholesky(res.S)
    np.testing.assert_allclose(np.einsum("kij,nkj->nki", L, whitened), res.nu, rtol=1e-10, atol=1e-12)


def test_innovations_of_a_filter_and_the_filterpy_reference(setup):
    model, z, x0, P0 = setup
    n, K, _ = z.shape
    filt = LinearGaussianFilter(model=model, x0=x0, P0=P0)
    inn = innovations(filt, z)
    np.testing.assert_array_equal(inn.nu, kalman_filter(model, z, x0, P0).nu)
    assert inn.whitened.shape == (n, K, 2) and inn.nis.shape == (n, K) and inn.S.shape == (K, 2, 2)
    ref = reference_innovations(filt, z)                 # the per-trial filterpy loop, called explicitly
    np.testing.assert_allclose(ref.nu, inn.nu, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(ref.nis, inn.nis, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("field, change", [("x0", lambda x0, P0: (x0[:, :3], P0)),
                                           ("P0", lambda x0, P0: (x0, P0[:3, :3]))])
def test_a_misshapen_filter_names_the_field(setup, field, change):
    model, _, x0, P0 = setup
    x0, P0 = change(x0, P0)
    with pytest.raises(ValueError, match=f"LinearGaussianFilter.{field}: expected"):
        LinearGaussianFilter(model=model, x0=x0, P0=P0)
    with pytest.raises(ValueError, match="LinearGaussianModel.R: expected an array of shape"):
        LinearGaussianModel(F=model.F, H=model.H, Q=model.Q, R=np.eye(3))


def _state_recursion_in_numpy(model, z, x0, gain):
    """The per-step NumPy loop the compiled state recursion replaced, kept as
    its bit-for-bit oracle: products by :func:`bench.batched.matvec`, in index order."""
    from radarbench.bench.batched import matvec
    n, steps, _ = z.shape
    x_prior, x_post, nu = np.empty((n, steps, model.dim_x)), np.empty((n, steps, model.dim_x)), np.empty_like(z)
    x = np.broadcast_to(x0, (n, model.dim_x)).copy()
    for k in range(steps):
        x_prior[:, k] = x
        nu[:, k] = z[:, k] - matvec(model.H, x)
        x_post[:, k] = x + matvec(gain[k], nu[:, k])
        x = matvec(model.F, x_post[:, k])
    return x_prior, x_post, nu


@pytest.mark.parametrize("d, m, n", [(1, 1, 1), (2, 1, 7), (4, 2, 33), (6, 3, 200), (9, 3, 5)])
def test_the_compiled_state_recursion_is_the_numpy_loop_bit_for_bit(d, m, n):
    """Every trial's numbers, not merely close: the committed results were made by the
    NumPy loop, and a compiled loop that fused a multiply-add or reordered a sum would
    move their last bits (docs/architecture.md, 'Portable numbers')."""
    rng = np.random.default_rng(100 * d + m)
    model = random_model(rng, d, m)
    z = rng.standard_normal((n, 40, m)) * 1e3
    x0 = rng.standard_normal((n, d))
    P0 = np.eye(d) * 50.0
    res = kalman_filter(model, z, x0, P0)
    expected = _state_recursion_in_numpy(model, z, x0, res.gain)
    for got, want in zip((res.x_prior, res.x_post, res.nu), expected):
        np.testing.assert_array_equal(got, want)
    shared = kalman_filter(model, z, x0[0], P0)             # one (d,) prior for all trials
    np.testing.assert_array_equal(shared.nu, _state_recursion_in_numpy(model, z, x0[0], res.gain)[2])
