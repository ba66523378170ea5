r"""WGS-84 geodetic coordinates to a local east-north-up (ENU) frame, for recorded
tracks given in latitude / longitude / altitude (scenario ``recorded-tracks``;
docs/architecture.md, 'Models').

The textbook two-step conversion (e.g. Farrell & Barth, *The Global Positioning
System and Inertial Navigation*, 1999, sec. 2.3; Bar-Shalom, Li & Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, use the same
local-tangent-plane frame):

* geodetic $(\phi, \lambda, h)$ to Earth-centred Earth-fixed (ECEF), with the
  prime-vertical radius $N = a / \sqrt{1 - e^2 \sin^2 \phi}$:
  $X = (N + h) \cos\phi \cos\lambda$, $Y = (N + h) \cos\phi \sin\lambda$,
  $Z = (N (1 - e^2) + h) \sin\phi$;
* ECEF offset from a reference point to ENU at that point's $(\phi_0, \lambda_0)$:

$$
\begin{bmatrix} e \\ n \\ u \end{bmatrix} =
\begin{bmatrix}
  -\sin\lambda_0 & \cos\lambda_0 & 0 \\
  -\sin\phi_0 \cos\lambda_0 & -\sin\phi_0 \sin\lambda_0 & \cos\phi_0 \\
  \cos\phi_0 \cos\lambda_0 & \cos\phi_0 \sin\lambda_0 & \sin\phi_0
\end{bmatrix}
\begin{bmatrix} \Delta X \\ \Delta Y \\ \Delta Z \end{bmatrix}.
$$

Exact (no flat-earth approximation): a track hundreds of kilometres from its
reference point keeps its true distances in 3-D; its east/north plane is the
tangent plane at the reference point.
"""

from __future__ import annotations

import numpy as np

#: WGS-84 semi-major axis a (m) and flattening f (NIMA TR8350.2)
WGS84_A_M = 6_378_137.0
WGS84_F = 1.0 / 298.257223563
#: first eccentricity squared e^2 = f (2 - f)
WGS84_E2 = WGS84_F * (2.0 - WGS84_F)


def geodetic_to_ecef(lat_deg, lon_deg, alt_m) -> np.ndarray:
    """(..., 3) ECEF coordinates (m) of geodetic latitude, longitude (degrees) and
    height above the ellipsoid (m), broadcast together."""
    phi, lam = np.deg2rad(lat_deg), np.deg2rad(lon_deg)
    h = np.asarray(alt_m, float)
    sin_phi = np.sin(phi)
    N = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * sin_phi ** 2)
    return np.stack(np.broadcast_arrays((N + h) * np.cos(phi) * np.cos(lam), (N + h) * np.cos(phi) * np.sin(lam),
                                        (N * (1.0 - WGS84_E2) + h) * sin_phi), axis=-1)


def ecef_to_enu_rotation(lat0_deg: float, lon0_deg: float) -> np.ndarray:
    """(3, 3) rotation taking an ECEF offset to (east, north, up) at the reference point."""
    p, lam = np.deg2rad(lat0_deg), np.deg2rad(lon0_deg)
    sp, cp, sl, cl = np.sin(p), np.cos(p), np.sin(lam), np.cos(lam)
    return np.array([[-sl, cl, 0.0],
                     [-sp * cl, -sp * sl, cp],
                     [cp * cl, cp * sl, sp]])


def geodetic_to_enu(lat_deg, lon_deg, alt_m, lat0_deg: float, lon0_deg: float, alt0_m: float) -> np.ndarray:
    """(..., 3) east, north, up (m) of geodetic points relative to the reference
    point (lat0, lon0, alt0), in the tangent frame at that point."""
    offset = geodetic_to_ecef(lat_deg, lon_deg, alt_m) - geodetic_to_ecef(lat0_deg, lon0_deg, alt0_m)
    return offset @ ecef_to_enu_rotation(lat0_deg, lon0_deg).T
