r"""CFAR detector maths on range-Doppler power maps: reference windows, the
CA and OS noise estimates over a whole batch of maps, their closed-form
false-alarm probabilities, and the nominal significance every CFAR method
of the ``cell-detection`` task reports (docs/architecture.md, 'Models').

The detectors are the three of the HFSWR detection chain ("目标检测与跟踪方法
-海洋遥感技术应用", sec. 1 "CFAR检测", in the shared papers as
hfswr-cfar-mn-jpda-ukf): CFAR "done along range and along Doppler
separately, then the two results combined, with the result of a peak
detection" (地波雷达的CFAR检测处理通常在距离向和多普勒向分别进行 ... 再综合距离向、
多普勒向检测结果,结合峰值检测的结果). Per dimension a cell under test $x_D$ is
compared with $U_0 = K\mu$:

* CA: "$\mu$ = the mean of the $N$ reference cells around the cell under test,
  $U_0 = K\mu$" (对被检测单元周围N个参考单元求均值,其结果便为噪声估计μ,检测门限U0=Kμ);
* OS: "the $N$ ($N = 2L$) reference cells, $L$ on each side of $x_D$, are sorted and
  the $k$-th smallest $x_k$ is the noise estimate $\mu$; $U_0 = K\mu$"
  (将参考单元中N(N=2L)个信号的值排序,取出其中第k个最小值xk,xk即为噪声估计值μ).

The third detector, the adaptive regression CFAR, fits a curve instead of
a window: :mod:`models.cfar.regression`.

The CA text says the register holds $N = 2L + 1$ cells and averages "the $N$
reference cells"; the register of $2L + 1$ includes the cell under test, so
both detectors here use $N = 2L$ reference cells, $L$ per side, as the OS text
prints. The document prints no guard cells: ``guard`` cells per side
between the cell under test and its reference cells are our parameter
(guard = 0 is the printed structure).

**Windows and map edges.** Along an axis of $M$ cells, the cell $i$ has its
reference cells at $i - g - L, \dots, i - g - 1$ and $i + g + 1, \dots, i + g + L$; those
outside the map are dropped (one-sided windows at the edges), so the cell's
$N' = N_{\text{left}} + N_{\text{right}} \le 2L$, and its closed form uses that $N'$. OS keeps its
quantile at the edges: $k' = \lceil k N' / N \rceil$ (:func:`edge_rank`).

**Nominal significance.** For square-law detected (exponential) noise of
any level, the false-alarm probability of "$x > K\mu$" is (Rohling's closed
forms, as the HFSWR chapter's sources give them)

$$
P_{fa}^{CA}(K) = (1 + K/N)^{-N}, \qquad
P_{fa}^{OS}(K) = \prod_{i=0}^{k-1} \frac{N - i}{N - i + K},
$$

and each method reports, per cell, $S = -\log_{10} P_{fa}(t)$ at the observed ratio
$t = x / \mu$ (:func:`ca_significance`, :func:`os_significance`): a monotone
transform of $t$, so "$S > -\log_{10} P_{fa}$" is exactly "$t > K(P_{fa})$" and one
threshold serves every detector, window and dimension. $S$ is capped at
:data:`MAX_SIGNIFICANCE` ($P_{fa} = 10^{-300}$, the smallest the calibration takes).

GO and SO (the larger or smaller of the two half-windows' means, our
baselines beside the chapter's detectors) share CA's windows and running
sums; their maths is in :mod:`models.cfar.halves`.

All kernels take a batch of maps with a leading trial axis; the per-axis
ones run along axis 1 of a (P, A, B) array (the Doppler axis on the
transposed maps), and :func:`window_cfar` runs a detector in one fused pass
per map (CA, GO, SO streamed row by row, :func:`_sum_cfar_rows`; OS,
:func:`_os_cfar_fused`), bit-identical to its composed steps
(:func:`window_cfar_composed`, the readable oracle). The order-statistic
machinery is in :mod:`models.cfar.order_statistic`, the peak detection in
:mod:`models.cfar.peaks`. Single-threaded and free of
shared state (parallelism comes from the harness's worker processes; ``bench
perf`` measures one core).

The package's modules: :mod:`.windows` (windows, edges, closed forms), :mod:`.estimates`
(the per-axis noise estimates and significance), :mod:`.fused` (one pass per map, the
combination, the peaks folded in), :mod:`.halves` (GO, SO), :mod:`.order_statistic`,
:mod:`.peaks`, :mod:`.regression`; the names the methods use are re-exported here.
"""

from radarbench.models.cfar.estimates import (CA, DETECTOR_CODES, GO, OS, SO, SUM_DETECTORS, axis_cfar, ca_cfar,
                                             halves_cfar, os_cfar, sum_inverses, window_noise, window_significance)
from radarbench.models.cfar.fused import ROW_BLOCK, combine, fold, window_cfar, window_cfar_composed
from radarbench.models.cfar.peaks import local_maxima, local_maxima_scipy, with_peaks
from radarbench.models.cfar.windows import (MAX_SIGNIFICANCE, axis_problem, ca_factor_along, ca_pfa, ca_significance,
                                           ca_threshold_factor, edge_rank, os_factor_along, os_pfa, os_significance,
                                           os_threshold_factor, reference_counts, window_counts)

__all__ = ["CA", "DETECTOR_CODES", "GO", "MAX_SIGNIFICANCE", "OS", "ROW_BLOCK", "SO", "SUM_DETECTORS", "axis_cfar",
           "axis_problem", "ca_cfar", "ca_factor_along", "ca_pfa", "ca_significance", "ca_threshold_factor", "combine",
           "edge_rank", "fold", "halves_cfar", "local_maxima", "local_maxima_scipy", "os_cfar", "os_factor_along",
           "os_pfa", "os_significance", "os_threshold_factor", "reference_counts", "sum_inverses", "window_cfar",
           "window_cfar_composed", "window_counts", "window_noise", "window_significance", "with_peaks"]
