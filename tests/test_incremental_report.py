"""The report is incremental (docs/architecture.md, 'Report'): a figure drawn before from
the same inputs and code is not drawn again, an output whose bytes did not change is not
written again, and what comes out equals a report built afresh."""

from __future__ import annotations

import io
import re
import shutil
from pathlib import Path

import pytest

from radarbench.bench.results import figure_cache as reuse
from radarbench.bench.run.progress import Progress
from radarbench.bench.report import build_outputs
from radarbench.bench.results.store import Store

TWO_TASKS = """
name = "two-tasks"
trials = 6
seed = 3
chunk = 6

[[scenarios]]
name = "cv-turn-cv"
snr_db = [0, 8]

[[scenarios]]
name = "maneuvering-1d"
params = {{ steps = 40, maneuver_start_s = 15.0, maneuver_duration_s = 10.0 }}
snr_db = [0, 10]

[[methods]]
name = "innovation"
params = {{ window = {window} }}

[[methods]]
name = "cumulant"
params = {{ window = 16 }}

[[methods]]
name = "cv-kf"

[[methods]]
name = "ca-kf"

[calibration]
pfa = 0.05
mode = "empirical"
h0_trials = 30

[record]
trials = 1
"""


def _outputs(folder: Path) -> dict[str, Path]:
    """The report's files of a run folder (not the store, the manifest or the recording)."""
    return {str(p.relative_to(folder)): p for p in sorted(folder.rglob("*"))
            if p.is_file() and p.suffix in (".md", ".html", ".csv", ".png") and "previous" not in p.parts}


def _mtimes(folder: Path) -> dict[str, int]:
    return {name: p.stat().st_mtime_ns for name, p in _outputs(folder).items()}


def _figures_line(stderr: str) -> tuple[int, int]:
    """(drawn, reused) of the report phase's last progress line."""
    found = re.findall(r"report: done, .*figures: (\d+) drawn, (\d+) reused", stderr)
    assert found, stderr
    return tuple(map(int, found[-1]))


def _build(folder: Path) -> tuple[int, int]:
    stream = io.StringIO()
    progress = Progress(stream=stream)
    try:
        build_outputs(folder, recording=False, progress=progress)
    finally:
        progress.close()
    return _figures_line(stream.getvalue())


def test_an_unchanged_run_folder_rebuilds_its_report_without_drawing_or_writing(small_run_copy):
    _build(small_run_copy)                               # the copy's own build (its figures are the run's)
    before = _mtimes(small_run_copy)
    drawn, reused = _build(small_run_copy)
    assert drawn == 0 and reused > 0, (drawn, reused)
    assert _mtimes(small_run_copy) == before


def test_a_figure_whose_file_was_changed_is_written_again(small_run_copy, tmp_path, monkeypatch):
    """From the user's cache, else drawn again."""
    _build(small_run_copy)
    figure = next(iter((small_run_copy / "figures").glob("*.png")))
    good = figure.read_bytes()
    figure.write_bytes(b"not the figure")
    assert _build(small_run_copy)[0] == 0 and figure.read_bytes() == good       # the user's cache had it
    figure.write_bytes(b"not the figure")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "empty-cache"))
    assert _build(small_run_copy)[0] == 1 and figure.read_bytes() == good


def test_a_figure_is_keyed_by_what_it_draws():
    import numpy as np
    import pandas as pd
    frame = pd.DataFrame({"config": ["a", "b"], "pd": [0.5, 0.75]})
    assert reuse.key_of(frame) == reuse.key_of(frame.copy())
    assert reuse.key_of(frame) != reuse.key_of(frame.assign(pd=[0.5, 0.7500000001]))
    assert reuse.key_of(frame) != reuse.key_of(frame.rename(columns={"pd": "pfa"}))
    assert reuse.key_of({"a": 1, "b": 2}) != reuse.key_of({"b": 2, "a": 1})      # a legend's order
    assert reuse.key_of(np.zeros(3)) != reuse.key_of(np.zeros(3, np.float32))
    assert reuse.key_of(object()) is None                                          # never reused wrongly


@pytest.fixture
def two_task_runs(tmp_path, bench_cli):
    """A run folder of a sweep with a detection and a tracking task, then the same folder
    after one detection config changed: (folder, stderr of the second run, mtimes between)."""
    sweep = tmp_path / "sweep.toml"
    out = tmp_path / "run"
    sweep.write_text(TWO_TASKS.format(window=5))
    bench_cli("run", sweep, "--out", out, "--workers", 1, "--no-record", check=True)
    before = _mtimes(out)
    sweep.write_text(TWO_TASKS.format(window=3))
    second = bench_cli("run", sweep, "--out", out, "--workers", 1, "--no-record", check=True)
    return out, second.stderr, before


def test_changing_one_config_redraws_only_the_figures_that_show_it(two_task_runs):
    out, stderr, before = two_task_runs
    after = _mtimes(out)
    redrawn = {Path(name).name for name in after if name.startswith("figures/") and after[name] != before.get(name)}
    drawn, reused = _figures_line(stderr)
    assert drawn >= len(redrawn)
    assert "pd_vs_snr.png" in redrawn                     # the detectors' figures show the changed config
    assert not {name for name in redrawn if name.startswith("tracking_")}, redrawn    # the trackers' do not
    assert reused >= sum(1 for name in after if name.startswith("figures/tracking_")) > 0


def test_an_incremental_report_equals_a_fresh_one(two_task_runs, tmp_path, monkeypatch):
    out, _, _ = two_task_runs
    fresh = tmp_path / "fresh"
    shutil.copytree(out, fresh)
    shutil.rmtree(fresh / "figures")
    for name in _outputs(fresh):
        (fresh / name).unlink()
    store = Store(fresh / "results.sqlite")
    try:
        store.set_meta(reuse.META, "{}")
    finally:
        store.close()
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "empty-cache"))   # nothing to reuse
    drawn, reused = _build(fresh)
    assert reused == 0 and drawn > 0
    mine, theirs = _outputs(out), _outputs(fresh)
    assert sorted(mine) == sorted(theirs)
    different = [name for name in mine if mine[name].read_bytes() != theirs[name].read_bytes()]
    assert not different, different


def test_the_report_phase_counts_its_sections_and_says_what_its_figures_cost():
    stream = io.StringIO()
    progress = Progress(stream=stream)
    progress.phase("report", total=2, label="sections")
    progress.detail("figures: 1 drawn, 2 reused")
    progress.advance(2)
    progress.phase("recording")
    progress.close()
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("bench: report: 0/2 sections (0%), "), lines
    assert re.fullmatch(r"bench: report: done, 2/2 sections \(figures: 1 drawn, 2 reused\) in \d+:\d\d", lines[1]), lines
    assert re.fullmatch(r"bench: recording: done, in \d+:\d\d", lines[-1]), lines      # units again, no detail


def test_a_run_with_nothing_new_rewrites_nothing(two_task_runs, bench_cli):
    out, _, _ = two_task_runs
    before = _mtimes(out)
    again = bench_cli("run", out.parent / "sweep.toml", "--out", out, "--workers", 1, "--no-record", check=True)
    assert "the report is up to date" in again.stdout and "report: " not in again.stderr, again.stderr
    assert _mtimes(out) == before
