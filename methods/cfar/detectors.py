"""Methods ``ca-cfar``, ``os-cfar``, ``regression-cfar`` and ``region-adaptive``:
the CFAR detectors of an HF surface-wave radar on range-Doppler power maps,
and ``go-cfar``, ``so-cfar``, the greatest-of and smallest-of baselines
(task ``cell-detection``; docs/architecture.md, 'Tasks').

After "目标检测与跟踪方法-海洋遥感技术应用" (the shared paper
hfswr-cfar-mn-jpda-ukf), sec. 1 "CFAR检测": CFAR along range and along
Doppler, the two results combined, then a peak detection; three detectors,
each suited to a background ("CA-CFAR suits regions of homogeneous noise
... OS-CFAR has some ability to suppress weak clutter ... the adaptive
regression CFAR suppresses ionospheric interference and low-speed clutter
to some degree, but in homogeneous regions detects worse than CA and OS";
and "segment the RD map first, identify the clutter regions, then choose
the CFAR method suited to each"). The maths (windows, kernels, closed forms,
the regression fit) is in :mod:`models.cfar` and :mod:`models.cfar.regression`;
the straightforward SciPy
implementations ``bench perf`` times them against are in
:mod:`methods.cfar.reference`.

Every method returns a :class:`~bench.tasks.cells.CellDetectionOutput`
whose statistic is the nominal significance S = -log10 Pfa(x / mu) per cell
(:mod:`models.cfar`), with the range/Doppler combination and the peak
detection folded in (cells that are not local maxima hold 0); the nominal
threshold is -log10(pfa) for all of them. ``threshold_factor(params, pfa)``
gives the K of the closed form, U0 = K mu.

**Peak detection.** The document combines the CFAR result "with the result
of a peak detection" (结合峰值检测的结果) and prints no neighbourhood: here a
cell survives if its power is the largest in the box of +-``peak_range``
range and +-``peak_doppler`` Doppler cells (our default +-1, a 3 x 3 box;
0 and 0 turn it off). It lowers the measured Pfa below the nominal (a
noise cell must also be a local maximum), as does ``dimension = "both"``
(a cell must pass twice); the calibration table shows by how much.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from radarbench.bench.core import Batch, Method
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import param
from radarbench.bench.registry import register_method
from radarbench.bench.tasks.cells import CELL_DETECTION, CellDetectionOutput
from radarbench.methods.cfar import reference
from radarbench.models import cfar
from radarbench.models.cfar import halves, regression

#: the longest reference half-window (cells per side); the axis must hold it (checked per scenario)
MAX_REFERENCE = 256
#: the widest guard (cells per side)
MAX_GUARD = 64
DIMENSIONS = ("range", "doppler", "both", "either")
DETECTORS = ("ca", "os", "regression")


def _reference(default: int, axis: str):
    return param(default, f"reference cells per side along {axis} (L; N = 2L)", ge=1, le=MAX_REFERENCE,
                 why=f"one cell per side at least; at most {MAX_REFERENCE} per side, and the map's {axis} "
                     "axis must hold the window (checked per scenario config)")


def _guard(default: int, axis: str):
    return param(default, f"guard cells per side along {axis}, between the cell under test and its "
                          "reference cells (the document prints none: 0)", ge=0, le=MAX_GUARD,
                 why=f"none to {MAX_GUARD} per side; every cell must keep a reference cell (checked per "
                     "scenario config)")


def _peak(axis: str):
    return param(1, f"peak detection: half-width of the local-maximum box along {axis} (cells; 0 with "
                    "the other 0: no peak detection; the document prints none)", ge=0, le=64,
                 why="none to 64 cells, a box far wider than any target's spread")


def _dimension(default: str):
    return param(default, "range or doppler alone; both: a cell must pass along range and along Doppler "
                          "(our reading of the chapter's 综合, 'combine'); either: along one of them",
                 choices=DIMENSIONS)


def _order(default: int):
    return param(default, "polynomial order of the fitted curve", ge=0, le=12,
                 why="a constant to order 12 (Legendre basis, well conditioned); the fitted axis must "
                     "have at least 2 (order + 1) cells (checked per scenario config)")


def _family():
    return param("log-polynomial", "curve family: log-polynomial (least squares in the log power, "
                                   "ours) or polynomial (in the linear power, ours); the document prints none",
                 choices=regression.FAMILIES)


def _iterations():
    return param(2, "robust iterations: refits leaving out cells above exclusion_factor times the "
                    "noise level (ours; 0: the plain least-squares fit)", ge=0, le=10,
                 why="none to 10 refits; the fit settles in two or three")


def _exclusion():
    return param(4.6, "robust iterations leave out cells above this many times the noise level "
                      "(4.6 = -ln 0.01: 1 % of exponential noise cells)", ge=1.0, le=1000.0,
                 why="at least the noise level itself; up to 30 dB above it")


def curve_of(params) -> regression.Curve:
    """The regression curve of a method's parameters (``family``, ``order``, ``iterations``, ``exclusion_factor``)."""
    return regression.Curve(params.family, params.order, params.iterations, params.exclusion_factor)


def _k(axis: str):
    return param(12, f"OS order k along {axis}: the k-th smallest of the N = 2L reference cells is mu "
                     "(the document prints no k; 12 of N = 16 is the common 3N/4)", ge=1, le=2 * MAX_REFERENCE,
                 why=f"1 to N = 2L (checked against reference_{axis.lower()})")


def _check_k(k: int, L: int, name: str) -> None:
    if k > 2 * L:
        raise ConfigError(name, f"k = {k} exceeds the N = {2 * L} reference cells")


def map_shape(scenario_params) -> tuple[int | None, int | None]:
    """(R, D) of a map scenario config (``range_cells``, ``doppler_cells``), None where unknown."""
    R, D = getattr(scenario_params, "range_cells", None), getattr(scenario_params, "doppler_cells", None)
    return (R if isinstance(R, int) else None, D if isinstance(D, int) else None)


def active_axes(dimension: str) -> tuple[str, ...]:
    return (dimension,) if dimension in ("range", "doppler") else ("range", "doppler")


def maps_of(batch: Batch) -> np.ndarray:
    """The batch's maps (n, R, D) float32 (z is (n, 1, R, D): one step)."""
    return np.ascontiguousarray(batch.z[:, 0], dtype=np.float32)


def window_problem(params, scenario_params) -> str | None:
    """A window along an active axis that leaves some cell without reference cells."""
    R, D = map_shape(scenario_params)
    for axis in active_axes(params.dimension):
        M = R if axis == "range" else D
        if M is not None:
            problem = cfar.axis_problem(M, getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"),
                                        f"{axis} ({M} cells)")
            if problem:
                return problem
    return None


def regression_problem(order: int, dimension: str, scenario_params) -> str | None:
    R, D = map_shape(scenario_params)
    for axis in active_axes(dimension):
        M = R if axis == "range" else D
        if M is not None and M < 2 * (order + 1):
            return f"a curve of order {order} along {axis} needs at least {2 * (order + 1)} cells, the map has {M}"
    return None


def finish(method, maps: np.ndarray, per_axis: dict, dimension: str, params,
           keep: np.ndarray) -> CellDetectionOutput:
    """The dimensions combined, the peak detection's local maxima ``keep``
    folded in (:func:`models.cfar.fold`), and the method's per-cell threshold
    factor for the recording's threshold map."""
    statistic, mu = cfar.fold(maps, per_axis, dimension, params.peak_range, params.peak_doppler,
                              peaks=lambda *_: keep)
    return CellDetectionOutput(statistic=statistic, noise_estimate=mu,
                               threshold_factor=partial(method.factor_map, params, shape=maps.shape[1:]))


def window_output(method, maps: np.ndarray, detector: str, params) -> CellDetectionOutput:
    """CA or OS over the active dimensions (:func:`models.cfar.window_cfar`)."""
    windows = {axis: (getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"),
                      getattr(params, f"k_{axis}", 0)) for axis in active_axes(params.dimension)}
    statistic, mu = cfar.window_cfar(maps, detector, windows, params.dimension, params.peak_range,
                                     params.peak_doppler)
    return CellDetectionOutput(statistic=statistic, noise_estimate=mu,
                               threshold_factor=partial(method.factor_map, params, shape=maps.shape[1:]))


def factors_combined(per_axis: dict[str, np.ndarray], dimension: str, shape: tuple[int, int]) -> np.ndarray:
    """(R, D) K from per-axis (M,) factors: for "both" the larger of the two
    (with the larger noise estimate, :func:`models.cfar.combine`, the threshold
    map mu K is the binding one where the two windows' N' agree; an
    approximation where they differ), for "either" the smaller."""
    along = {"range": lambda K: K[:, None], "doppler": lambda K: K[None, :]}
    maps = [np.broadcast_to(along[axis](K), shape) for axis, K in per_axis.items()]
    if len(maps) == 1:
        return np.array(maps[0])
    return np.maximum(*maps) if dimension == "both" else np.minimum(*maps)


class CfarMethod(Method):
    """What the CFAR methods share: the task, the nominal threshold, the
    memory estimate, the pair check."""

    task = CELL_DETECTION

    def nominal_threshold(self, params, pfa: float, batch: Batch) -> float:
        """-log10(pfa): every statistic is on the scale of nominal significance."""
        return float(-np.log10(pfa))

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        R, D = map_shape(scenario_params)
        if R is None or D is None:
            return None
        return int(n * R * D * 4 * 10)              # float32 maps: per-dimension estimates and significances

    def check_scenario(self, params, scenario_params) -> str | None:
        return window_problem(params, scenario_params)

    def work(self, batch: Batch, params) -> tuple[str, float]:
        """("cells", range x Doppler cells x maps): the cells under test of the batch."""
        return "cells", float(np.prod(batch.z.shape[:1] + batch.z.shape[2:]))

    def least_cost(self, batch: Batch, params, output: CellDetectionOutput) -> dict[str, float]:
        """Bytes: every map read once (float32, :func:`maps_of`) and the statistic and noise
        estimate maps written once; the windows' sums, selections and fits are not counted
        (no floor of them holds for every CFAR here), so this is a memory-bandwidth floor."""
        cells = float(np.prod(batch.z.shape[:1] + batch.z.shape[2:]))
        return {"bytes": cells * np.dtype(np.float32).itemsize + output.statistic.nbytes
                + output.noise_estimate.nbytes}

    def threshold_factors(self, params, pfa: float) -> dict[str, float]:
        """K per active dimension for ``pfa`` at the full window."""
        return {axis: self.axis_factor(params, pfa, axis) for axis in active_axes(params.dimension)}

    def threshold_factor(self, params, pfa: float) -> float:
        """K of the first active dimension (range for "both"/"either") at the full window."""
        return next(iter(self.threshold_factors(params, pfa).values()))

    def axis_factor(self, params, pfa: float, axis: str) -> float:
        raise NotImplementedError

    def factor_map(self, params, pfa: float, shape: tuple[int, int]) -> np.ndarray:
        """(R, D) K per cell at its own window (edges included), the dimensions combined."""
        return factors_combined({axis: self.axis_factors(params, pfa, shape[0 if axis == "range" else 1], axis)
                                 for axis in active_axes(params.dimension)}, params.dimension, shape)

    def axis_factors(self, params, pfa: float, M: int, axis: str) -> np.ndarray:
        raise NotImplementedError


@register_method
class CaCfar(CfarMethod):
    r"""Cell-averaging CFAR along range and Doppler (running sums), combined, with peak detection.

    Per dimension, $\mu = \frac{1}{N'} \sum x_i$ over the $N'$ reference cells in the map
    ($N' = 2L$ inside, fewer at the edges), $U_0 = K\mu$ ("对被检测单元周围N个
    参考单元求均值,其结果便为噪声估计μ,检测门限U0=Kμ"), and under homogeneous
    exponential noise

    $$
    P_{fa}(K) = (1 + K/N')^{-N'}, \qquad S = N' \log_{10}(1 + t/N'), \quad t = x/\mu
    $$

    (:func:`models.cfar.ca_cfar`, $O(1)$ per cell).
    """

    name = "ca-cfar"
    reference_name = ("SciPy running sums (scipy.ndimage.uniform_filter1d: the window's block less the guard "
                      "block), NumPy significance")
    perf_targets = {"*": {"speedup": 10.0}}

    @dataclass(frozen=True)
    class Params:
        reference_range: int = _reference(8, "range")
        guard_range: int = _guard(1, "range")
        reference_doppler: int = _reference(8, "Doppler")
        guard_doppler: int = _guard(2, "Doppler")
        dimension: str = _dimension("both")
        peak_range: int = _peak("range")
        peak_doppler: int = _peak("Doppler")

    def run(self, batch: Batch, params) -> CellDetectionOutput:
        return window_output(self, maps_of(batch), "ca", params)

    def reference_run(self, batch: Batch, params) -> CellDetectionOutput:
        return reference.ca(maps_of(batch), params)

    def axis_factor(self, params, pfa: float, axis: str) -> float:
        return cfar.ca_threshold_factor(pfa, 2 * getattr(params, f"reference_{axis}"))

    def axis_factors(self, params, pfa: float, M: int, axis: str) -> np.ndarray:
        return cfar.ca_factor_along(pfa, M, getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"))


@register_method
class OsCfar(CfarMethod):
    r"""Order-statistic CFAR along range and Doppler (numba selection kernel), combined, with peak detection.

    Per dimension, $\mu = x_{(k)}$, the $k$-th smallest of the $N = 2L$ reference cells
    ("将参考单元中N(N=2L)个信号的值排序,取出其中第k个最小值xk,xk即为噪声估计值μ"),
    $U_0 = K\mu$, and under homogeneous exponential noise (:func:`models.cfar.os_cfar`)

    $$
    P_{fa}(K) = \prod_{i=0}^{k-1} \frac{N - i}{N - i + K}.
    $$

    At the map's edges the window holds $N' < N$ cells and $k' = \lceil k N'/N \rceil$. The
    document prints no $k$; our default $k = 12$ of $N = 16$ is the common $3N/4$.
    """

    name = "os-cfar"
    reference_name = ("scipy.ndimage.rank_filter with the window's footprint (guard cells excluded), "
                      "np.partition at the edges, NumPy significance")
    perf_targets = {"*": {"speedup": 10.0}}

    @dataclass(frozen=True)
    class Params:
        reference_range: int = _reference(8, "range")
        guard_range: int = _guard(1, "range")
        k_range: int = _k("range")
        reference_doppler: int = _reference(8, "Doppler")
        guard_doppler: int = _guard(2, "Doppler")
        k_doppler: int = _k("Doppler")
        dimension: str = _dimension("both")
        peak_range: int = _peak("range")
        peak_doppler: int = _peak("Doppler")

        def validate(self) -> None:
            _check_k(self.k_range, self.reference_range, "k_range")
            _check_k(self.k_doppler, self.reference_doppler, "k_doppler")

    def run(self, batch: Batch, params) -> CellDetectionOutput:
        return window_output(self, maps_of(batch), "os", params)

    def reference_run(self, batch: Batch, params) -> CellDetectionOutput:
        return reference.os(maps_of(batch), params)

    def axis_factor(self, params, pfa: float, axis: str) -> float:
        return cfar.os_threshold_factor(pfa, 2 * getattr(params, f"reference_{axis}"), getattr(params, f"k_{axis}"))

    def axis_factors(self, params, pfa: float, M: int, axis: str) -> np.ndarray:
        return cfar.os_factor_along(pfa, M, getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"),
                                    getattr(params, f"k_{axis}"))


class HalvesCfar(CfarMethod):
    r"""GO- or SO-CFAR (:attr:`detector`): along range and along Doppler, the
    larger or the smaller of the two half-windows' means is $\mu$, combined, with
    peak detection.

    Not in the HFSWR chapter (which names CA, OS and regression): the
    classical answers to CA's two weaknesses it names, "at clutter edges and
    with multiple targets the noise estimate is too high": GO takes the
    greater half to hold the false alarms down at a clutter edge (Hansen &
    Sawyers, "Detectability loss due to 'greatest of' selection in a
    cell-averaging CFAR", 1980), SO the smaller to keep a neighbouring target
    in one half from masking the cell under test (Trunk, "Range resolution of
    targets using automatic detectors", 1978); both analysed in Gandhi &
    Kassam, "Analysis of CFAR processors in nonhomogeneous background", 1988. Per dimension, with the leading half
    ($L$ cells behind $g$ guard cells before the cell under test) and the lagging
    half (after it), each cut at the map's edges ($n_l$, $n_r$ cells; one empty:
    the other alone, CA's estimate), $m = \frac{1}{n} \sum$ of a half and $U_0 = T \mu$ with

    $$
    \mu = \max(m_l, m_r) \ \text{(GO)} \quad \text{or} \quad \min(m_l, m_r) \ \text{(SO)};
    $$

    under homogeneous exponential noise, with $p_a = (n_a + T)/(N + T)$, $q_a = 1 - p_a$,

    $$
    \begin{aligned}
    P_{fa}^{GO}(T) &= \sum_{a \in \{l, r\}} (1 + T/n_a)^{-n_a}\, I_{q_a}(n_o, n_a), \\
    P_{fa}^{SO}(T) &= \sum_{a \in \{l, r\}} (1 + T/n_a)^{-n_a}\, I_{p_a}(n_a, n_o)
    \end{aligned}
    $$

    ($I$ the regularised incomplete beta function, $o$ the other half; at
    $n_l = n_r = n$, $P_{fa}^{SO} = 2 \sum_{k<n} \binom{n - 1 + k}{k} (2 + T/n)^{-(n + k)}$ and
    $P_{fa}^{GO} = 2 (1 + T/n)^{-n} - P_{fa}^{SO}$; :mod:`models.cfar.halves`), and the
    statistic is $S = -\log_{10} P_{fa}(x / \mu)$ per cell; $T$ for a Pfa by root-finding.
    """

    detector = ""
    reference_name = ("SciPy running sums of each half-window (scipy.ndimage.uniform_filter1d), NumPy max/min, "
                      "significance by scipy.special.betainc")
    perf_targets = {"*": {"speedup": 10.0}}

    Params = CaCfar.Params                      # CA's windows, split in two halves

    def run(self, batch: Batch, params) -> CellDetectionOutput:
        return window_output(self, maps_of(batch), self.detector, params)

    def reference_run(self, batch: Batch, params) -> CellDetectionOutput:
        return reference.halves(maps_of(batch), params, self.detector)

    def axis_factor(self, params, pfa: float, axis: str) -> float:
        L = getattr(params, f"reference_{axis}")
        return halves.halves_threshold_factor(pfa, L, L, self.detector == "go")

    def axis_factors(self, params, pfa: float, M: int, axis: str) -> np.ndarray:
        left, right = cfar.window_counts(M, getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}"))
        return halves.halves_factor_along(pfa, left, right, self.detector == "go")


@register_method
class GoCfar(HalvesCfar):
    """Greatest-of CFAR: :class:`HalvesCfar` with the larger half-window mean per dimension."""

    name = "go-cfar"
    detector = "go"


@register_method
class SoCfar(HalvesCfar):
    """Smallest-of CFAR: :class:`HalvesCfar` with the smaller half-window mean per dimension."""

    name = "so-cfar"
    detector = "so"


@register_method
class RegressionCfar(CfarMethod):
    r"""Adaptive regression CFAR: a curve fitted to each power spectrum is the noise estimate.

    "The adaptive regression detector fits the power spectrum by curve
    regression; the fit is the noise estimate, times the threshold factor $K$
    the threshold" (自适应回归检测器采用曲线回归方法拟合功率谱,获得噪声整体估计 ...
    将噪声估计值乘以门限因子K获得检测门限). The power spectrum of a range cell
    is its Doppler line, so the default fits along Doppler (``dimension``
    "range" fits along range, "both"/"either" combine the two). The document
    prints no curve: ours are a least-squares polynomial of ``order``
    (Legendre basis) in the log power (``family`` "log-polynomial", the
    default: strong narrow clutter lines barely lift it) or in the linear
    power ("polynomial", the ablation), optionally refitted without the
    cells far above the noise level (``iterations``, ``exclusion_factor``;
    :func:`models.cfar.regression.regression_fit`). The noise level is the
    fit corrected by the mean of the fitted variable over the cells it
    keeps ($e^{f + \gamma}$ for the plain log fit $f$, $\gamma$ Euler's constant), so it is unbiased in
    homogeneous noise.

    Nominal significance: derived, not calibrated, from each cell's
    leverage under homogeneous exponential noise
    (:func:`models.cfar.regression.significance`): exact for the linear
    family at order 0 without robust iterations, approximate otherwise.
    Measured on 400 x 64 lines of 256 homogeneous cells (measured / nominal
    Pfa at 1e-2, 1e-3, 1e-4; about +-4 % sampling error at 1e-4), order 4:
    log-polynomial plain 1.01, 1.04, 1.16, with 2 robust iterations 1.07,
    1.26, 1.67; polynomial plain 1.01, 1.03, 1.14, robust 0.98, 1.16, 1.64
    (the deeper the tail, the more the approximations understate it).
    ``threshold_factor`` is $K$ at the mean leverage
    $(\text{order} + 1)/M$ of an $M$-cell line.
    """

    name = "regression-cfar"
    # No bench perf reference: the fit (models.cfar.regression.regression_fit) is already the
    # vectorised NumPy a user would write (the normal equations of every line in one matmul),
    # so the nearest plain peer is this code itself; the per-line lstsq loop of
    # methods.cfar.reference.regression is the tests' oracle only.

    @dataclass(frozen=True)
    class Params:
        family: str = _family()
        order: int = _order(4)
        iterations: int = _iterations()
        exclusion_factor: float = _exclusion()
        dimension: str = _dimension("doppler")
        peak_range: int = _peak("range")
        peak_doppler: int = _peak("Doppler")

    def run(self, batch: Batch, params) -> CellDetectionOutput:
        maps = maps_of(batch)
        keep = cfar.local_maxima(maps, params.peak_range, params.peak_doppler)     # the significance is paid there only
        per_axis = {axis: regression.regression_cfar(maps, curve_of(params), axis, keep)
                    for axis in active_axes(params.dimension)}
        return finish(self, maps, per_axis, params.dimension, params, keep)

    def check_scenario(self, params, scenario_params) -> str | None:
        return regression_problem(params.order, params.dimension, scenario_params)

    def unit_memory_bytes(self, params, scenario_params, n: int) -> int | None:
        R, D = map_shape(scenario_params)
        if R is None or D is None:
            return None
        return int(n * R * D * 8 * (2 * (params.order + 1) + 12))    # float64 design products, fit, leverage

    def threshold_factors(self, params, pfa: float, cells: int = 256) -> dict[str, float]:
        """K at the mean leverage (order + 1)/M of a line of M = ``cells`` cells."""
        h = (params.order + 1) / cells
        return {axis: regression.threshold_factor(pfa, h, curve_of(params))
                for axis in active_axes(params.dimension)}

    def axis_factors(self, params, pfa: float, M: int, axis: str) -> np.ndarray:
        return regression.factor_along(pfa, M, curve_of(params))


@register_method
class RegionAdaptive(CfarMethod):
    """Per clutter region the detector the document recommends: CA, OS or regression, one threshold for all.

    "Segment the RD map first, identify the clutter regions, then choose the
    CFAR method suited to each clutter type" (可以先对RD谱进行分割,识别出不同杂波区,
    然后基于不同杂波类型选择适合的CFAR检测方法). The segmentation here is the
    scene's true region labels (an oracle segmentation: the best any
    segmenter could do). Per region name, a parameter picks the detector;
    the defaults read the document: CA in homogeneous noise, regression in
    the ionospheric interference, OS at the Bragg lines and the clutter
    edge (the document says OS "suppresses weak clutter" and degrades in
    strong clutter, and that regression helps against "low-speed clutter";
    for the Bragg region the text supports OS or regression, so it is a
    parameter). All statistics are nominal significances, so the per-cell
    choice needs one threshold; the peak detection runs once on the result.
    """

    name = "region-adaptive"

    @dataclass(frozen=True)
    class Params(OsCfar.Params):
        """The CA and OS windows (OS-CFAR's parameters, shared), then the
        per-region choice and the regression's parameters."""

        homogeneous: str = param("ca", "detector in the homogeneous region", choices=DETECTORS)
        bragg: str = param("os", "detector at the first-order Bragg lines", choices=DETECTORS)
        interference: str = param("regression", "detector in the ionospheric interference band", choices=DETECTORS)
        clutter_edge: str = param("os", "detector at the clutter edge", choices=DETECTORS)
        family: str = _family()
        order: int = _order(4)
        iterations: int = _iterations()
        exclusion_factor: float = _exclusion()
        regression_dimension: str = _dimension("doppler")

    def run(self, batch: Batch, params) -> CellDetectionOutput:
        maps = maps_of(batch)
        choice = self.detector_map(batch.scene, params)
        keep = cfar.local_maxima(maps, params.peak_range, params.peak_doppler)
        sig = np.zeros(maps.shape, dtype=np.float32)
        mu = np.zeros(maps.shape, dtype=np.float32)
        for detector in DETECTORS:
            where = choice == detector
            if where.any():
                s, m = self._detector(detector, maps, params, keep & where)
                sig[:, where], mu[:, where] = s[:, where], m[:, where]
        return CellDetectionOutput(statistic=cfar.with_peaks(maps, sig, params.peak_range, params.peak_doppler,
                                                             peaks=lambda *_: keep),
                                   noise_estimate=mu, threshold_factor=partial(self.factor_map, params,
                                                                              shape=maps.shape[1:], choice=choice))

    @staticmethod
    def detector_map(scene, params) -> np.ndarray:
        """(R, D) the detector name of every cell, from its region's name (the two
        sides of a split clutter edge take the clutter edge's detector)."""
        names = np.array([getattr(params, "clutter_edge" if name.startswith("clutter-edge") else name.replace("-", "_"))
                          for name in scene.region_names])
        return names[np.asarray(scene.region_labels, dtype=np.intp)]

    @staticmethod
    def _detector(detector: str, maps: np.ndarray, params, keep: np.ndarray):
        """(significance, noise estimate) of one detector over the whole maps
        (the regression's significance only where ``keep``: the kept cells of its regions)."""
        if detector == "regression":
            per_axis = {axis: regression.regression_cfar(maps, curve_of(params), axis, keep)
                        for axis in active_axes(params.regression_dimension)}
            return cfar.combine(per_axis, params.regression_dimension)
        per_axis = {}
        for axis in active_axes(params.dimension):
            L, g = getattr(params, f"reference_{axis}"), getattr(params, f"guard_{axis}")
            per_axis[axis] = (cfar.ca_cfar(maps, L, g, axis) if detector == "ca"
                              else cfar.os_cfar(maps, L, g, getattr(params, f"k_{axis}"), axis))
        return cfar.combine(per_axis, params.dimension)

    def check_scenario(self, params, scenario_params) -> str | None:
        return window_problem(params, scenario_params) or regression_problem(
            params.order, params.regression_dimension, scenario_params)

    def factor_map(self, params, pfa: float, shape: tuple[int, int], choice: np.ndarray | None = None) -> np.ndarray:
        """(R, D) K per cell of the detector its region uses (``choice``, from
        :meth:`detector_map`; None: CA everywhere)."""
        K = np.zeros(shape)
        for detector, method in (("ca", CaCfar()), ("os", OsCfar()), ("regression", RegressionCfar())):
            where = np.full(shape, detector == "ca") if choice is None else choice == detector
            if where.any():
                dimension = params.regression_dimension if detector == "regression" else params.dimension
                per_axis = {axis: method.axis_factors(params, pfa, shape[0 if axis == "range" else 1], axis)
                            for axis in active_axes(dimension)}
                K[where] = factors_combined(per_axis, dimension, shape)[where]
        return K

    def threshold_factors(self, params, pfa: float) -> dict[str, float]:
        """K of the CA detector per active dimension (the others' differ; see their methods)."""
        return {axis: cfar.ca_threshold_factor(pfa, 2 * getattr(params, f"reference_{axis}"))
                for axis in active_axes(params.dimension)}

