r"""HF surface-wave radar geometry: a constant-velocity ship seen in range,
azimuth and radial velocity (the multi-target task's shared maths;
docs/architecture.md, 'Models').

After "目标检测与跟踪方法 (Target detection and tracking methods), 海洋遥感技术应用"
(the HFSWR CFAR / M-N / JPDA-UKF chapter), section 2(1).

State and frame: $x = [x, v_x, y, v_y]'$ (metres, m/s; $x$ east, $y$ north: Cartesian, the
paper's CV state), the sensor at ``sensor_xy`` $= (s_x, s_y)$, $d_x = x - s_x$, $d_y = y - s_y$.
Measurement (the paper's eq. 6.71, noise-free part): range (m), azimuth clockwise from
north ($+y$) in $(-\pi, \pi]$, radial velocity (m/s) positive receding,

$$
r = \sqrt{d_x^2 + d_y^2}, \qquad \mathit{az} = \operatorname{atan2}(d_x, d_y), \qquad
v_r = (d_x v_x + d_y v_y) / r. \qquad (6.71)
$$

The noise is independent per component; the paper notes that range and radial
velocity may be correlated with a coefficient $\rho$ that an HFSWR cannot measure,
and takes $\rho = 0$ — so do we.

Motion (the paper's eq. 6.69): $x_{k+1} = F x_k + G v_k$ with the CV transition $F$
(:func:`cv_transition`) and $v_k \sim \mathcal{N}(0, \sigma_v^2 I)$ a white acceleration held
over each scan: the *discrete* white-noise acceleration model,
$Q = \sigma_v^2 G G'$ with $G = [T^2/2, T]'$ per axis (:func:`cv_process_noise`).
"""

from __future__ import annotations

import numpy as np

from radarbench.models.spherical import wrap_angle

__all__ = ["MEASUREMENT_LABELS", "POSITION_INDEX", "STATE_LABELS", "VELOCITY_INDEX", "angle_difference",
           "cv_process_noise", "cv_transition", "measure", "measure_jacobian", "measurement_residual",
           "plot_to_cartesian", "wrap_angle"]

#: state components, in order
STATE_LABELS = ("x", "vx", "y", "vy")
#: measured components, in order (m, rad, m/s)
MEASUREMENT_LABELS = ("range", "azimuth", "radial_velocity")
#: indices of the position and velocity components in the state
POSITION_INDEX = (0, 2)
VELOCITY_INDEX = (1, 3)


def _offsets(x, sensor_xy):
    x = np.asarray(x, float)
    s = np.asarray(sensor_xy, float)
    return x[..., 0] - s[0], x[..., 2] - s[1], x[..., 1], x[..., 3]


def measure(x, sensor_xy) -> np.ndarray:
    """h(x): (..., 3) [range m, azimuth rad (clockwise from north), radial
    velocity m/s (positive receding)] of states ``x`` (..., 4) seen from
    ``sensor_xy`` (2,) (the paper's eq. 6.71 without noise)."""
    dx, dy, vx, vy = _offsets(x, sensor_xy)
    r = np.hypot(dx, dy)
    return np.stack([r, np.arctan2(dx, dy), (dx * vx + dy * vy) / r], axis=-1)


def measure_jacobian(x, sensor_xy) -> np.ndarray:
    """dh/dx (..., 3, 4) of :func:`measure` at states ``x`` (..., 4).

    With r^2 = dx^2 + dy^2 and vr = (dx vx + dy vy) / r::

        dr/d(x, vx, y, vy)  = (dx/r, 0, dy/r, 0)
        daz/d(...)          = (dy/r^2, 0, -dx/r^2, 0)
        dvr/d(...)          = ((vx - vr dx/r)/r, dx/r, (vy - vr dy/r)/r, dy/r)
    """
    dx, dy, vx, vy = _offsets(x, sensor_xy)
    r2 = dx * dx + dy * dy
    r = np.sqrt(r2)
    vr = (dx * vx + dy * vy) / r
    zero = np.zeros_like(r)
    rows = (np.stack([dx / r, zero, dy / r, zero], axis=-1),
            np.stack([dy / r2, zero, -dx / r2, zero], axis=-1),
            np.stack([(vx - vr * dx / r) / r, dx / r, (vy - vr * dy / r) / r, dy / r], axis=-1))
    return np.stack(rows, axis=-2)


def angle_difference(a, b):
    """a - b wrapped to (-pi, pi] (azimuth residuals near south, az ~ +-pi)."""
    return wrap_angle(np.asarray(a, float) - np.asarray(b, float))


def measurement_residual(z, zhat) -> np.ndarray:
    """z - zhat (..., 3) with the azimuth difference wrapped to (-pi, pi]."""
    res = np.asarray(z, float) - np.asarray(zhat, float)
    res[..., 1] = wrap_angle(res[..., 1])
    return res


def plot_to_cartesian(z, sensor_xy) -> np.ndarray:
    """(..., 2) east/north position (m) of plots ``z`` (..., >= 2) [range,
    azimuth, ...]: the inverse of the range and azimuth of :func:`measure`."""
    z = np.asarray(z, float)
    s = np.asarray(sensor_xy, float)
    r, az = z[..., 0], z[..., 1]
    return np.stack([s[0] + r * np.sin(az), s[1] + r * np.cos(az)], axis=-1)


def cv_transition(dt: float) -> np.ndarray:
    """F (4, 4) of the constant-velocity model over ``dt`` seconds for
    [x, vx, y, vy] (the paper's eq. 6.69)."""
    block = np.array([[1.0, dt], [0.0, 1.0]])
    F = np.zeros((4, 4))
    F[:2, :2] = F[2:, 2:] = block
    return F


def cv_gain(dt: float) -> np.ndarray:
    """G (4, 2): how an acceleration (ax, ay) held over ``dt`` enters
    [x, vx, y, vy]: x_{k+1} = F x_k + G a_k."""
    G = np.zeros((4, 2))
    G[:2, 0] = G[2:, 1] = (0.5 * dt * dt, dt)
    return G


def cv_process_noise(dt: float, accel_std: float) -> np.ndarray:
    """Q (4, 4) = accel_std^2 G G' of the *discrete* white-noise acceleration
    model (acceleration N(0, accel_std^2) m/s^2 per axis, held over each
    scan of ``dt`` seconds); per axis [[T^4/4, T^3/2], [T^3/2, T^2]] sigma^2."""
    G = cv_gain(dt)
    return float(accel_std) ** 2 * (G @ G.T)
