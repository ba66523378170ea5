"""Spherical measurement model: Jacobian, angle wrapping, the sensors' components."""

import numpy as np

from radarbench.models.spherical import MEASURED, los_basis, measure, measurement_jacobian, measurement_residual, wrap_angle


def test_spherical_jacobian_matches_finite_differences():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(20, 3)) * 3000.0
    for sensor in ("passive", "active"):
        H = measurement_jacobian(p, sensor)
        h = 1e-4
        num = np.stack([(measure(p + h * np.eye(3)[i], sensor) - measure(p - h * np.eye(3)[i], sensor)) / (2 * h)
                        for i in range(3)], axis=-1)
        np.testing.assert_allclose(H, num, rtol=1e-6, atol=1e-12)


def test_wrap_angle():
    a = np.array([-3 * np.pi, -np.pi, 0.0, np.pi, 2 * np.pi + 0.1, -np.pi - 0.1])
    np.testing.assert_allclose(wrap_angle(a), [np.pi, np.pi, 0.0, np.pi, 0.1, np.pi - 0.1], atol=1e-12)


def test_measured_components():
    assert MEASURED == {"passive": (1, 2), "active": (0, 1, 2)}


def test_line_of_sight_basis_is_orthonormal_and_points_along_the_range():
    R = los_basis(0.7, -0.3)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    p = 4000.0 * R[0]
    np.testing.assert_allclose(measure(p, "active"), [4000.0, 0.7, -0.3], rtol=1e-12)


def test_residual_wraps_the_bearing_only():
    z = np.array([100.0, np.pi - 0.01, 0.2])
    zhat = np.array([90.0, -np.pi + 0.01, 0.1])
    np.testing.assert_allclose(measurement_residual(z, zhat), [10.0, -0.02, 0.1], atol=1e-12)
