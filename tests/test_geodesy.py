"""models.geodesy: WGS-84 geodetic -> ECEF -> local ENU against hand-checked points."""

import numpy as np

from radarbench.models.geodesy import WGS84_A_M, WGS84_F, geodetic_to_ecef, geodetic_to_enu

#: the polar radius b = a (1 - f)
B_M = WGS84_A_M * (1.0 - WGS84_F)


def test_ecef_of_a_hand_checked_point():
    """45 N 45 E on the ellipsoid: N = a / sqrt(1 - e^2 / 2) = 6 388 838.29 m, so
    X = Y = N / 2 and Z = N (1 - e^2) / sqrt(2) (worked by hand to the centimetre)."""
    np.testing.assert_allclose(geodetic_to_ecef(45.0, 45.0, 0.0), [3194419.145, 3194419.145, 4487348.409], atol=0.01)
    np.testing.assert_allclose(geodetic_to_ecef(0.0, 0.0, 100.0), [WGS84_A_M + 100.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(geodetic_to_ecef(90.0, 0.0, 0.0), [0.0, 0.0, B_M], atol=1e-6)


def test_enu_axes_at_the_equator():
    """Reference 0 N 0 E: up is +X, east +Y, north +Z of ECEF. A point 90 degrees east on
    the equator is a east and a down; the north pole is b north and a down."""
    np.testing.assert_allclose(geodetic_to_enu(0.0, 0.0, 100.0, 0.0, 0.0, 0.0), [0.0, 0.0, 100.0], atol=1e-6)
    np.testing.assert_allclose(geodetic_to_enu(0.0, 90.0, 0.0, 0.0, 0.0, 0.0), [WGS84_A_M, 0.0, -WGS84_A_M],
                               atol=1e-6)
    np.testing.assert_allclose(geodetic_to_enu(90.0, 0.0, 0.0, 0.0, 0.0, 0.0), [0.0, B_M, -WGS84_A_M], atol=1e-6)


def test_enu_preserves_distances_and_broadcasts():
    """A rotation: the ENU offset has the ECEF offset's length, for arrays of points."""
    lat, lon, alt = np.array([48.1, 48.3, 47.9]), np.array([11.5, 11.9, 11.2]), np.array([500.0, 3000.0, 0.0])
    enu = geodetic_to_enu(lat, lon, alt, 48.0, 11.6, 200.0)
    ecef = geodetic_to_ecef(lat, lon, alt) - geodetic_to_ecef(48.0, 11.6, 200.0)
    assert enu.shape == (3, 3)
    np.testing.assert_allclose(np.linalg.norm(enu, axis=-1), np.linalg.norm(ecef, axis=-1), rtol=1e-12)
    # 0.1 degree of latitude near 48 N is about 11.1 km north, almost nothing east
    small = geodetic_to_enu(48.1, 11.6, 200.0, 48.0, 11.6, 200.0)
    assert abs(small[0]) < 1e-6 and 11_100 < small[1] < 11_140 and abs(small[2]) < 10
