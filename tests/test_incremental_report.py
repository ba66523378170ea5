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


def test_a_rerun_whose_results_are_equal_redraws_only_the_runtime_figure(tmp_path, bench_cli):
    """Two runs of one sweep into two folders compute equal results in other times: only
    the runtime's figure shows the times (the glance's and the tasks' are drawn from the
    results alone), and the second run's tables come from the user's cache, equal."""
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(TWO_TASKS.format(window=5))
    runs = [bench_cli("run", sweep, "--out", tmp_path / name, "--workers", 1, "--no-record", "--no-cache", check=True)
            for name in ("first", "second")]
    assert _figures_line(runs[1].stderr)[0] == 1, runs[1].stderr
    assert any((tmp_path / "first" / "figures").glob("glance-*.png"))
    first, second = _outputs(tmp_path / "first"), _outputs(tmp_path / "second")
    assert sorted(first) == sorted(second)
    differing = {name for name in first if first[name].read_bytes() != second[name].read_bytes()}
    # the times: the runtime's figure, summary.csv's seconds per trial, the pages (and their folder)
    assert differing <= {"figures/runtime.png", "summary.csv", "report.md", "report.html"}, differing


def _counted(fn):
    calls = []

    def counted(*args):
        calls.append(args)
        return fn(*args)
    counted.__qualname__ = fn.__qualname__
    return counted, calls


def test_a_table_or_text_is_reused_for_equal_inputs_and_code(tmp_path):
    import pandas as pd
    frame = pd.DataFrame({"config": ["a", "b"], "pd": [0.5, float("nan")], "n": [3, 4], "ok": [True, False],
                          "note": [None, "x"]})
    summarise, calls = _counted(lambda values, label: frame.assign(label=label))
    with reuse.reusing(reuse.FigureReuse(folder=tmp_path)):
        first = reuse.reused(summarise, [1.0, 2.0], "x")
        again = reuse.reused(summarise, [1.0, 2.0], "x")
        other = reuse.reused(summarise, [1.0, 2.5], "x")
        other_code = reuse.reused(summarise, [1.0, 2.0], "x", code="a plugin's task, edited")
        text, text_calls = _counted(lambda s: s.upper())
        assert reuse.reused(text, "abc") == reuse.reused(text, "abc") == "ABC"
        unknown, unknown_calls = _counted(lambda s: s.lower())
        assert reuse.reused(unknown, "ABC", code=None) == reuse.reused(unknown, "ABC", code=None) == "abc"
    assert len(calls) == 3 and len(text_calls) == 1 and len(unknown_calls) == 2      # unidentified code: never reused
    pd.testing.assert_frame_equal(again, first, check_exact=True)
    pd.testing.assert_frame_equal(other, first, check_exact=True)
    pd.testing.assert_frame_equal(other_code, first, check_exact=True)


def test_a_value_that_cannot_be_kept_exactly_or_a_damaged_one_is_computed_again(tmp_path):
    import pandas as pd
    tuples, calls = _counted(lambda: pd.DataFrame({"pair": [(1, 2)]}))            # JSON gives back a list
    indexed, indexed_calls = _counted(lambda: pd.DataFrame({"x": [1.0]}, index=[7]))
    with reuse.reusing(reuse.FigureReuse(folder=tmp_path)):
        for _ in range(2):
            assert reuse.reused(tuples).pair.iloc[0] == (1, 2)
            assert reuse.reused(indexed).index[0] == 7
        assert len(calls) == len(indexed_calls) == 2 and not list(tmp_path.glob("*.json"))
        text, text_calls = _counted(lambda: "kept")
        reuse.reused(text)
        for kept in tmp_path.glob("*.json"):
            kept.write_bytes(b"{not json")
        assert reuse.reused(text) == "kept" and len(text_calls) == 2
    assert reuse.reused(text) == "kept" and len(text_calls) == 3          # outside a build: computed


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
    labels = np.array(["a", "b"], dtype=object)
    assert reuse.key_of(labels) != reuse.key_of(np.array(["a", None], dtype=object))
    assert reuse.key_of(labels) != reuse.key_of(np.array(["ab"], dtype=object))
    assert reuse.key_of(labels) != reuse.key_of(labels.reshape(2, 1))


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


def test_an_edited_config_recomputes_only_its_own_paired_comparisons(tmp_path, monkeypatch):
    """Each pair's comparison is reused by its values (bench.report.glance._pair_rows): with one
    of four configs changed, the three pairs it is in are computed again, the three others not,
    and the frame equals one computed afresh."""
    import importlib
    import types

    import numpy as np
    import pandas as pd
    glance = importlib.import_module("radarbench.bench.report.glance")    # the package's name is the function

    task = types.SimpleNamespace(name="t", ranking_metric="rmse", ranking_binary=False, ranking_higher_is_better=False,
                                 equal_chance_metric="")
    rng = np.random.default_rng(5)
    configs = ["a", "b", "c", "d"]
    trials = pd.DataFrame([{"scenario": "s", "config": c, "snr_db": snr, "trial": t, "rmse": rng.gamma(2.0)}
                           for c in configs for snr in (0.0, 6.0) for t in range(8)])
    edited = trials.assign(rmse=np.where(trials.config == "c", trials.rmse * 1.5, trials.rmse))
    task_of = dict.fromkeys(configs, task)
    calls = []
    compare = glance.compare_pair
    monkeypatch.setattr(glance, "compare_pair", lambda *a: calls.append(a) or compare(*a))
    with reuse.reusing(reuse.FigureReuse(folder=tmp_path)):
        glance.comparisons_frame(trials, task_of)
        assert len(calls) == 6 * 3                               # 6 pairs, over all levels and per level
        calls.clear()
        incremental = glance.comparisons_frame(edited, task_of)
    assert len(calls) == 3 * 3
    pd.testing.assert_frame_equal(incremental, glance.comparisons_frame(edited, task_of), check_exact=True)


def test_json_values_are_kept_only_when_read_back_as_they_were():
    import numpy as np
    rows = [{"n": 3, "p": float("nan"), "ok": True, "better": "tie", "low": -0.0, "none": None}]
    assert reuse._decoded(reuse._encoded(rows)) is not None
    assert reuse._same(reuse._decoded(reuse._encoded(rows)), rows)
    assert reuse._encoded([(1, 2)]) is None                       # a tuple comes back a list
    assert reuse._encoded([np.float64(1.0)]) is None              # a NumPy float comes back a float
    assert reuse._encoded({1: "a"}) is None                       # a key comes back a string


def test_bounding_the_cache_drops_a_killed_writers_temporary_files_not_a_live_ones(tmp_path):
    import os
    import time
    stale, live, kept = tmp_path / ".KEY.json.abc.tmp", tmp_path / ".KEY2.json.def.tmp", tmp_path / "KEY.json"
    for path in (stale, live, kept):
        path.write_bytes(b"{}")
    old = time.time() - 2 * reuse.STALE_TEMPORARY_S
    os.utime(stale, (old, old))
    reuse._bound(tmp_path)
    assert not stale.exists() and live.exists() and kept.exists()
