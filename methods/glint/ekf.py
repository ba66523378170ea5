"""Method ``ekf``: extended Kalman filter for the ``glint`` scenario's spherical measurements."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from radarbench.bench.batched import inner, matmul, matvec
from radarbench.bench.core import TRACKING, Batch, Method, TrackingOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.models.glint import GlintModel, glint_model_of
from radarbench.models.spherical import measure, measurement_jacobian, measurement_residual


@dataclass(frozen=True)
class EKFResult:
    """Output of :func:`ekf_filter` (``n`` trials, ``K`` steps, state size d, m measured).

    x_post : (n, K, d) updated state x_k|k;  P_post : (n, K, d, d) its covariance
    x_prior : (n, K, d) predicted state x_k|k-1 (step 0: the prior x0)
    nu : (n, K, m) innovation z_k - h(x_k|k-1), bearing wrapped to (-pi, pi]
    nis : (n, K) normalised innovation squared nu' S^-1 nu
    """

    x_post: np.ndarray
    P_post: np.ndarray
    x_prior: np.ndarray
    nu: np.ndarray
    nis: np.ndarray


def kalman_gain(P: np.ndarray, H: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched gain K = P H' S^-1 and innovation covariance S = H P H' + R:
    P (n, d, d), H (n, m, d), R (m, m) or (n, m, m)."""
    PHt = matmul(P, H.transpose(0, 2, 1))                        # (n, d, m)
    S = matmul(H, PHt) + R
    return np.linalg.solve(S, PHt.transpose(0, 2, 1)).transpose(0, 2, 1), S


#: ``reweigh(nu, H, P, R) -> R_k``: the measurement covariance an update uses given the
#: innovation (the EKF: R itself; an M-estimator: R over its residual weights)
Reweigh = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def ekf_filter(z: np.ndarray, model: GlintModel, R: np.ndarray, reweigh: Reweigh | None = None) -> EKFResult:
    """Batched EKF over ``n`` trials of ``K`` spherical measurements.

    Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking
    and Navigation* (2001), sec. 10.3, with FilterPy's conventions (its
    ``ExtendedKalmanFilter`` is the reference of the tests):

        H_k = dh/dx at x_k|k-1,  S = H P H' + R,  K = P H' S^-1
        x_k|k = x_k|k-1 + K (z_k - h(x_k|k-1))        (bearing residual wrapped)
        P_k|k = (I - K H) P (I - K H)' + K R K'       (Joseph form)
        x_k+1|k = F x_k|k + G u,  P_k+1|k = F P_k|k F' + Q

    The dynamics are linear (the ``glint`` model), only the measurement is
    linearised. ``model`` is the tracking scene's :class:`~models.glint.GlintModel`
    (F, Bu = G u, Q, x0, P0, sensor); ``x0``, ``P0`` are the prior of step 0 (step 0 updates with
    ``z[:, 0]`` first, as in :func:`models.kalman.kalman_filter`). Covariances
    depend on the data through the Jacobian, so they carry the trial axis;
    the loop runs over time only. ``reweigh`` (None: R as given) replaces R at
    each update by the (n, m, m) covariance it returns for the step's innovation
    (the Huber M-estimator of :mod:`methods.glint.huber`); gain, update and the
    Joseph form then use it, and ``nis`` stays the innovation's under R.
    """
    z = np.asarray(z, float)
    n, K, m = z.shape
    F, Bu, Q, sensor = model.F, model.Bu, model.Q, model.sensor
    d = F.shape[0]
    eye = np.eye(d)
    x = np.broadcast_to(np.asarray(model.x0, float), (n, d)).copy()
    P = np.broadcast_to(np.asarray(model.P0, float), (n, d, d)).copy()
    out = EKFResult(x_post=np.empty((n, K, d)), P_post=np.empty((n, K, d, d)),
                    x_prior=np.empty((n, K, d)), nu=np.empty((n, K, m)), nis=np.empty((n, K)))
    for k in range(K):
        out.x_prior[:, k] = x
        H = np.zeros((n, m, d))
        H[:, :, :3] = measurement_jacobian(x[:, :3], sensor)
        gain, S = kalman_gain(P, H, R)
        nu = measurement_residual(z[:, k], measure(x[:, :3], sensor))
        out.nu[:, k] = nu
        out.nis[:, k] = inner(nu, np.linalg.solve(S, nu[..., None])[..., 0])
        R_k = R
        if reweigh is not None:
            R_k = reweigh(nu, H, P, R)
            gain = kalman_gain(P, H, R_k)[0]
        x = x + matvec(gain, nu)
        I_KH = eye - matmul(gain, H)
        P = matmul(matmul(I_KH, P), I_KH.transpose(0, 2, 1)) + matmul(matmul(gain, R_k), gain.transpose(0, 2, 1))
        P = 0.5 * (P + P.transpose(0, 2, 1))
        out.x_post[:, k], out.P_post[:, k] = x, P
        x = matvec(F, x) + Bu
        P = matmul(matmul(F, P), F.T) + Q
    return out


def filterpy_ekf(z: np.ndarray, model: GlintModel, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference: FilterPy's ``ExtendedKalmanFilter`` on one trial, same
    conventions as :func:`ekf_filter` (update then predict with control
    B u); returns x_post (K, d) and P_post (K, d, d). The tests' oracle and
    ``bench perf``'s baseline."""
    from filterpy.kalman import ExtendedKalmanFilter

    sensor, d, m = model.sensor, model.F.shape[0], z.shape[-1]

    def jacobian(x):
        H = np.zeros((m, d))
        H[:, :3] = measurement_jacobian(x[:3], sensor)
        return H

    f = ExtendedKalmanFilter(dim_x=d, dim_z=m, dim_u=3)
    f.x, f.P = model.x0.copy(), model.P0.copy()
    f.F, f.Q, f.R, f.B = model.F, model.Q, R, model.G
    xs, Ps = [], []
    for zk in z:
        f.update(zk, HJacobian=jacobian, Hx=lambda x: measure(x[:3], sensor), residual=measurement_residual)
        xs.append(f.x.copy())
        Ps.append(f.P.copy())
        f.predict(u=model.u)
    return np.array(xs), np.array(Ps)


def noise_covariance(model: GlintModel, which: str) -> np.ndarray:
    """Diagonal R (m, m) the EKF assumes: the Gaussian core's sigma^2
    (``"core"``) or the glint noise's total variance (``"mixture"``)."""
    if which == "core":
        return np.diag(np.asarray(model.sigma, float) ** 2)
    return np.diag(np.asarray(model.noise_variance, float))


@register_method
class EKF(Method):
    r"""Extended Kalman filter assuming Gaussian measurement noise (batched over trials).

    Runs :func:`ekf_filter` on the ``glint`` scenario's model (the tracking
    scene's :class:`~models.glint.GlintModel`): the exact linear dynamics with
    the known control, the spherical measurement linearised at the
    prediction, angle residuals wrapped to $(-\pi, \pi]$. The filter assumes Gaussian
    measurement noise with the Gaussian core's variance $\sigma^2$ (``noise_variance =
    "core"``: ignores the glint, so outliers pass into the estimate with the
    full gain) or with the glint noise's total variance,
    $(1 - \epsilon) \sigma^2 + 2 \epsilon \eta^2$ for the mixture model (``"mixture"``: the
    best linear filter's choice, consistent on average but slower for the Gaussian
    bulk). Returns the updated estimate $x_{k|k}$ and its covariance $P_{k|k}$ (for
    NEES); traces: ``nis``, the normalised innovation squared.
    """

    name = "ekf"
    task = TRACKING
    needs = frozenset({"glint-model"})
    reference_name = "per-trial filterpy ExtendedKalmanFilter loop"
    reference_trials = 10

    @dataclass(frozen=True)
    class Params:
        noise_variance: str = param(
            "core", "measurement-noise variance the filter assumes: 'core' = the Gaussian core's "
            "sigma^2, 'mixture' = the glint noise's total variance", choices=("core", "mixture"))

    def run(self, batch: Batch, params) -> TrackingOutput:
        model = glint_model_of(batch.scene)
        res = ekf_filter(batch.z, model, noise_covariance(model, params.noise_variance))
        return TrackingOutput(estimate=res.x_post, covariance=res.P_post, traces={"nis": res.nis})

    def reference_run(self, batch: Batch, params) -> TrackingOutput:
        """The straightforward per-trial loop ``bench perf`` compares against."""
        model = glint_model_of(batch.scene)
        R = noise_covariance(model, params.noise_variance)
        runs = [filterpy_ekf(z, model, R) for z in batch.z]
        return TrackingOutput(estimate=np.stack([x for x, _ in runs]), covariance=np.stack([P for _, P in runs]))
