r"""Kinematic state models of a point target, per Cartesian axis: the
transition $F$ and process-noise covariance $Q$ of the constant-velocity (CV),
constant-acceleration (CA), Singer and "current statistical" models, the
position measurement matrix $H$, and :class:`KinematicModel`, what the
``maneuvering-1d`` scenario hands to its trackers (docs/architecture.md,
'Models' and 'Scenes').

State per axis: ``[p, v, a]`` (m, m/s, m/s²); in ``dims`` dimensions the
axes are stacked block by block, ``[x, vx, ax, y, vy, ay]``
(:func:`per_axis`). The CV model runs on ``[p, v]`` per axis; :func:`embed_cv`
writes it in the three-component form (acceleration row zero) so that CV and CA
filters share one state space (IMM, variable-dimension filter).

Notation after Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to
Tracking and Navigation* (2001), sec. 6.3 and 8.2 (Singer), and Li & Jilkov,
"Survey of maneuvering target tracking, part I: dynamic models" (the survey
the AR-model patent cites), sec. 4 (Singer, current statistical model):

* CV, discrete white-noise acceleration (DWNA), $\sigma_a$ in m/s²:
  $F = \begin{bmatrix} 1 & T \\ 0 & 1 \end{bmatrix}$, $Q = \sigma_a^2 g g'$, $g = [T^2/2, T]'$;
* CA, discrete Wiener-process acceleration (DWPA), $\sigma_j$ (m/s²) the std of the
  acceleration increment over one step:
  $F = \begin{bmatrix} 1 & T & T^2/2 \\ 0 & 1 & T \\ 0 & 0 & 1 \end{bmatrix}$,
  $Q = \sigma_j^2 g g'$, $g = [T^2/2, T, 1]'$;
* Singer: $\dot{a} = -\alpha a + w$, $E[w(t) w(s)] = 2 \alpha \sigma_m^2 \delta(t - s)$;
  $F = e^{A T}$, $Q = \int_0^T e^{A s} L q L' e^{A' s}\, ds$, computed exactly by Van
  Loan's matrix-exponential method (:func:`singer`), with
  $F = \begin{bmatrix} 1 & T & (\alpha T - 1 + e^{-\alpha T})/\alpha^2 \\
  0 & 1 & (1 - e^{-\alpha T})/\alpha \\ 0 & 0 & e^{-\alpha T} \end{bmatrix}$;
* current statistical (Zhou & Kumar): the Singer $F$ and $Q$ around a non-zero
  "current" mean acceleration $\bar{a}$, with the input $U \bar{a}$
  (:func:`current_statistical_input`) and the acceleration variance
  $\sigma_a^2 = \frac{4 - \pi}{\pi} (a_{\max} - \bar{a})^2$ ($\bar{a} \ge 0$) or
  $\frac{4 - \pi}{\pi} (a_{-\max} + \bar{a})^2$ ($\bar{a} < 0$; $a_{-\max}$ the
  ``a_max_neg`` bound) (:func:`current_statistical_variance`).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.linalg

from radarbench.bench.core import require, require_arrays

#: components per axis of the scenario's state
AXIS_STATE = ("", "v", "a")
AXIS_NAMES = ("x", "y")


def state_labels(dims: int) -> tuple[str, ...]:
    """("x", "vx", "ax") in 1-D, then ("y", "vy", "ay") for the second axis."""
    return tuple(prefix + axis for axis in AXIS_NAMES[:dims] for prefix in AXIS_STATE)


def position_index(dims: int, per_axis_states: int = 3) -> tuple[int, ...]:
    """Indices of the position components in the stacked state."""
    return tuple(per_axis_states * j for j in range(dims))


def per_axis(block: np.ndarray, dims: int) -> np.ndarray:
    """The same per-axis block on each of ``dims`` axes: kron(I_dims, block), element for
    element (the off-diagonal blocks are 0 * block, signed zeros included), as one
    broadcast product: ``np.kron``'s general path was a fifth of a small tracker's call."""
    block = np.asarray(block, float)
    rows, cols = block.shape
    return (np.eye(dims)[:, None, :, None] * block[None, :, None, :]).reshape(dims * rows, dims * cols)


def cv(dt: float, sigma_a: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis (F, Q) of the CV model (DWNA, Bar-Shalom et al. 2001, sec. 6.3.2)."""
    F = np.array([[1.0, dt], [0.0, 1.0]])
    g = np.array([[dt * dt / 2.0], [dt]])
    return F, sigma_a ** 2 * (g @ g.T)


def ca(dt: float, sigma_j: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis (F, Q) of the CA model (DWPA, Bar-Shalom et al. 2001, sec. 6.3.3)."""
    F = np.array([[1.0, dt, dt * dt / 2.0], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    g = np.array([[dt * dt / 2.0], [dt], [1.0]])
    return F, sigma_j ** 2 * (g @ g.T)


def singer(dt: float, alpha: float, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_singer`, computed once per (dt, alpha, sigma_m) (a tracker builds its model
    on every call: the matrix exponential was a third of a small batch's time);
    the arrays are read-only."""
    return _singer(float(dt), float(alpha), float(sigma_m))


@functools.lru_cache(maxsize=64)
def _singer(dt: float, alpha: float, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis (F, Q) of the Singer model with maneuver time constant 1/alpha (s)
    and acceleration std sigma_m (m/s^2). For alpha T <= 1 by Van Loan's method: with
    A = [[0, 1, 0], [0, 0, 1], [0, 0, -alpha]], L = [0, 0, 1]', q = 2 alpha sigma_m^2,
    expm([[-A, L q L'], [0, A']] T) = [[., M12], [0, M22]] gives F = M22',
    Q = F M12 (exact, without the cancellations of the closed form at small alpha T);
    beyond, where the block expm(-A T) grows as e^{alpha T}, by Singer's closed form
    (:func:`_singer_closed_form`)."""
    F, Q = _singer_closed_form(dt, alpha, sigma_m) if alpha * dt > 1.0 else _singer_van_loan(dt, alpha, sigma_m)
    F.flags.writeable = Q.flags.writeable = False
    return F, Q


def _singer_van_loan(dt: float, alpha: float, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_singer` by Van Loan's method."""
    A = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -alpha]])
    LqL = np.zeros((3, 3))
    LqL[2, 2] = 2.0 * alpha * sigma_m ** 2
    M = np.zeros((6, 6))
    M[:3, :3], M[:3, 3:], M[3:, 3:] = -A, LqL, A.T
    E = scipy.linalg.expm(M * dt)
    F = E[3:, 3:].T
    Q = F @ E[:3, 3:]
    return F, 0.5 * (Q + Q.T)


def _singer_transition(dt: float, alpha: float) -> np.ndarray:
    """The Singer F = [[1, T, (alpha T - 1 + e^{-alpha T})/alpha^2], [0, 1, (1 - e^{-alpha T})/alpha],
    [0, 0, e^{-alpha T}]]."""
    e = math.exp(-alpha * dt)
    return np.array([[1.0, dt, (alpha * dt - 1.0 + e) / alpha ** 2], [0.0, 1.0, (1.0 - e) / alpha], [0.0, 0.0, e]])


def _singer_closed_form(dt: float, alpha: float, sigma_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Singer's (F, Q), Q = 2 alpha sigma_m^2 [q_ij] (Singer 1970; Bar-Shalom et al. 2001,
    sec. 8.2.3), with a = alpha, E1 = e^{-aT}, E2 = e^{-2aT}:
    q11 = (1 - E2 + 2aT + 2a^3T^3/3 - 2a^2T^2 - 4aT E1)/(2a^5),
    q12 = (E2 + 1 - 2E1 + 2aT E1 - 2aT + a^2T^2)/(2a^4), q13 = (1 - E2 - 2aT E1)/(2a^3),
    q22 = (4E1 - 3 - E2 + 2aT)/(2a^3), q23 = (E2 + 1 - 2E1)/(2a^2), q33 = (1 - E2)/(2a)."""
    a = alpha
    aT, E1, E2 = alpha * dt, math.exp(-alpha * dt), math.exp(-2.0 * alpha * dt)
    q11 = (1 - E2 + 2 * aT + 2 * aT ** 3 / 3 - 2 * aT ** 2 - 4 * aT * E1) / (2 * a ** 5)
    q12 = (E2 + 1 - 2 * E1 + 2 * aT * E1 - 2 * aT + aT ** 2) / (2 * a ** 4)
    q13 = (1 - E2 - 2 * aT * E1) / (2 * a ** 3)
    q22 = (4 * E1 - 3 - E2 + 2 * aT) / (2 * a ** 3)
    q23 = (E2 + 1 - 2 * E1) / (2 * a ** 2)
    q33 = (1 - E2) / (2 * a)
    Q = 2 * a * sigma_m ** 2 * np.array([[q11, q12, q13], [q12, q22, q23], [q13, q23, q33]])
    return _singer_transition(dt, alpha), Q


def current_statistical_input(dt: float, alpha: float) -> np.ndarray:
    """Per-axis input U (3,) of the current statistical model, x_{k+1} = F x_k + U a_bar:
    U = [(-T + alpha T^2/2 + (1 - e^{-alpha T})/alpha)/alpha, T - (1 - e^{-alpha T})/alpha,
    1 - e^{-alpha T}] (Zhou & Kumar). With a_bar = the current acceleration estimate, F x + U a_bar
    is the CA prediction [p + v T + a T^2/2, v + a T, a]."""
    e = -math.expm1(-alpha * dt)                         # 1 - exp(-alpha T), accurate at small alpha T
    return np.array([(-dt + alpha * dt * dt / 2.0 + e / alpha) / alpha, dt - e / alpha, e])


def current_statistical_variance(a_bar: np.ndarray, a_max: float, a_max_neg: float,
                                 floor: float) -> np.ndarray:
    """sigma_a^2 of the current statistical model (Zhou & Kumar) for the current mean
    acceleration ``a_bar`` (any shape): (4 - pi)/pi (a_max - a_bar)^2 for a_bar >= 0,
    (4 - pi)/pi (a_max_neg + a_bar)^2 for a_bar < 0 (a_max, a_max_neg > 0 the largest
    accelerations either way). ``a_bar`` beyond the bounds would give a variance that
    grows again (or vanishes at the bound), so it is clipped into [-a_max_neg, a_max]
    and the variance held at ``floor`` at least."""
    a = np.minimum(np.maximum(a_bar, -a_max_neg), a_max)
    room = np.where(a >= 0.0, a_max - a, a_max_neg + a)
    return np.maximum((4.0 - math.pi) / math.pi * room ** 2, floor)


def embed_cv(F_cv: np.ndarray, Q_cv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The per-axis CV (F, Q) written on [p, v, a]: the acceleration is not part of the
    model (row and column zero), so a CV and a CA filter share one state space."""
    F, Q = np.zeros((3, 3)), np.zeros((3, 3))
    F[:2, :2], Q[:2, :2] = F_cv, Q_cv
    return F, Q


def position_measurement(dims: int, per_axis_states: int = 3) -> np.ndarray:
    """H (dims, per_axis_states * dims): the position of each axis."""
    H = np.zeros((dims, per_axis_states * dims))
    H[np.arange(dims), list(position_index(dims, per_axis_states))] = 1.0
    return H


def cv_components(dims: int) -> list[int]:
    """Indices of [p, v] of each axis in the three-component state: where a CV
    state (``2 dims``) sits in the scenario's state (``3 dims``)."""
    return [3 * j + c for j in range(dims) for c in (0, 1)]


@dataclass(frozen=True, eq=False)
class KinematicModel:
    """What a kinematic tracking scenario (``maneuvering-1d``) tells its trackers
    (the tracking scene's ``model``): the step, the measurement noise, the number
    of axes and the prior of step 0 in the state ``[x, vx, ax(, y, vy, ay)]``.
    Each tracker chooses its own dynamics (this module's F, Q)."""

    #: time step T between measurements (s)
    dt_s: float
    #: std of the Gaussian position-measurement noise, per axis (m)
    noise_std_m: float
    #: number of Cartesian axes (1: range only; 2: planar position)
    dims: int
    #: (3 dims,) prior mean of step 0 (m, m/s, m/s^2 per axis), shared by all trials
    x0: np.ndarray
    #: (3 dims, 3 dims) prior covariance of step 0
    P0: np.ndarray

    def __post_init__(self) -> None:
        require(self, "dt_s", isinstance(self.dt_s, float) and self.dt_s > 0, "a float > 0 (s)")
        require(self, "noise_std_m", isinstance(self.noise_std_m, float) and self.noise_std_m > 0,
                "a float > 0 (m)")
        require(self, "dims", self.dims in (1, 2), "1 or 2")
        d = 3 * self.dims
        require_arrays(self, {"x0": (d,), "P0": (d, d)})

    @cached_property
    def H(self) -> np.ndarray:
        """(dims, 3 dims) position measurement matrix."""
        return position_measurement(self.dims)

    @cached_property
    def R(self) -> np.ndarray:
        """(dims, dims) measurement-noise covariance."""
        return self.noise_std_m ** 2 * np.eye(self.dims)


def kinematic_model_of(scene) -> KinematicModel:
    """The scene's :class:`KinematicModel`, or a TypeError naming what it holds
    (the trackers of this module's models run on kinematic scenes only)."""
    model = getattr(scene, "model", None)
    if not isinstance(model, KinematicModel):
        raise TypeError(f"expected a tracking scene whose model is a models.kinematics.KinematicModel "
                        f"(a scenario providing kinematic-model), got {type(model).__name__}")
    return model
