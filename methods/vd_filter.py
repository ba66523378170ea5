"""Method ``vd-filter``: the variable-dimension filter (CV, switching to CA on a
chi-square maneuver detection and back when the acceleration is
insignificant), batched over trials."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from bench.core import Batch, TrackingOutput
from bench.params import param
from bench.registry import register_method
from methods._kinematic_base import SIGMA_WHY, KinematicTracker, ca_noise_param, cv_ca_modes, cv_noise_param, output
from models.kalman import LinearGaussianModel, predict_batched, update_batched
from models.kinematics import KinematicModel

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
    return np.einsum("...i,...i->...", a, np.linalg.solve(P[..., acc[:, None], acc[None, :]], a[..., None])[..., 0])


@register_method
class VariableDimension(KinematicTracker):
    """Variable-dimension filter (Bar-Shalom & Birmiwal): CV, CA on a chi-square maneuver detection, back to CV when the acceleration is insignificant.

    Bar-Shalom & Birmiwal, "Variable dimension filter for maneuvering target
    tracking" (IEEE Trans. AES, 1982), as described in the AR-model patent's
    background (CV filtering, CA once a detection statistic exceeds its
    threshold). State [p, v, a] per axis; in the quiet mode the CV model
    (DWNA, sigma_a, acceleration 0 and outside the model,
    :func:`models.kinematics.embed_cv`), in the maneuver mode the CA model
    (DWPA, sigma_j). The rule, batched over trials (each trial switches on
    its own):

    * **Detection** (CV mode): the fading-memory NIS
      eps_bar_k = rho eps_bar_{k-1} + eps_k (eps_k = nu' S^-1 nu of the CV
      filter, chi2(m) under no maneuver, m = dims; effective window
      1/(1 - rho)) is compared with the (1 - ``detect_level``) quantile of a
      scaled chi-square c chi2(nu), c = 1/(1 + rho), nu = m (1 + rho)/(1 - rho),
      the one with eps_bar's steady-state mean m/(1 - rho) and variance
      2m/(1 - rho^2) (our choice of the threshold's law).
    * **Switch to CA** at step k (trace ``switch`` = 1): the maneuver is
      taken to have begun ``window_steps`` = s steps earlier; the CA filter
      restarts from the estimate at k - s (position, velocity and their
      covariance kept; acceleration 0 with std ``accel_init_std_m_s2``,
      uncorrelated; the prior of step 0 if k < s) and re-filters
      z_{k-s+1..k}, so the acceleration is estimated from the window.
      Bar-Shalom & Birmiwal initialise the acceleration from the innovation
      at k - s instead; our diffuse restart lets the window's measurements
      estimate it. Estimates already output are not revised.
    * **Switch back to CV** (the acceleration insignificant): after s steps
      in CA mode, when delta_k = sum of a_j' P_aa,j^-1 a_j over the last s
      steps is below the (1 - ``back_level``) quantile of chi2(m s) (delta's
      law were the estimates independent with a = 0); the acceleration
      leaves the state and eps_bar restarts at 0.

    Reported covariance: in CV mode the acceleration variance is sigma_a^2
    (:mod:`methods._kinematic_base`). Traces: ``mode`` (0 CV, 1 CA),
    ``switch``, ``fading_nis`` (eps_bar; NaN in CA mode).
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
        window_steps: int = param(5, "window s: steps re-filtered at a restart, and over which the "
                                  "acceleration's significance is tested", ge=1, le=100,
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
        rules = VDRules.of(params, model.dims)
        z = batch.z
        n, K, _ = z.shape
        d, acc, s = cv_m.dim_x, np.arange(2, cv_m.dim_x, 3), rules.window
        xs, Ps = np.empty((n, K, d)), np.empty((n, K, d, d))
        mode_tr, switch, fading_tr, q_hist = np.zeros((n, K)), np.zeros((n, K)), np.full((n, K), np.nan), \
            np.zeros((n, K))
        x = np.broadcast_to(model.x0, (n, d)).copy()
        P = np.broadcast_to(model.P0, (n, d, d)).copy()
        mode, eps_bar, ca_steps = np.zeros(n, bool), np.zeros(n), np.zeros(n, int)
        for k in range(K):
            upd = update_batched(x, P, z[:, k], model.H, model.R)
            x, P = upd.x, upd.P
            eps_bar = np.where(mode, 0.0, rules.rho * eps_bar + upd.nis)
            detect = ~mode & (eps_bar > rules.detect_threshold)
            if detect.any():
                idx = np.flatnonzero(detect)
                x[idx], P[idx] = self._refilter(idx, k, xs, Ps, z, model, ca_m, rules, acc)
                mode[idx], ca_steps[idx], switch[idx, k] = True, 0, 1.0
            q_hist[mode, k] = _acceleration_nis(x[mode], P[mode], acc)     # CV trials: no acceleration
            ca_steps = np.where(mode & ~detect, ca_steps + 1, ca_steps)
            back = mode & (ca_steps >= s) & (q_hist[:, max(k - s + 1, 0):k + 1].sum(axis=1) < rules.back_threshold)
            if back.any():
                x[back], P[back] = _drop_acceleration(x[back], P[back], acc)
                mode[back], eps_bar[back] = False, 0.0
            xs[:, k], Ps[:, k] = x, P
            mode_tr[:, k] = mode
            fading_tr[:, k] = np.where(mode, np.nan, eps_bar)
            F = np.where(mode[:, None, None], ca_m.F, cv_m.F)
            Q = np.where(mode[:, None, None], ca_m.Q, cv_m.Q)
            x, P = predict_batched(x, P, F, Q)
        return self._output(xs, Ps, mode_tr, switch, fading_tr, acc, params)

    @staticmethod
    def _refilter(idx, k, xs, Ps, z, model, ca_m, rules, acc):
        """The CA restart of trials ``idx`` detected at step k: from the estimate at
        k - s (or the prior), re-filter the window's measurements up to z_k."""
        start = k - rules.window
        if start >= 0:
            x, P = _restart_state(xs[idx, start], Ps[idx, start], acc, rules.accel_init_var)
            first = start + 1
            x, P = predict_batched(x, P, ca_m.F, ca_m.Q)
        else:
            x, P = _restart_state(np.broadcast_to(model.x0, (len(idx), len(model.x0))),
                                  np.broadcast_to(model.P0, (len(idx), *model.P0.shape)), acc, rules.accel_init_var)
            first = 0
        for j in range(first, k + 1):
            upd = update_batched(x, P, z[idx, j], model.H, model.R)
            x, P = upd.x, upd.P
            if j < k:
                x, P = predict_batched(x, P, ca_m.F, ca_m.Q)
        return x, P

    @staticmethod
    def _output(xs, Ps, mode_tr, switch, fading_tr, acc, params) -> TrackingOutput:
        quiet = mode_tr == 0                                     # CV mode: report a = 0 with var sigma_a^2
        Ps = Ps.copy()
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
