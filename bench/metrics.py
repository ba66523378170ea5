"""Generic statistics of the harness: intervals, bootstrap, RMSE, crossings.

Every task's metrics (bench/tasks/<task>/metrics.py) are built from these; the
definitions are in docs/architecture.md, 'Metrics'.

* proportions: Wilson score intervals (``scipy.stats.binomtest``);
* rates counted over steps that are correlated within a trial (per-step Pfa
  of a window statistic): a ratio-estimator interval over trials
  (:func:`clustered_rate_interval`);
* means and other statistics over trials: percentile bootstrap with a fixed
  seed (reproducible);
* RMSE per step across trials and its time average (the papers' "average RMSE");
* the SNR at which a Pd curve reaches 0.5: a probit fit to the binomial counts
  with a profile-likelihood interval (:func:`fit_crossing`), or the adjacent
  levels it jumps between;
* paired differences between method configs on the same trials (paired
  bootstrap, McNemar's exact test) and unpaired ones between runs.

A *cell* is one (scenario config, method config, SNR) of a sweep: summaries
have one row per cell (:func:`by_cell`).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy import optimize, special, stats

#: this module computes stored numbers: its code belongs to the identity of every config
#: that loads it (docs/architecture.md, 'Identities')
COMPUTES_RESULTS = True

CONFIDENCE = 0.95
BOOTSTRAP_RESAMPLES = 2000
BOOTSTRAP_SEED = 20040101
#: The columns that identify a cell in trials.csv and summary.csv.
CELL_KEYS = ["scenario", "method", "config", "params", "snr_db"]


def by_cell(trials: pd.DataFrame):
    """``(keys, rows)`` per cell, in the order of ``trials``: ``keys`` maps
    :data:`CELL_KEYS` to the cell's values."""
    for key, g in trials.groupby(CELL_KEYS, sort=False, dropna=False):
        yield dict(zip(CELL_KEYS, key)), g


def series_key(keys: dict) -> tuple:
    """The key of a cell's series: (scenario, config, snr_db)."""
    return keys["scenario"], keys["config"], keys["snr_db"]


def mean_realised_snr(g: pd.DataFrame) -> float:
    """Mean realised SNR of a cell's trials (NaN when the scenario gives none)."""
    return float(np.nanmean(g["realised_snr_db"])) if g["realised_snr_db"].notna().any() else np.nan


def binomial_interval(successes: int, trials: int, level: float = CONFIDENCE) -> tuple[float, float]:
    """Wilson score interval for a proportion (NaN when there are no trials)."""
    if trials <= 0:
        return (np.nan, np.nan)
    ci = stats.binomtest(int(successes), int(trials)).proportion_ci(level, method="wilson")
    return float(ci.low), float(ci.high)


def clustered_rate_interval(events: np.ndarray, opportunities: np.ndarray,
                            level: float = CONFIDENCE) -> tuple[float, float]:
    """Interval of a rate counted over steps (or cells) that are correlated
    within a trial, e.g. the per-step false-alarm rate of a window statistic.

    ``events[i]`` and ``opportunities[i]`` are trial *i*'s count of alarms and
    of steps. The rate R = sum(events) / sum(opportunities) is a ratio
    estimator over independent trials; its linearised variance
    ``n/(n-1) * sum((e_i - R o_i)^2) / (sum o_i)^2`` (Cochran, *Sampling
    Techniques*, eq. 6.13) counts the clustering of alarms. The interval is
    Wilson's on the *effective* number of steps ``sum(o) / deff``, where the
    design effect ``deff`` is that variance over the binomial one (at least 1,
    so never narrower than the independent-steps interval), with Student's
    quantile in place of the normal one (Korn & Graubard, "Confidence
    intervals for proportions with small expected number of positive counts
    estimated from survey data", Survey Methodology 24, 1998). Its degrees of
    freedom are the trials that alarmed (at most n - 1): with rare clustered
    alarms the variance rests on those trials alone; in simulation (window
    sums of 16-32 chi-square values) this keeps coverage at or above 95 %
    where the normal quantile falls to 0.88 with few alarming trials.

    Chosen over a cluster bootstrap, whose percentile interval collapses to
    [0, 0] without alarms and under-covers with few alarming trials. Limits:
    every trial one step (independent Bernoulli trials): Wilson's interval;
    at most one trial alarmed, or one trial in all (no between-trial
    variance): the assumption-free bracket [q_low / max(o), q_high] from
    Wilson's interval of q, the fraction of trials with an alarm, because a
    stationary per-step rate p satisfies q / o <= p <= q.
    """
    e = np.asarray(events, float)
    o = np.asarray(opportunities, float)
    total_o = float(o.sum())
    if total_o <= 0:
        return (np.nan, np.nan)
    if np.all(o == 1):
        return binomial_interval(int(e.sum()), e.size, level)
    rate = float(e.sum()) / total_o
    n, alarmed = e.size, int(np.count_nonzero(e > 0))
    if n < 2 or alarmed < 2:
        q_low, q_high = binomial_interval(alarmed, n, level)
        return q_low / float(o.max()), q_high
    var_binomial = rate * (1 - rate) / total_o
    var_ratio = n / (n - 1) * float(((e - rate * o) ** 2).sum()) / total_o ** 2
    deff = max(1.0, var_ratio / var_binomial) if var_binomial > 0 else 1.0
    return wilson_interval(rate, total_o / deff, level, df=min(n - 1, alarmed))


def wilson_interval(proportion: float, n: float, level: float = CONFIDENCE,
                    df: float = np.inf) -> tuple[float, float]:
    """Wilson score interval for a proportion observed on ``n`` (possibly
    effective, non-integer) independent Bernoulli trials; with finite ``df``
    Student's quantile replaces the normal one."""
    if n <= 0:
        return (np.nan, np.nan)
    z = float(stats.norm.isf((1 - level) / 2) if np.isinf(df) else stats.t.isf((1 - level) / 2, df))
    denom = 1 + z * z / n
    centre = (proportion + z * z / (2 * n)) / denom
    half = z * np.sqrt(proportion * (1 - proportion) / n + z * z / (4 * n * n)) / denom
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def _bootstrap_interval(n: int, estimate, level: float, resamples: int) -> tuple[float, float]:
    """Percentile bootstrap interval: ``estimate(idx)`` maps a (resamples, n)
    array of resampled indices to one statistic per resample; fixed seed."""
    idx = np.random.default_rng(BOOTSTRAP_SEED).integers(0, n, size=(resamples, n))
    values = estimate(idx)
    alpha = (1 - level) / 2
    return float(np.quantile(values, alpha)), float(np.quantile(values, 1 - alpha))


def bootstrap_mean_interval(values: np.ndarray, level: float = CONFIDENCE,
                            resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float]:
    """Percentile bootstrap interval of the mean, with a fixed seed (reproducible)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return (np.nan, np.nan)
    if values.size == 1 or np.all(values == values[0]):
        return (float(values[0]), float(values[0]))
    return _bootstrap_interval(values.size, lambda idx: values[idx].mean(axis=1), level, resamples)


#: Elements of resampled data held at once by :func:`bootstrap_statistic_interval` (memory bound).
_BOOTSTRAP_BLOCK = 20_000_000


def bootstrap_statistic_interval(samples: np.ndarray, statistic, level: float = CONFIDENCE,
                                 resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float]:
    """Percentile bootstrap interval of ``statistic``, resampling trials (the
    first axis), with a fixed seed. Vectorised: ``statistic`` takes a stack of
    resampled data sets, (r, n, ...), and returns one value per data set (r,);
    the resamples are evaluated in blocks of at most ``_BOOTSTRAP_BLOCK`` elements."""
    samples = np.asarray(samples, float)
    if len(samples) < 2:
        value = statistic(samples[None])[0] if len(samples) else np.nan
        return (float(value), float(value))
    block = max(1, _BOOTSTRAP_BLOCK // max(1, samples.size))

    def estimate(idx):
        return np.concatenate([statistic(samples[idx[i:i + block]]) for i in range(0, len(idx), block)])
    return _bootstrap_interval(len(samples), estimate, level, resamples)


def mean_over_present(x: np.ndarray, axis: int) -> np.ndarray:
    """Mean along ``axis``, where NaN marks a value that is not there (a step a trial of a
    ragged batch does not have; docs/architecture.md, 'Ragged batches'): over the values
    present, NaN where none is. Without NaN, ``numpy.mean`` itself (the same bits)."""
    x = np.asarray(x, float)
    if not np.isnan(x).any():
        return np.mean(x, axis=axis)
    count = (~np.isnan(x)).sum(axis=axis)
    total = np.nansum(x, axis=axis)
    return np.divide(total, count, out=np.full(np.shape(total), np.nan), where=count > 0)


def per_step_rmse(sq_err: np.ndarray) -> np.ndarray:
    """RMSE per step across trials, from squared errors (..., n, K); NaN marks a step a
    trial does not have (:func:`mean_over_present`)."""
    return np.sqrt(mean_over_present(sq_err, axis=-2)) if sq_err.shape[-2] else np.full(sq_err.shape[-1:], np.nan)


def time_averaged_rmse(sq_err: np.ndarray):
    """Mean over steps of the per-step RMSE across trials (the papers' "average RMSE"),
    of squared errors (n, K); of a stack (r, n, K), one per data set (r,). A ragged
    batch's steps (NaN where a trial does not have one): each step over the trials that
    have it, the mean over the steps some trial has."""
    if not sq_err.shape[-2]:
        return float("nan")
    value = mean_over_present(per_step_rmse(sq_err), axis=-1)
    return float(value) if np.ndim(value) == 0 else value


def crossing(x: np.ndarray, y: np.ndarray, level: float = 0.5) -> float:
    """The first x at which the piecewise-linear y(x) reaches ``level`` from below.

    NaN when y never reaches it in the range (the crossing lies above it);
    ``-inf`` when y already starts at or above it (the crossing lies below).
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    order = np.argsort(x)
    x, y = x[order], y[order]
    above = np.nonzero(y >= level)[0]
    if above.size == 0:
        return float("nan")
    i = above[0]
    if i == 0:
        return float("-inf")
    x0, x1, y0, y1 = x[i - 1], x[i], y[i - 1], y[i]
    return float(x0 + (level - y0) * (x1 - x0) / (y1 - y0))


def snr_at_pd(snr_db, pd, pd_low, pd_high, level: float = 0.5) -> tuple[float, float, float]:
    """SNR at which Pd reaches ``level``, with an interval from the Pd bands.

    The upper band reaches the level first (lower SNR bound), the lower band
    last (upper bound). See :func:`crossing` for NaN and ``-inf``.
    """
    return crossing(snr_db, pd, level), crossing(snr_db, pd_high, level), crossing(snr_db, pd_low, level)


# ------------------------------------------------------------------ paired and unpaired differences

def _stratified_means(values: np.ndarray, strata: np.ndarray, resamples: int, rng=None) -> np.ndarray:
    """(resamples,) bootstrap replicates of the mean over strata of each
    stratum's mean, resampling within each stratum (an SNR level's trials).
    ``rng`` None: a fresh generator seeded with :data:`BOOTSTRAP_SEED`, whose draws
    depend on the strata's sizes only (:func:`_fresh_resamples`)."""
    levels = np.unique(strata)
    by_level = [values[strata == level] for level in levels]
    draws = _fresh_resamples(tuple(v.size for v in by_level), resamples) if rng is None else \
        [rng.integers(0, v.size, size=(resamples, v.size)) for v in by_level]
    out = np.zeros(resamples)
    for v, index in zip(by_level, draws):
        out += v[index].mean(axis=1)
    return out / levels.size


#: strata sizes whose fresh resampling indices :func:`_fresh_resamples` keeps
RESAMPLES_MEMO_SIZE = 4
_resamples_memo: dict = {}


def _fresh_resamples(sizes: tuple[int, ...], resamples: int) -> list[np.ndarray]:
    """The indices a generator seeded with :data:`BOOTSTRAP_SEED` draws for strata of
    ``sizes``, in order: the same for every metric and config pair of a scenario, so drawn
    once (the draws were two thirds of a report's bootstrap). Kept for the last
    :data:`RESAMPLES_MEMO_SIZE` strata sizes, as int32, read-only."""
    key = (sizes, resamples)
    found = _resamples_memo.pop(key, None)
    if found is None:
        rng = np.random.default_rng(BOOTSTRAP_SEED)
        found = [rng.integers(0, n, size=(resamples, n)).astype(np.int32) for n in sizes]
        for index in found:
            index.flags.writeable = False
    _resamples_memo[key] = found              # the most recent last
    while len(_resamples_memo) > RESAMPLES_MEMO_SIZE:
        del _resamples_memo[next(iter(_resamples_memo))]
    return found


def stratified_mean(values, strata) -> float:
    """The mean over strata (SNR levels) of each stratum's mean: every level weighs the same."""
    values, strata = np.asarray(values, float), np.asarray(strata)
    return float(np.mean([values[strata == s].mean() for s in np.unique(strata)])) if values.size else np.nan


def _finite_pairs(*arrays):
    keep = np.ones(len(arrays[0]), bool)
    for a in arrays:
        if a.dtype.kind == "f":
            keep &= np.isfinite(a)
    return [a[keep] for a in arrays]


def bootstrap_mean_ci(values, strata, level: float = CONFIDENCE,
                      resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float]:
    """(mean, low, high): :func:`stratified_mean` of ``values`` and its percentile
    bootstrap interval, resampling trials within each stratum (fixed seed; NaN values dropped)."""
    values, strata = _finite_pairs(np.asarray(values, float), np.asarray(strata))
    if values.size == 0:
        return (np.nan, np.nan, np.nan)
    reps = _stratified_means(values, strata, resamples)
    alpha = (1 - level) / 2
    noise = FLOAT_NOISE * float(np.abs(values).max())
    return tuple(_snap(x, noise) for x in (stratified_mean(values, strata), np.quantile(reps, alpha),
                                           np.quantile(reps, 1 - alpha)))


#: Means of means of values of magnitude v are exact to about n eps v over n values: a
#: mean within FLOAT_NOISE v of 0 is 0 (the 5.55e-18 upper end of a paired interval of
#: equal trials read as a significant gain), and so is a negative zero.
FLOAT_NOISE = 1e-10


def _snap(x, noise: float) -> float:
    return 0.0 if abs(float(x)) <= noise else float(x)


#: The numerical resolution of a per-trial metric, relative to its values: two values of one
#: trial within RELATIVE_RESOLUTION · max(|a|, |b|) of each other are one value computed along
#: two routes (two implementations of one filter differ by rounding, ~1e-13 of an RMSE in
#: metres), so :func:`paired_difference` counts them as equal: rounding is a tie, never a
#: winner nor a change (docs/architecture.md, 'Report').
RELATIVE_RESOLUTION = 1e-9


def resolved_differences(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``b - a`` per pair, 0 where the two are equal to :data:`RELATIVE_RESOLUTION`."""
    d = b - a
    return np.where(np.abs(d) <= RELATIVE_RESOLUTION * np.maximum(np.abs(a), np.abs(b)), 0.0, d)


def paired_difference(a, b, strata, level: float = CONFIDENCE,
                      resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float]:
    """(mean, low, high) of ``b - a`` over pairs (the same trial seen by two
    method configs, or by two runs that share their trials): the paired
    bootstrap resamples the pairs, within each stratum (SNR level), so the noise
    common to both cancels. Pairs with a NaN are dropped; pairs equal to the metric's
    resolution differ by 0 (:func:`resolved_differences`)."""
    a, b, strata = _finite_pairs(np.asarray(a, float), np.asarray(b, float), np.asarray(strata))
    return bootstrap_mean_ci(resolved_differences(a, b), strata, level, resamples)


def unpaired_difference(a, a_strata, b, b_strata, level: float = CONFIDENCE,
                        resamples: int = BOOTSTRAP_RESAMPLES) -> tuple[float, float, float]:
    """(mean, low, high) of mean(b) - mean(a) for independent samples (two runs
    that do not share trials): each resampled on its own, within strata."""
    a, a_strata = _finite_pairs(np.asarray(a, float), np.asarray(a_strata))
    b, b_strata = _finite_pairs(np.asarray(b, float), np.asarray(b_strata))
    if a.size == 0 or b.size == 0:
        return (np.nan, np.nan, np.nan)
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    reps = _stratified_means(b, b_strata, resamples, rng) - _stratified_means(a, a_strata, resamples, rng)
    alpha = (1 - level) / 2
    return (stratified_mean(b, b_strata) - stratified_mean(a, a_strata), float(np.quantile(reps, alpha)),
            float(np.quantile(reps, 1 - alpha)))


def mcnemar_exact(a, b) -> tuple[int, int, float]:
    """McNemar's exact test of paired 0/1 outcomes: (pairs with a = 1, b = 0;
    pairs with a = 0, b = 1; two-sided p-value, the binomial test of the
    discordant pairs at 1/2). 1 when no pair is discordant."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    keep = np.isfinite(a) & np.isfinite(b)
    a, b = a[keep] > 0.5, b[keep] > 0.5
    only_a, only_b = int(np.count_nonzero(a & ~b)), int(np.count_nonzero(b & ~a))
    if only_a + only_b == 0:
        return only_a, only_b, 1.0
    return only_a, only_b, float(stats.binomtest(only_b, only_a + only_b, 0.5).pvalue)


# ------------------------------------------------------------------ SNR at which Pd reaches 0.5

#: A crossing is *resolved* by the SNR levels unless it falls between two adjacent
#: levels whose Pd (above the floor, as a fraction of what is left) is at most the
#: first and at least the second of these: then the data say only "between them".
UNRESOLVED_BAND = (0.1, 0.9)
_CHI2_1 = float(stats.chi2.isf(1 - CONFIDENCE, 1))


@dataclass(frozen=True)
class Crossing:
    """Where a Pd curve reaches a level. ``kind``: "fit" (``mid`` in [``low``,
    ``high``], the probit fit's profile-likelihood interval; an end may be
    ±inf: beyond the swept range), "between" (``low`` and ``high`` are the
    adjacent levels that jump across it), "below" / "above" (the swept range
    starts above / ends below the level)."""

    kind: str
    mid: float
    low: float
    high: float

    @property
    def order(self) -> float:
        """A sort key: lower SNR first ("between": its midpoint), "above" last."""
        if self.kind == "between":
            return (self.low + self.high) / 2
        return {"below": -np.inf, "above": np.inf}.get(self.kind, self.mid)


def _probit_deviance(snr, k, n, floor, z, s50, slope):
    p = floor + (1 - floor) * special.ndtr(z + slope * (snr - s50))
    p = np.clip(p, 1e-12, 1 - 1e-12)
    return -2 * float(np.sum(k * np.log(p) + (n - k) * np.log1p(-p)))


def _profile(snr, k, n, floor, z, s50) -> float:
    """The deviance at crossing ``s50``, minimised over the slope (log scale, per dB)."""
    res = optimize.minimize_scalar(lambda ls: _probit_deviance(snr, k, n, floor, z, s50, np.exp(ls)),
                                   bounds=(np.log(1e-3), np.log(1e2)), method="bounded", options={"xatol": 1e-4})
    return float(res.fun)


def _profile_end(excess, mid: float, step: float, limit: float) -> float:
    """Where ``excess`` (profile deviance above the cut-off) turns positive going from
    ``mid`` towards ``limit`` in steps of ``step``; ±inf if it never does before ``limit``."""
    inner = mid
    while (limit - inner) * np.sign(step) > 0:
        outer = inner + step
        if excess(outer) > 0:
            return float(optimize.brentq(excess, inner, outer, xtol=1e-3))
        inner = outer
    return float(np.sign(step) * np.inf)


def fit_crossing(snr_db, successes, trials, floor: float = 0.0, level: float = 0.5) -> Crossing:
    """The SNR at which Pd reaches ``level``, from binomial counts per SNR level.

    Model (probit with a floor): Pd(s) = c + (1 − c) Φ(z + b (s − s50)), with
    c the floor (a detector's chance Pd; 0 where there is none, taken as known),
    z = Φ⁻¹((level − c)/(1 − c)) so that Pd(s50) = level, and slope b > 0.
    s50 is the maximum-likelihood estimate; its 95% interval is the profile
    likelihood's: the s50 whose deviance, minimised over b, is within
    χ²₁(0.95) = 3.84 of the minimum (an end that leaves the swept range by more
    than the range's width is open: ±inf). Where the levels do not resolve the
    crossing (:data:`UNRESOLVED_BAND`), or it lies outside the swept range, no
    fit is made (see :class:`Crossing`).
    """
    counts = (np.asarray(snr_db, float), np.asarray(successes, float), np.asarray(trials, float))
    return _fit_crossing(*(tuple(a.tolist()) for a in counts), float(floor), float(level))


@functools.lru_cache(maxsize=1024)
def _fit_crossing(snr_db: tuple, successes: tuple, trials: tuple, floor: float, level: float) -> Crossing:
    """:func:`fit_crossing` of counts given as tuples: a report asks for the same curve's
    crossing from several sections and its claims (a fit is ~10 ms)."""
    snr = np.asarray(snr_db, float)
    k, n = np.asarray(successes, float), np.asarray(trials, float)
    order = np.argsort(snr)
    snr, k, n = snr[order], k[order], n[order]
    pd_ = k / np.maximum(n, 1)
    above = np.flatnonzero(pd_ >= level)
    if above.size == 0:
        return Crossing("above", np.nan, float(snr[-1]), np.inf)
    if above[0] == 0 or floor >= level:
        return Crossing("below", np.nan, -np.inf, float(snr[0]))
    i = above[0]
    q = (pd_ - floor) / (1 - floor)
    if q[i - 1] <= UNRESOLVED_BAND[0] and q[i] >= UNRESOLVED_BAND[1]:
        return Crossing("between", np.nan, float(snr[i - 1]), float(snr[i]))
    z = float(special.ndtri((level - floor) / (1 - floor)))
    span = float(snr[-1] - snr[0]) or 1.0
    start = crossing(snr, pd_, level)
    res = optimize.minimize_scalar(lambda s: _profile(snr, k, n, floor, z, s),
                                   bounds=(snr[i - 1] - span / 4, snr[i] + span / 4), method="bounded",
                                   options={"xatol": 1e-4})
    mid = float(res.x) if res.fun <= _profile(snr, k, n, floor, z, start) else start
    dmin = _profile(snr, k, n, floor, z, mid)

    def excess(s):
        return _profile(snr, k, n, floor, z, s) - dmin - _CHI2_1
    step = span / 40
    return Crossing("fit", mid, _profile_end(excess, mid, -step, snr[0] - span),
                    _profile_end(excess, mid, step, snr[-1] + span))
