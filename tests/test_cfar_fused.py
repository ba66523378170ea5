"""The fused window-CFAR kernel (models.cfar.window_cfar) is bit-identical to
its composition of steps, for CA, OS, GO and SO (models.cfar.window_cfar_composed: noise estimate per
axis, local maxima, significance, combination) and to the per-axis detectors
combined afterwards (models.cfar.fold), decisions and significances, for
random map sizes, windows, OS ranks, dimensions and peak boxes."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.models import cfar


@st.composite
def _cases(draw):
    detector = draw(st.sampled_from(["ca", "os", "go", "so"]))
    dimension = draw(st.sampled_from(["both", "either", "range", "doppler"]))
    R, D = draw(st.integers(8, 40)), draw(st.integers(8, 70))
    windows = {}
    for axis, M in (("range", R), ("doppler", D)):
        g = draw(st.integers(0, 3))
        L = draw(st.integers(1, max(1, min(12, M - 2 * g - 2))))
        windows[axis] = (L, g, draw(st.integers(1, 2 * L)))
    if draw(st.booleans()):                                      # equal N' along both axes (CA's one-log path)
        windows["doppler"] = windows["range"]
    active = ("range", "doppler") if dimension in ("both", "either") else (dimension,)
    peaks = draw(st.sampled_from([(0, 0), (1, 1), (2, 0), (0, 3), (2, 1)]))
    return detector, dimension, (draw(st.integers(1, 4)), R, D), {a: windows[a] for a in active}, peaks


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


@settings(derandomize=True, deadline=None, max_examples=100)
@given(case=_cases(), seed=st.integers(0, 2**32 - 1), clutter=st.booleans())
def test_fused_kernel_equals_the_composition_bit_for_bit(case, seed, clutter):
    detector, dimension, shape, windows, (half_range, half_doppler) = case
    for axis, (L, g, _) in windows.items():
        M = shape[1] if axis == "range" else shape[2]
        if cfar.axis_problem(M, L, g, axis):
            return                                               # refused by the method's scenario check
    rng = np.random.default_rng(seed)
    maps = rng.exponential(size=shape)
    if clutter:                                                  # ties, zeros and strong lines
        maps[:, :, shape[2] // 3] *= 1e4
        maps[:, shape[1] // 2] = 0.0
        maps = np.round(maps, 1)
    maps = maps.astype(np.float32)
    fused = cfar.window_cfar(maps, detector, windows, dimension, half_range, half_doppler)
    composed = cfar.window_cfar_composed(maps, detector, windows, dimension, half_range, half_doppler)
    for got, want in zip(fused, composed):
        assert got.dtype == np.float32 and got.shape == maps.shape
        np.testing.assert_array_equal(_bits(got), _bits(want))
    # the decisions at any threshold follow from the significances: identical too
    assert np.array_equal(fused[0] > 2.0, composed[0] > 2.0)
    # and both equal the per-axis detectors combined afterwards (cfar.fold, as the regression
    # CFAR does): checks the combined significance (one log where CA's two ratios are ordered)
    per_axis = {axis: cfar.axis_cfar(maps, detector, L, g, k, axis) for axis, (L, g, k) in windows.items()}
    folded = cfar.fold(maps, per_axis, dimension, half_range, half_doppler)
    for got, want in zip(fused, folded):
        np.testing.assert_array_equal(_bits(got), _bits(want))
