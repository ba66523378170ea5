"""Per-trial results do not depend on the batch (docs/concepts.md: identical results whatever
the workers and chunking; docs/architecture.md, 'Portable numbers').

Random small sweeps — for every task, one of its scenarios (small instance) and one or two of
its methods, null and SNR trials — run with a random chunk size (1, a divisor of the trials, a
size that leaves a short last chunk) and with one chunk of all the trials: every row of
trials.csv, steps.csv, summary.csv and calibration.csv must be the same text, bit for
bit, apart from the timing columns. Each example costs two command-line runs, so the
examples are few (and the test is ``slow``: the README's test command runs it).
"""

from __future__ import annotations

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.sweep import tomlw
from radarbench.bench.sweep.capabilities import fits
from tests.conftest import run_bench
from tests.test_recorded_tracks import small_params_on_a_csv

TRIALS = 6
H0_TRIALS = 12
CSVS = ("trials.csv", "steps.csv", "summary.csv", "calibration.csv")


def _scenarios_by_task() -> dict[str, dict[str, list[str]]]:
    """task -> {scenario -> the methods that serve it}, in registry order."""
    registry.discover()
    out: dict[str, dict[str, list[str]]] = {}
    for s, scls in registry.scenarios().items():
        methods = [m for m, mcls in registry.methods().items() if fits(mcls, scls)]
        out.setdefault(scls.tasks[0], {})[s] = methods
    return out


BY_TASK = _scenarios_by_task()


@st.composite
def sweeps(draw) -> dict:
    """A sweep of one scenario per task (its small instance) with up to two of its methods."""
    scenarios, methods = [], []
    for task in sorted(BY_TASK):
        name = draw(st.sampled_from(sorted(BY_TASK[task])))
        params = dict(getattr(registry.get_scenario(name), "small_params", None) or {})
        scenarios.append({"name": name, "params": params, "snr_db": [draw(st.sampled_from([0.0, 6.0, 12.0]))]})
        pick = draw(st.lists(st.sampled_from(BY_TASK[task][name]), min_size=1, max_size=2, unique=True))
        methods += [m for m in pick if m not in methods]
    return {"name": "chunking", "trials": TRIALS, "seed": draw(st.integers(0, 2 ** 31)), "scenarios": scenarios,
            "methods": [{"name": m} for m in methods],
            "calibration": {"pfa": 0.1, "mode": "empirical", "h0_trials": H0_TRIALS}, "record": {"trials": 0}}


def _run(tmp_path, sweep: dict, chunk: int) -> dict[str, pd.DataFrame]:
    path = tmp_path / f"chunk{chunk}.toml"
    path.write_text(tomlw.dumps({**sweep, "chunk": chunk}))
    out = tmp_path / f"run{chunk}"
    run_bench("run", path, "--out", out, "--workers", 1, "--quiet", "--fresh", check=True)
    return {name: _without_timing(pd.read_csv(out / name, dtype=str, keep_default_na=False)) for name in CSVS}


def _without_timing(frame: pd.DataFrame) -> pd.DataFrame:
    return frame.drop(columns=[c for c in frame.columns if c.startswith("seconds")])


@pytest.mark.slow                     # four command-line runs: about a minute on a quiet machine
@settings(max_examples=2, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(sweep=sweeps(), chunk=st.sampled_from([1, 2, 3, 4]))
def test_every_row_is_the_same_whatever_the_chunk_size(tmp_path, sweep, chunk):
    for entry in sweep["scenarios"]:            # its small instance reads an optional extra's sample
        if entry["name"] == "recorded-tracks":
            entry["params"] = small_params_on_a_csv(tmp_path)
    whole, chunked = _run(tmp_path, sweep, max(TRIALS, H0_TRIALS)), _run(tmp_path, sweep, chunk)
    for name in CSVS:
        assert len(whole[name]) and list(whole[name].columns) == list(chunked[name].columns), name
        pd.testing.assert_frame_equal(whole[name], chunked[name], obj=f"{name} with chunk = {chunk}")
