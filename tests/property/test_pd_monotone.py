"""Pd is non-decreasing in SNR, up to sampling error, on a fixed-seed sweep.

Trial i sees the same noise at every SNR (common random numbers), so Pd
estimates at neighbouring levels are positively correlated and the unpaired
bound used here, 3.5 * sqrt(p1 (1 - p1) / n + p2 (1 - p2) / n), is
conservative: a drop larger than that is a real non-monotonicity.
"""

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.report import build_outputs
from radarbench.bench.run.runner import plan_record, run_sweep

TRIALS = 150


@pytest.mark.slow                     # three whole sweeps of seven SNR levels, reports included
@settings(derandomize=True, deadline=None, max_examples=3)
@given(seed=st.integers(0, 2**31))
def test_pd_is_non_decreasing_in_snr(seed, tmp_path_factory):
    out = tmp_path_factory.mktemp("monotone")
    plan = parse_sweep({
        "name": "monotone", "scenario": "cv-turn-cv", "trials": TRIALS, "seed": seed, "chunk": 75,
        "snr_db": {"start": -12, "stop": 6, "step": 3},
        "methods": [{"name": "innovation", "params": {"window": [1, 5]}},
                    {"name": "cumulant", "params": {"moment": ["centred", "raw"]}},
                    {"name": "wavelet"}],
        "calibration": {"h0_trials": 150}})
    run_sweep(plan, out, plan_record=plan_record(plan, "test"), workers=1, quiet=True).close()
    build_outputs(out, recording=False)
    summary = pd.read_csv(out / "summary.csv")
    for config, g in summary.groupby("config"):
        p = g.sort_values("snr_db").pd.to_numpy()
        bound = 3.5 * np.sqrt((p[:-1] * (1 - p[:-1]) + p[1:] * (1 - p[1:])) / TRIALS)
        assert np.all(np.diff(p) >= -np.maximum(bound, 1e-12)), (config, p)
