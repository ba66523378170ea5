"""An edited sweep in the same run folder reuses every stored result whose scenario config,
method config, calibration and code are unchanged (docs/running.md, 'Edit, re-run,
compare'), and its results equal a fresh run's (computed: --no-cache), byte for byte outside
timing columns."""

from __future__ import annotations

import contextlib
import sqlite3
from pathlib import Path

import pandas as pd
import pytest

from radarbench.bench.cli import main

pytestmark = pytest.mark.slow

SWEEP = """
name = "edits"
scenario = "cv-turn-cv"
trials = {trials}
chunk = 20
seed = 4
snr_db = [0, 10]
scenario_params = {{ steps = 120, onset_step = 60 }}
calibration = {{ h0_trials = 40, pfa = {pfa} }}
record = {{ trials = 1 }}

[[methods]]
name = "innovation"
params = {{ window = {windows} }}

[[methods]]
name = "cusum"
"""


def _run(folder: Path, out: Path, capsys, *options: str, **values) -> str:
    sweep = folder / "sweep.toml"
    sweep.write_text(SWEEP.format(**({"trials": 40, "pfa": 0.01, "windows": "[1, 5]"} | values)))
    assert main(["run", str(sweep), "--out", str(out), "--workers", "1", "--no-record", *options]) == 0
    return capsys.readouterr().err


def _runs(out: Path) -> set[tuple[str, str]]:
    with contextlib.closing(sqlite3.connect(out / "results.sqlite")) as con:
        return set(con.execute("SELECT unit, method FROM runs"))


def _same_as_fresh(out: Path, fresh: Path) -> None:
    for name in ("summary.csv", "trials.csv", "calibration.csv", "comparisons.csv"):
        a, b = pd.read_csv(out / name), pd.read_csv(fresh / name)
        timing = [c for c in a.columns if "second" in c or c.endswith("_s") or "time" in c]
        pd.testing.assert_frame_equal(a.drop(columns=timing), b.drop(columns=timing), obj=name)


def test_an_edited_method_parameter_computes_only_that_config(tmp_path, capsys):
    out = tmp_path / "run"
    _run(tmp_path, out, capsys)
    before = _runs(out)
    said = _run(tmp_path, out, capsys, windows="[1, 3]")
    assert "the sweep changed: reusing 6 stored units, computing 6 (unit, method config) runs on them" in said, said
    assert "6 (unit, method config) runs it no longer asks for" in said, said
    after = _runs(out)
    assert {m for _, m in after - before} == {"innovation[window=3]"}
    assert {m for _, m in before - after} == {"innovation[window=5]"}
    summary = pd.read_csv(out / "summary.csv")
    assert "innovation[window=5]" not in set(summary["config"]) and "innovation[window=3]" in set(summary["config"])
    _run(tmp_path, tmp_path / "fresh", capsys, "--no-cache", windows="[1, 3]")
    _same_as_fresh(out, tmp_path / "fresh")


def test_more_trials_compute_only_the_new_trials(tmp_path, capsys):
    out = tmp_path / "run"
    _run(tmp_path, out, capsys)
    before = _runs(out)
    said = _run(tmp_path, out, capsys, trials=60)
    assert "the sweep changed: reusing 6 stored units and the units it adds" in said and "previous" not in said, said
    added = {u for u, _ in _runs(out) - before}
    assert added == {f"evaluation/cv-turn-cv/{snr}/000000040+20" for snr in ("+0", "+10")}
    _run(tmp_path, tmp_path / "fresh", capsys, "--no-cache", trials=60)
    _same_as_fresh(out, tmp_path / "fresh")


def test_a_new_calibration_recomputes_the_calibrated_runs(tmp_path, capsys):
    out = tmp_path / "run"
    _run(tmp_path, out, capsys)
    said = _run(tmp_path, out, capsys, pfa=0.05)
    assert "computing 18 (unit, method config) runs" in said, said     # 3 detector configs x 6 units (a nominal threshold is stored)
    _run(tmp_path, tmp_path / "fresh", capsys, "--no-cache", pfa=0.05)
    _same_as_fresh(out, tmp_path / "fresh")


def test_a_removed_config_leaves_the_recording_too(tmp_path, capsys):
    """Was: exit 1, "no task given for method config(s) 'innovation[window=1]'": the stored
    trial records kept the removed config's traces, and the recording had no task for them."""
    out = tmp_path / "run"
    sweep = tmp_path / "sweep.toml"
    for windows in ("[1, 5]", "[5]"):
        sweep.write_text(SWEEP.format(trials=40, pfa=0.01, windows=windows))
        assert main(["run", str(sweep), "--out", str(out), "--workers", "1"]) == 0, capsys.readouterr().err
    from radarbench.bench.recording import TrialRecord
    from radarbench.bench.report import _of_the_plan, _task_of
    from radarbench.bench.results.store import Store
    store = Store(out / "results.sqlite")
    stored = {label for blob in store.records() for label in TrialRecord.from_bytes(blob).methods}
    shown = {label for r in _of_the_plan(store.records(), _task_of(store.plan())) for label in r.methods}
    assert "innovation[window=1]" in stored and shown == {"innovation[window=5]", "cusum"}
    assert (out / "recording.rrd").is_file()
