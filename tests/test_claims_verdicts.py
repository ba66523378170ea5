"""The claims' verdict rule on synthetic intervals (bench/report/claims.py; docs/architecture.md, 'Report').

A claim reproduces when our 95% interval lies within the claimed range (beyond 0 or the
minimal effect on the claimed side; within value ± tolerance; within [min, max]), does not
reproduce when the interval lies entirely outside it, and is not resolved otherwise, with
the trials that would resolve it: n_needed ≈ n · (half-width / distance to the threshold)².
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from radarbench.bench.report import claims
from radarbench.bench.report.quantities import Value

R, D, U = claims.REPRODUCES, claims.DOES_NOT, claims.NOT_RESOLVED
INF = math.inf


def _claim(expect: str, **keys) -> claims.Claim:
    return claims.Claim(id="c", claim="c", where="w", expect=expect, quantity={"kind": "summary"}, **keys)


def _value(low: float, high: float, x: float | None = None, n: float = 100.0, null: bool = False) -> Value:
    return Value((low + high) / 2 if x is None else x, low, high, n=n, null=null)


@pytest.mark.parametrize("expect, keys, low, high, word", [
    # directional, threshold 0
    ("positive", {}, 0.05, 0.15, R),
    ("positive", {}, -0.01, 0.15, U),                    # covers 0: not resolved (it was "does not reproduce")
    ("positive", {}, -0.15, -0.05, D),                   # the other side of 0
    ("positive", {}, -0.1, 0.0, D),                      # reaches 0 at most: excludes every positive effect
    ("positive", {}, 0.0, 0.0, D),                       # identical results
    ("negative", {}, -0.15, -0.05, R),
    ("negative", {}, -0.1, 0.1, U),
    ("negative", {}, 0.05, 0.1, D),
    ("negative", {}, -INF, -1.0, R),                     # a crossing below the swept levels
    ("positive", {}, 2.0, INF, R),                       # ... above them
    # directional with a minimal effect: beyond it to reproduce, short of it to fail
    ("positive", {"minimal_effect": 0.1}, 0.12, 0.2, R),
    ("positive", {"minimal_effect": 0.1}, 0.05, 0.15, U),   # excludes 0, not the minimal effect
    ("positive", {"minimal_effect": 0.1}, 0.02, 0.08, D),   # positive, yet smaller than the paper's effect
    ("negative", {"minimal_effect": 0.1}, -0.3, -0.12, R),
    ("negative", {"minimal_effect": 0.1}, -0.15, -0.05, U),
    ("negative", {"minimal_effect": 0.1}, -0.08, -0.02, D),
    # value ± tolerance: the interval must be narrower than the tolerance to reproduce
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.45, 0.55, R),
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.4, 0.6, R),        # the closed range
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.35, 0.55, U),      # holds the value, too wide
    ("value", {"value": 0.5, "tolerance": 0.1}, -0.1, 1.1, U),       # wide enough to hold anything
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.61, 0.7, D),
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.3, 0.39, D),
    ("value", {"value": 0.5}, 0.45, 0.55, U),                        # no tolerance: an interval never settles it
    ("value", {"value": 0.5}, 0.5, 0.5, R),                          # a value without an interval
    ("value", {"value": 0.5}, 0.52, 0.6, D),
    # between
    ("between", {"min": 0.4, "max": 0.6}, 0.45, 0.55, R),
    ("between", {"min": 0.4, "max": 0.6}, 0.35, 0.5, U),
    ("between", {"min": 0.4, "max": 0.6}, 0.5, 0.65, U),
    ("between", {"min": 0.4, "max": 0.6}, 0.61, 0.7, D),
    ("between", {"min": 0.4, "max": 0.6}, 0.2, 0.39, D),
    ("between", {"min": 1.0, "max": 100.0}, 2.0, INF, U),            # beyond the levels: not settled
])
def test_the_verdict_reads_the_interval_against_the_claimed_range(expect, keys, low, high, word):
    c = _claim(expect, **keys)
    assert claims.settled(c, low, high) == word
    got, reason = claims.verdict(c, _value(low, high) if math.isfinite(low + high) else Value(math.nan, low, high))
    assert got == word and (reason == "") == (word == R)


@pytest.mark.parametrize("expect, keys, low, high, reason", [
    ("positive", {}, -0.15, -0.05, "the opposite sign"),
    ("negative", {}, 0.05, 0.15, "the opposite sign"),
    ("positive", {}, -0.1, 0.0, "none in the claimed direction: the interval reaches 0 at most"),
    ("positive", {"minimal_effect": 0.1}, 0.02, 0.08, "smaller than the minimal effect 0.1"),
    ("negative", {"minimal_effect": 0.1}, -0.08, 0.02, "smaller than the minimal effect 0.1"),
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.61, 0.7, "the claimed 0.5 lies below our interval widened "
                                                            "by its tolerance 0.1"),
    ("value", {"value": 0.5}, 0.2, 0.3, "the claimed 0.5 lies above our interval"),
    ("between", {"min": 0.4, "max": 0.6}, 0.61, 0.7, "outside [0.4, 0.6]"),
])
def test_does_not_reproduce_says_why(expect, keys, low, high, reason):
    assert claims.verdict(_claim(expect, **keys), _value(low, high)) == (D, reason)


# ------------------------------------------------------------------ trials needed

@pytest.mark.parametrize("expect, keys, x, low, high, n, needed", [
    ("positive", {}, 0.1, -0.1, 0.3, 100, 400),                      # w 0.2, d 0.1: 100 · 2²
    ("positive", {}, -0.05, -0.15, 0.05, 100, 400),                  # the estimate on the other side: w_hi / d
    ("negative", {}, -0.2, -0.5, 0.1, 50, 50 * (0.3 / 0.2) ** 2),    # asymmetric: the half-width facing 0
    ("positive", {"minimal_effect": 0.05}, 0.1, 0.0, 0.2, 100, 400),  # the threshold is the minimal effect
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.52, 0.36, 0.6, 50, 50 * (0.16 / 0.12) ** 2),   # inside: both sides
    ("value", {"value": 0.5, "tolerance": 0.1}, 0.65, 0.55, 0.7, 100, 400),   # outside: the near edge
    ("value", {"value": 0.5}, 0.55, 0.45, 0.65, 100, 400),           # no tolerance: only "does not reproduce"
    ("between", {"min": 0.4, "max": 0.6}, 0.65, 0.55, 0.7, 100, 400),
    ("between", {"min": 0.4, "max": 0.6}, 0.45, 0.35, 0.58, 10, 10 * (0.1 / 0.05) ** 2),
])
def test_trials_needed_is_n_times_the_squared_ratio_of_half_width_to_distance(expect, keys, x, low, high, n,
                                                                              needed):
    c = _claim(expect, **keys)
    assert claims.settled(c, low, high) == U
    assert claims.trials_needed(c, Value(x, low, high, n=n)) == pytest.approx(needed)


def _shrunk(v: Value, n_new: float) -> tuple[float, float]:
    """v's interval with n_new trials: each half-width scaled by sqrt(n / n_new)."""
    k = math.sqrt(v.n / n_new)
    return v.value - (v.value - v.low) * k, v.value + (v.high - v.value) * k


def test_the_estimated_trials_just_settle_the_claim_as_the_estimate_says():
    """On random intervals of every kind: a little more than the estimate settles the claim
    (reproduces when the estimate is inside the claimed range, else does not), a little less
    does not."""
    rng = np.random.default_rng(38)
    kinds = [("positive", {}), ("negative", {}), ("positive", {"minimal_effect": 0.3}),
             ("negative", {"minimal_effect": 0.3}), ("value", {"value": 0.2, "tolerance": 0.4}),
             ("value", {"value": -0.1}), ("between", {"min": -0.5, "max": 0.6})]
    checked = {R: 0, D: 0}
    for _ in range(600):
        expect, keys = kinds[rng.integers(len(kinds))]
        c = _claim(expect, **keys)
        x = rng.uniform(-1.5, 1.5)
        v = Value(x, x - rng.uniform(0.05, 2.0), x + rng.uniform(0.05, 2.0), n=float(rng.integers(10, 500)))
        if claims.settled(c, v.low, v.high) != U:
            continue
        needed = claims.trials_needed(c, v)
        lo, hi = claims.claimed_range(c)
        towards = R if lo <= x <= hi else D
        assert needed > v.n
        assert claims.settled(c, *_shrunk(v, needed * 1.001)) == towards
        assert claims.settled(c, *_shrunk(v, needed * 0.999)) == U
        checked[towards] += 1
    assert min(checked.values()) > 20


def test_no_estimate_where_trials_cannot_settle_it():
    positive = _claim("positive")
    assert math.isnan(claims.trials_needed(positive, Value(0.0, -0.1, 0.1, n=100)))       # on the threshold
    assert math.isnan(claims.trials_needed(positive, Value(0.1, -0.1, 0.3)))              # no trial count
    assert math.isnan(claims.trials_needed(positive, Value(math.nan, -0.1, 0.3, n=100)))  # no estimate
    value = _claim("value", value=0.5)
    assert math.isnan(claims.trials_needed(value, Value(0.5, 0.4, 0.6, n=100)))


@pytest.mark.parametrize("c, v, reason", [
    (_claim("positive"), Value(0.1, -0.1, 0.3, n=100),
     "~400 trials per level (this run: 100) would resolve it, as “reproduces” if the estimate holds"),
    (_claim("positive"), Value(-0.05, -0.15, 0.05, n=100),
     "~400 trials per level (this run: 100) would resolve it, as “does not reproduce” if the estimate holds"),
    (_claim("value", value=0.001, tolerance=0.0005), Value(0.002, 0.00055, 0.0073, n=1000, null=True),
     "~8,500 null trials (this run: 1,000) would resolve it, as “does not reproduce” if the estimate holds"),
    (_claim("positive"), Value(0.1, -0.11, 0.3, n=100),       # 441 rounded up to two digits
     "~450 trials per level (this run: 100) would resolve it, as “reproduces” if the estimate holds"),
    (_claim("positive"), Value(0.0, -0.1, 0.1, n=100),
     "the estimate sits on the claim's threshold: no number of trials would resolve it"),
    (_claim("value", value=0.5), Value(0.5, 0.4, 0.6, n=100),
     "the estimate is the claimed value and the claim states no tolerance: no number of trials would resolve it"),
    (_claim("positive"), Value(0.1, -0.1, 0.3),
     "the trials behind its interval are not known"),
    (_claim("positive"), Value(0.1, -0.1, 0.3, n=0),
     "the trials behind its interval are not known"),
    (_claim("between", min=1.0, max=100.0), Value(math.nan, 2.0, INF, n=100),
     "the SNR levels bound its interval (a crossing between or beyond them): more levels would resolve it"),
    (_claim("positive"), Value(math.nan, -1.0, 2.0, n=100),
     "the SNR levels bound its interval (a crossing between or beyond them): more levels would resolve it"),
])
def test_a_claim_not_resolved_says_how_many_trials_would_resolve_it(c, v, reason):
    assert claims.verdict(c, v) == (U, reason)
