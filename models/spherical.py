r"""Spherical radar measurements of a Cartesian position: geometry and the
measurement model $h(p)$, its Jacobian and the angle-aware residual.

Frame and angles (the ``glint`` scenario's, and the trackers'): ENU, the sensor at the
origin, $x$ east, $y$ north, $z$ up (metres); bearing clockwise from north, in $(-\pi, \pi]$:

$$
r = \sqrt{x^2 + y^2 + z^2}, \qquad b = \operatorname{atan2}(x, y), \qquad
e = \operatorname{atan2}\big(z, \sqrt{x^2 + y^2}\big).
$$

A sensor measures some of $(r, b, e)$ (:data:`MEASURED`): an *active* radar all
three, a *passive* one the two angles. The measurement equation is
$z = h(p) + v$ with $h$ the selected components; an extended Kalman filter
linearises it with $H = \partial h / \partial p$ (:func:`measurement_jacobian`), and every
residual $z - h$ must wrap the bearing difference to $(-\pi, \pi]$
(:func:`measurement_residual`), otherwise a target near south ($b \approx \pm\pi$)
produces $2\pi$ innovations.
"""

from __future__ import annotations

import math

import numpy as np

#: measured components per sensor (range in m, angles in rad)
MEASUREMENT_LABELS = {"passive": ("bearing", "elevation"), "active": ("range", "bearing", "elevation")}
#: which of (range, bearing, elevation) each sensor measures
MEASURED = {"passive": (1, 2), "active": (0, 1, 2)}


def wrap_angle(a):
    """Angle(s) wrapped to (-pi, pi]."""
    a = np.asarray(a, float)
    w = np.mod(a + np.pi, 2.0 * np.pi) - np.pi          # [-pi, pi)
    return np.where(w == -np.pi, np.pi, w)


def los_basis(bearing: float, elevation: float) -> np.ndarray:
    """(3, 3) rows: unit vectors of increasing range, bearing and elevation at
    (bearing, elevation) (rad; bearing clockwise from north (+y), elevation
    above the horizontal). Orthonormal; ``R @ p`` gives line-of-sight
    coordinates, ``R.T @ q`` world coordinates."""
    sb, cb, se, ce = math.sin(bearing), math.cos(bearing), math.sin(elevation), math.cos(elevation)
    return np.array([[ce * sb, ce * cb, se],
                     [cb, -sb, 0.0],
                     [-se * sb, -se * cb, ce]])


def spherical(p) -> np.ndarray:
    """(..., 3) range (m), bearing (rad, clockwise from north = atan2(x, y)),
    elevation (rad) of positions ``p`` (..., 3) seen from the origin."""
    p = np.asarray(p, float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    rho = np.hypot(x, y)
    return np.stack([np.sqrt(rho ** 2 + z ** 2), np.arctan2(x, y), np.arctan2(z, rho)], axis=-1)


def measure(p, sensor: str) -> np.ndarray:
    """Noise-free measurement h(p) (..., m) of positions (..., 3)."""
    return spherical(p)[..., list(MEASURED[sensor])]


def measurement_jacobian(p, sensor: str) -> np.ndarray:
    """dh/dp (..., m, 3) of :func:`measure` at positions ``p`` (..., 3).

    With rho^2 = x^2 + y^2 and r^2 = rho^2 + z^2::

        dr/dp = (x, y, z) / r
        db/dp = (y, -x, 0) / rho^2
        de/dp = (-x z / rho, -y z / rho, rho) / r^2
    """
    p = np.asarray(p, float)
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    rho2 = x ** 2 + y ** 2
    rho = np.sqrt(rho2)
    r2 = rho2 + z ** 2
    r = np.sqrt(r2)
    zero = np.zeros_like(x)
    d_range = np.stack([x / r, y / r, z / r], axis=-1)
    d_bearing = np.stack([y / rho2, -x / rho2, zero], axis=-1)
    d_elev = np.stack([-x * z / (r2 * rho), -y * z / (r2 * rho), rho / r2], axis=-1)
    rows = (d_range, d_bearing, d_elev)
    return np.stack([rows[i] for i in MEASURED[sensor]], axis=-2)


def measurement_residual(z, zhat):
    """z - zhat with the bearing difference wrapped to (-pi, pi]; works for
    both sensors (bearing is the next-to-last component) and any leading axes."""
    res = np.asarray(z, float) - np.asarray(zhat, float)
    res[..., -2] = wrap_angle(res[..., -2])
    return res
