r"""The coordinated-turn (CT) model with an unknown turn rate: its transition, the
Jacobian an extended Kalman filter predicts with, and the turn a scenario flies
(docs/architecture.md, 'Models').

Bar-Shalom, Li & Kirubarajan, *Estimation with Applications to Tracking and
Navigation* (2001), sec. 11.7.1-11.7.2: state $[x, v_x, y, v_y, \Omega]'$ (m, m/s,
rad/s; $\Omega > 0$ counter-clockwise), over one step $T$ with $\Omega$ held:

$$
\begin{aligned}
x' &= x + a v_x - b v_y, & a &= \sin(\Omega T)/\Omega, \\
v_x' &= c v_x - s v_y, & b &= (1 - \cos(\Omega T))/\Omega, \\
y' &= y + b v_x + a v_y, & s &= \sin(\Omega T), \quad c = \cos(\Omega T), \\
v_y' &= s v_x + c v_y, \quad \Omega' = \Omega,
\end{aligned}
$$

so $[x, v_x, y, v_y]'$ becomes $F(\Omega) [x, v_x, y, v_y]'$ (:func:`ct_transition`), and the
Jacobian's last column is $\partial F / \partial \Omega\, [x, v_x, y, v_y]'$ with
$a' = (\Omega T c - s)/\Omega^2$, $b' = (\Omega T s - (1 - c))/\Omega^2$, $s' = T c$, $c' = -T s$
(:func:`ct_jacobian`). At $|\Omega T| < 10^{-4}$ $a$, $b$, $a'$, $b'$ are their series
($a = T (1 - (\Omega T)^2/6)$, $b = \Omega T^2/2\, (1 - (\Omega T)^2/12)$, $a' = -\Omega T^3/3$,
$b' = T^2/2\, (1 - (\Omega T)^2/4)$): the closed forms cancel to 0/0 there; $\Omega = 0$ is
the CV transition exactly.
"""

from __future__ import annotations

import numba
import numpy as np

#: below this |Omega T| the closed forms are replaced by their series (module docstring)
SERIES_BELOW = 1e-4
#: index of the turn rate in the CT state [x, vx, y, vy, Omega]
TURN_RATE_INDEX = 4


@numba.njit(cache=True)
def _coefficients(omega, dt):
    """(a, b, s, c, a', b') of the module docstring."""
    wt = omega * dt
    s, c = np.sin(wt), np.cos(wt)
    if abs(wt) < SERIES_BELOW:
        a = dt * (1.0 - wt * wt / 6.0)
        b = 0.5 * omega * dt * dt * (1.0 - wt * wt / 12.0)
        da = -omega * dt ** 3 / 3.0
        db = 0.5 * dt * dt * (1.0 - wt * wt / 4.0)
    else:
        a, b = s / omega, (1.0 - c) / omega
        da = (wt * c - s) / (omega * omega)
        db = (wt * s - (1.0 - c)) / (omega * omega)
    return a, b, s, c, da, db


@numba.njit(cache=True)
def ct_transition(omega, dt):
    """F(Omega) (4, 4) on [x, vx, y, vy] for turn rate ``omega`` (rad/s) over ``dt`` (s)."""
    a, b, s, c, _, _ = _coefficients(omega, dt)
    F = np.zeros((4, 4))
    F[0, 0] = F[2, 2] = 1.0
    F[0, 1], F[0, 3] = a, -b
    F[1, 1], F[1, 3] = c, -s
    F[2, 1], F[2, 3] = b, a
    F[3, 1], F[3, 3] = s, c
    return F


@numba.njit(cache=True)
def ct_jacobian(x, dt):
    """(f(x), J): the CT prediction of one state ``x`` [x, vx, y, vy, Omega] (5,) over ``dt``
    and its Jacobian J (5, 5) at ``x`` (module docstring)."""
    omega = x[TURN_RATE_INDEX]
    a, b, s, c, da, db = _coefficients(omega, dt)
    J = np.zeros((5, 5))
    J[:4, :4] = ct_transition(omega, dt)
    J[4, 4] = 1.0
    vx, vy = x[1], x[3]
    J[0, 4] = da * vx - db * vy
    J[1, 4] = -dt * s * vx - dt * c * vy
    J[2, 4] = db * vx + da * vy
    J[3, 4] = dt * c * vx - dt * s * vy
    f = np.empty(5)
    f[:4] = J[:4, :4] @ x[:4]
    f[4] = omega
    return f, J


def ct_noise(dt: float, sigma_a: float, sigma_omega: float) -> np.ndarray:
    """Q (5, 5) of the CT model: a white acceleration sigma_a (m/s^2) per axis held over the
    step (DWNA, g = [T^2/2, T]') and a turn-rate random walk of std sigma_omega T per step
    (sigma_omega in rad/s^2; Bar-Shalom et al. 2001, sec. 11.7.2)."""
    g = np.array([dt * dt / 2.0, dt])
    Q = np.zeros((5, 5))
    for axis in (0, 2):
        Q[axis:axis + 2, axis:axis + 2] = sigma_a ** 2 * np.outer(g, g)
    Q[4, 4] = (sigma_omega * dt) ** 2
    return Q


def turn_acceleration(velocity: np.ndarray, omega: float) -> np.ndarray:
    """The centripetal acceleration Omega x v (..., 2) of a coordinated turn: (-Omega vy, Omega vx)."""
    velocity = np.asarray(velocity, float)
    return omega * np.stack([-velocity[..., 1], velocity[..., 0]], axis=-1)
