"""Method ``vd-filter``: the variable-dimension filter (CV, switching to CA on a
chi-square maneuver detection and back when the acceleration is
insignificant), batched over trials."""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np
from scipy import stats

from radarbench.bench.core import Batch, TrackingOutput
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.methods.kinematic.base import SIGMA_WHY, KinematicTracker, ca_noise_param, cv_ca_modes, cv_noise_param, output
from radarbench.models.kalman import LinearGaussianModel, inverse_logdet, predict_one, small_inverse_into, update_one, update_scratch
from radarbench.models.kinematics import KinematicModel

LEVEL_WHY = "a test level: a probability away from 0 and 1"


@dataclass(frozen=True)
class VDRules:
    """The switching rule's constants (:class:`VariableDimension`): fading factor rho,
    the detection threshold on the fading NIS, the window s and the threshold of
    the acceleration's significance over it, the restart acceleration variance."""

    rho: float
    detect_threshold: float
    window: int
    back_threshold: float
    accel_init_var: float

    @classmethod
    def of(cls, params, dims: int) -> "VDRules":
        rho = params.fading
        # the fading sum of NIS ~ chi2(m) has mean m/(1-rho) and variance 2m/(1-rho^2) in steady
        # state; a scaled chi-square c chi2(nu) with the same two moments: c = 1/(1+rho),
        # nu = m (1+rho)/(1-rho)
        nu = dims * (1.0 + rho) / (1.0 - rho)
        return cls(rho=rho, detect_threshold=float(stats.chi2.isf(params.detect_level, nu) / (1.0 + rho)),
                   window=params.window_steps,
                   back_threshold=float(stats.chi2.isf(params.back_level, dims * params.window_steps)),
                   accel_init_var=params.accel_init_std_m_s2 ** 2)


def _restart_state(x: np.ndarray, P: np.ndarray, acc: np.ndarray, accel_var: float):
    """The CA restart: keep position and velocity (and their covariance), acceleration 0
    with variance ``accel_var``, uncorrelated."""
    x, P = x.copy(), P.copy()
    x[..., acc] = 0.0
    P[..., acc, :] = 0.0
    P[..., :, acc] = 0.0
    P[..., acc, acc] = accel_var
    return x, P


def _drop_acceleration(x: np.ndarray, P: np.ndarray, acc: np.ndarray):
    """Back to CV: the acceleration leaves the state (0, no variance)."""
    x, P = x.copy(), P.copy()
    x[..., acc] = 0.0
    P[..., acc, :] = 0.0
    P[..., :, acc] = 0.0
    return x, P


def _acceleration_nis(x: np.ndarray, P: np.ndarray, acc: np.ndarray) -> np.ndarray:
    """a' P_aa^-1 a of the acceleration estimate (...,)."""
    a = x[..., acc]
    P_aa_inv = inverse_logdet(P[..., acc[:, None], acc[None, :]])[0]
    return np.einsum("...i,...i->...", a, (P_aa_inv @ a[..., None])[..., 0])


@numba.njit(cache=True)
def _restart_into(x, P, acc, accel_var):
    """:func:`_restart_state` in place (one trial)."""
    for a in acc:
        x[a] = 0.0
        P[a, :] = 0.0
        P[:, a] = 0.0
        P[a, a] = accel_var


@numba.njit(cache=True)
def _acceleration_nis_one(x, P, acc, P_aa, P_aa_inv):
    """a' P_aa^-1 a of one trial's acceleration estimate."""
    for j in range(len(acc)):
        for l in range(len(acc)):
            P_aa[j, l] = P[acc[j], acc[l]]
    small_inverse_into(P_aa, P_aa_inv)
    q = 0.0
    for j in range(len(acc)):
        for l in range(len(acc)):
            q += x[acc[j]] * P_aa_inv[j, l] * x[acc[l]]
    return q


@numba.njit(cache=True)
def _vd_kernel(z, valid, x0, P0, F_cv, Q_cv, F_ca, Q_ca, H, R, rho, detect_threshold, window, back_threshold,
               accel_var):
    """The rule of :class:`VariableDimension`, trial by trial and step by step in compiled
    loops (the switching and the restarts differ per trial). ``valid`` (n, K) bool: the
    steps each trial has; at a missing one the filter predicts only and neither test runs
    (the mode holds), the re-filtering of a restart skips it, and the back-to-CV test's
    window is the last s steps the trial has. Returns x_k|k (n, K, d), P_k|k (n, K, d, d),
    the mode, switch and fading-NIS traces (n, K)."""
    n, K, m = z.shape
    d = x0.shape[0]
    acc = np.arange(2, d, 3)
    xs, Ps = np.empty((n, K, d)), np.empty((n, K, d, d))
    mode_tr, switch, fading = np.zeros((n, K)), np.zeros((n, K)), np.full((n, K), np.nan)
    x, P, x_new, P_new = np.empty(d), np.empty((d, d)), np.empty(d), np.empty((d, d))
    nu, S, FP, zero_u = np.empty(m), np.empty((m, m)), np.empty((d, d)), np.zeros(d)
    P_aa, P_aa_inv, q = np.empty((len(acc), len(acc))), np.empty((len(acc), len(acc))), np.zeros(K)
    scratch = update_scratch(d, m)
    for i in range(n):
        x[:], P[:, :] = x0, P0
        in_ca, eps_bar, ca_steps, seen = False, 0.0, 0, -1
        for k in range(K):
            if valid[i, k]:                                 # else a step the trial does not have: predict only
                seen += 1                                       # the index of this step among the trial's own
                nis, _ = update_one(x, P, z[i, k], H, R, x_new, P_new, nu, S, scratch)
                x[:], P[:, :] = x_new, P_new
                detected = False
                if not in_ca:
                    eps_bar = rho * eps_bar + nis
                    if eps_bar > detect_threshold:              # restart in CA at k - s and re-filter
                        start = k - window
                        if start >= 0:
                            x[:], P[:, :] = xs[i, start], Ps[i, start]
                            _restart_into(x, P, acc, accel_var)
                            predict_one(x, P, F_ca, Q_ca, zero_u, x_new, P_new, FP)
                            x[:], P[:, :] = x_new, P_new
                        else:
                            x[:], P[:, :] = x0, P0
                            _restart_into(x, P, acc, accel_var)
                        for j in range(max(start + 1, 0), k + 1):
                            if valid[i, j]:
                                update_one(x, P, z[i, j], H, R, x_new, P_new, nu, S, scratch)
                                x[:], P[:, :] = x_new, P_new
                            if j < k:
                                predict_one(x, P, F_ca, Q_ca, zero_u, x_new, P_new, FP)
                                x[:], P[:, :] = x_new, P_new
                        in_ca, detected, ca_steps = True, True, 0
                        switch[i, k] = 1.0
                if in_ca:
                    q[seen] = _acceleration_nis_one(x, P, acc, P_aa, P_aa_inv)
                    if not detected:
                        ca_steps += 1
                    if ca_steps >= window and q[seen - window + 1:seen + 1].sum() < back_threshold:
                        for a in acc:                           # back to CV: the acceleration leaves
                            x[a] = 0.0
                            P[a, :] = 0.0
                            P[:, a] = 0.0
                        in_ca, eps_bar = False, 0.0
            xs[i, k], Ps[i, k] = x, P
            mode_tr[i, k] = 1.0 if in_ca else 0.0
            if not in_ca:
                fading[i, k] = eps_bar
            if in_ca:
                predict_one(x, P, F_ca, Q_ca, zero_u, x_new, P_new, FP)
            else:
                predict_one(x, P, F_cv, Q_cv, zero_u, x_new, P_new, FP)
            x[:], P[:, :] = x_new, P_new
    return xs, Ps, mode_tr, switch, fading


@register_method
class VariableDimension(KinematicTracker):
    r"""Variable-dimension filter (Bar-Shalom & Birmiwal): CV, CA on a chi-square maneuver detection with a back-dated restart (s steps before the detection, re-filtered), back to CV when the acceleration is insignificant.

    Bar-Shalom & Birmiwal, "Variable dimension filter for maneuvering target
    tracking" (IEEE Trans. AES, 1982), as described in the AR-model patent's
    background (CV filtering, CA once a detection statistic exceeds its
    threshold). State $[p, v, a]'$ per axis; in the quiet mode the CV model
    (DWNA, $\sigma_a$, acceleration 0 and outside the model,
    :func:`models.kinematics.embed_cv`), in the maneuver mode the CA model
    (DWPA, $\sigma_j$). The rule (each trial switches and restarts on its own,
    so the filter runs as one compiled loop over trials and steps,
    :func:`_vd_kernel`, on the per-trial steps of :mod:`models.kalman`):

    * **Detection** (CV mode): the fading-memory NIS
      $\bar{\epsilon}_k = \rho\, \bar{\epsilon}_{k-1} + \epsilon_k$
      ($\epsilon_k = \nu' S^{-1} \nu$ of the CV filter, $\chi^2(m)$ under no maneuver,
      $m$ = dims; effective window $1/(1 - \rho)$) is compared with the
      1 − ``detect_level`` quantile of a scaled chi-square $c\, \chi^2(n)$,
      $c = 1/(1 + \rho)$, $n = m (1 + \rho)/(1 - \rho)$, the one with $\bar{\epsilon}$'s
      steady-state mean $m/(1 - \rho)$ and variance $2m/(1 - \rho^2)$ (our choice of
      the threshold's law).
    * **Switch to CA, back-dated** at step $k$ (trace ``switch`` = 1): the maneuver is
      taken to have begun ``window_steps`` = $s$ steps earlier; the CA filter
      restarts from the estimate at $k - s$ (position, velocity and their
      covariance kept; acceleration 0 with std ``accel_init_std_m_s2``,
      uncorrelated; the prior of step 0 if $k < s$) and re-filters
      $z_{k-s+1}, \dots, z_k$, so the acceleration is estimated from the window.
      Bar-Shalom & Birmiwal initialise the acceleration from the innovation
      at $k - s$ instead; our diffuse restart lets the window's measurements
      estimate it. Estimates already output are not revised, but from $k$ on
      the CA filter has seen the window's $s$ measurements as a maneuver's: a
      head start over a tracker that switches at $k$ without looking back (the
      AR tracker's seamless switch), which the comparisons against it carry.
    * **Switch back to CV** (the acceleration insignificant): after $s$ steps
      in CA mode, when $\delta_k = \sum_{j=k-s+1}^{k} \hat{a}_j' P_{aa,j}^{-1} \hat{a}_j$ is below
      the 1 − ``back_level`` quantile of $\chi^2(m s)$ ($\delta$'s law were the
      estimates independent with $a = 0$); the acceleration leaves the state and
      $\bar{\epsilon}$ restarts at 0.

    Reported covariance: in CV mode the acceleration variance is $\sigma_a^2$
    (:mod:`methods.kinematic.base`). Traces: ``mode`` (0 CV, 1 CA),
    ``switch``, ``fading_nis`` ($\bar{\epsilon}$; NaN in CA mode).
    """

    name = "vd-filter"
    reference_name = "per-trial filterpy KalmanFilter loop with the same switching"

    @dataclass(frozen=True)
    class Params:
        accel_noise_m_s2: float = cv_noise_param(1.0)
        accel_increment_m_s2: float = ca_noise_param(1.0)
        fading: float = param(0.8, "fading factor rho of the NIS average (effective window 1/(1 - rho) steps)",
                              ge=0.0, le=0.99, why="0 is the NIS alone; at most a 100-step memory")
        detect_level: float = param(0.01, "per-step false-detection probability of the maneuver test",
                                    ge=1e-12, le=0.5, why=LEVEL_WHY)
        window_steps: int = param(5, "window s: steps the CA restart is back-dated by and re-filters, and "
                                  "over which the acceleration's significance is tested", ge=1, le=100,
                                  why="one step at least; at most 100, a re-run per detection")
        back_level: float = param(0.05, "level of the acceleration's significance test (back to CV below "
                                  "its threshold)", ge=1e-12, le=0.5, why=LEVEL_WHY)
        accel_init_std_m_s2: float = param(30.0, "std of the acceleration at a CA restart (m/s^2)", ge=1e-3,
                                           le=1e3, why=SIGMA_WHY)

    @staticmethod
    def modes(model: KinematicModel, params) -> list[LinearGaussianModel]:
        return cv_ca_modes(model, params.accel_noise_m_s2, params.accel_increment_m_s2)

    def track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        cv_m, ca_m = self.modes(model, params)
        r = VDRules.of(params, model.dims)
        valid = batch.scene.valid_steps
        valid = np.ones(batch.z.shape[:2], bool) if valid is None else np.ascontiguousarray(valid)
        xs, Ps, mode, switch, fading = _vd_kernel(
            np.ascontiguousarray(batch.z, dtype=float), valid, model.x0, model.P0, cv_m.F, cv_m.Q, ca_m.F, ca_m.Q,
            model.H, model.R, r.rho, r.detect_threshold, r.window, r.back_threshold, r.accel_init_var)
        return self._output(xs, Ps, mode, switch, fading, np.arange(2, cv_m.dim_x, 3), params)

    @staticmethod
    def _output(xs, Ps, mode_tr, switch, fading_tr, acc, params) -> TrackingOutput:
        quiet = mode_tr == 0                                     # CV mode: report a = 0 with var sigma_a^2
        Ps[..., acc, acc] = np.where(quiet[..., None], params.accel_noise_m_s2 ** 2, Ps[..., acc, acc])
        out = output(xs, Ps, mode_tr, switch)
        out.traces["fading_nis"] = fading_tr
        return out

    def reference_track(self, batch: Batch, model: KinematicModel, params) -> TrackingOutput:
        """The same rule trial by trial with a filterpy ``KalmanFilter``."""
        from filterpy.kalman import KalmanFilter

        cv_m, ca_m = self.modes(model, params)
        rules = VDRules.of(params, model.dims)
        n, K, m = batch.z.shape
        d, acc, s = cv_m.dim_x, np.arange(2, cv_m.dim_x, 3), rules.window
        xs, Ps = np.empty((n, K, d)), np.empty((n, K, d, d))
        mode_tr, switch, fading_tr = np.zeros((n, K)), np.zeros((n, K)), np.full((n, K), np.nan)

        def new_filter(x, P, mode_model):
            kf = KalmanFilter(dim_x=d, dim_z=m)
            kf.F, kf.H, kf.Q, kf.R = mode_model.F, mode_model.H, mode_model.Q, mode_model.R
            kf.x, kf.P = np.array(x, float), np.array(P, float)
            return kf

        for i in range(n):
            z = batch.z[i]
            kf, in_ca, eps_bar, ca_steps, q = new_filter(model.x0, model.P0, cv_m), False, 0.0, 0, []
            for k in range(K):
                kf.update(z[k])
                if not in_ca:
                    eps_bar = rules.rho * eps_bar + float(kf.y @ np.linalg.solve(kf.S, kf.y))
                    if eps_bar > rules.detect_threshold:
                        start = k - s
                        if start >= 0:
                            kf = new_filter(*_restart_state(xs[i, start], Ps[i, start], acc, rules.accel_init_var),
                                            ca_m)
                            kf.predict()
                        else:
                            kf = new_filter(*_restart_state(model.x0, model.P0, acc, rules.accel_init_var), ca_m)
                        for j in range(max(start + 1, 0), k + 1):
                            kf.update(z[j])
                            if j < k:
                                kf.predict()
                        in_ca, ca_steps, switch[i, k], q = True, -1, 1.0, []
                if in_ca:
                    q.append(float(_acceleration_nis(kf.x, kf.P, acc)))
                    ca_steps += 1
                    if ca_steps >= s and sum(q[-s:]) < rules.back_threshold:
                        kf = new_filter(*_drop_acceleration(kf.x, kf.P, acc), cv_m)
                        in_ca, eps_bar = False, 0.0
                xs[i, k], Ps[i, k], mode_tr[i, k] = kf.x, kf.P, in_ca
                fading_tr[i, k] = np.nan if in_ca else eps_bar
                kf.predict()
        return self._output(xs, Ps, mode_tr, switch, fading_tr, acc, params)
