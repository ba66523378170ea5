"""The CLI driven as a user would drive it (subprocesses)."""

import os
import signal
import sqlite3
import subprocess
import sys
import time

import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.tasks import summary_columns
from conftest import scaled

#: summary.csv's columns with the built-in tasks, in the order readers have always found them.
SUMMARY_COLUMNS = ["scenario", "method", "config", "params", "snr_db", "n_trials", "pd", "pd_low", "pd_high",
                   "pfa", "pfa_low", "pfa_high", "delay_mean", "delay_low", "delay_high", "delay_median",
                   "rmse_mean", "rmse_low", "rmse_high", "seconds_per_trial", "threshold", "realised_snr_db",
                   "divergence_rate", "divergence_low", "divergence_high", "nees_mean",
                   "pd_step", "pd_step_low", "pd_step_high",
                   "pd_equal_chance", "pd_equal_chance_low", "pd_equal_chance_high",
                   # tracking scenes with a maneuver mask (empty for the others)
                   "rmse_quiet", "rmse_quiet_low", "rmse_quiet_high", "rmse_maneuver", "rmse_maneuver_low",
                   "rmse_maneuver_high", "rmse_onset", "rmse_onset_low", "rmse_onset_high", "switch_pd",
                   "switch_pd_low", "switch_pd_high", "switch_delay_mean", "switch_delay_low", "switch_delay_high",
                   "false_switch_rate", "false_switch_low", "false_switch_high", "q_quiet_mean", "q_maneuver_mean",
                   "q_maneuver_low", "q_maneuver_high",
                   # tracking scenes with a position bound: the posterior Cramér–Rao bound and efficiency
                   "pcrb_rmse", "efficiency",
                   "rmse_all_mean", "rmse_all_low", "rmse_all_high", "snr_offset_unit_innovation_db",
                   # cell detection (bench/tasks/cells/metrics.py), appended after the earlier tasks'
                   "false_alarms_per_map", "false_alarms_per_map_low", "false_alarms_per_map_high",
                   *(f"{kind}_{region}{end}" for region in ("homogeneous", "bragg", "interference", "clutter_edge",
                                                            "clutter_edge_quiet", "clutter_edge_raised")
                     for kind in ("pd", "pfa") for end in ("", "_low", "_high")),
                   "pd_paired", "pd_paired_low", "pd_paired_high", "targets_per_map", "swerling",
                   # multi-target tracking (bench/tasks/multitarget/metrics.py)
                   "scene_pd", "clutter_per_scan", "gospa_cutoff_m", "gospa_order",
                   *(f"{m}_{end}" for m in ("gospa", "gospa_loc", "gospa_missed", "gospa_false", "ospa",
                                            "false_track_rate", "track_breaks", "id_switches", "purity", "init_delay")
                     for end in ("mean", "low", "high")),
                   "initiated_fraction",
                   # detect and track (bench/tasks/detecttrack): the detector's cells
                   *(f"{m}_{end}" for m in ("cell_pd", "cell_pfa") for end in ("mean", "low", "high"))]

TRIAL_COLUMNS = ["scenario", "method", "params", "snr_db", "trial", "seed", "detected", "delay",
                 "false_alarms", "null_steps"]


def test_list_shows_methods_and_scenarios(bench_cli):
    out = bench_cli("list", check=True).stdout
    for name in ("cv-turn-cv", "innovation", "cumulant", "maneuver-detection", "tasks:", "tracking", "tbd"):
        assert name in out


def test_summary_columns_keep_their_order():
    assert summary_columns(registry.tasks().values()) == SUMMARY_COLUMNS


def test_run_writes_every_output_and_report_rebuilds_them(bench_cli, small_run_copy):
    out = small_run_copy                       # the small sweep's run folder, recording included
    for name in ("plan.toml", "results.sqlite", "trials.csv", "summary.csv", "calibration.csv", "report.md",
                 "recording.rrd", "figures/pd_vs_snr.png", "figures/delay_vs_snr.png", "figures/runtime.png"):
        assert (out / name).exists(), name
    trials = pd.read_csv(out / "trials.csv")
    assert set(TRIAL_COLUMNS) <= set(trials.columns)
    assert len(trials) == 3 * 2 * 12           # configs x SNR levels x trials
    summary = pd.read_csv(out / "summary.csv")
    detection = [c for c in SUMMARY_COLUMNS
                 if c in summary_columns([registry.get_task("maneuver-detection")])]
    assert list(summary.columns) == detection   # the run's task only, in the pinned order
    assert len(summary) == 3 * 2
    assert ((summary.pd_low <= summary.pd) & (summary.pd <= summary.pd_high)).all()
    report = (out / "report.md").read_text()
    for section in ("## Calibration", "## Detection probability", "## Runtime", "## Failures", "## Provenance"):
        assert section in report

    _check_recording(out / "recording.rrd", trials)

    before = {n: (out / n).read_text() for n in ("trials.csv", "summary.csv", "calibration.csv")}
    for n in before:
        (out / n).unlink()
    bench_cli("report", out, check=True)
    assert {n: (out / n).read_text() for n in before} == before


def _check_recording(rrd, trials):
    """The recording holds, per SNR level, trial 0's truth, measurements and, per
    method config, the statistic, the threshold in force and the alarms."""
    import numpy as np
    from rerun.chunk import RrdReader

    from radarbench.bench.recording import entity_root, method_entity_names, rerun_path

    reader = RrdReader(rrd)
    paths = set(reader.store().schema().entity_paths())
    names = method_entity_names(trials.config.unique())
    for snr in trials.snr_db.unique():
        root = entity_root("cv-turn-cv", snr, 0)
        assert rerun_path(f"{root}/truth") in paths and rerun_path(f"{root}/measurements") in paths
        for config, name in names.items():
            for leaf in ("statistic", "threshold"):
                assert rerun_path(f"{root}/{name}/{leaf}") in paths, (root, name, leaf)
            chunks = reader.stream().filter(content=rerun_path(f"{root}/{name}/threshold"), is_static=False,
                                            components="Scalars:scalars").to_chunks()
            logged = np.concatenate([np.concatenate(c.to_record_batch().column("Scalars:scalars").to_pylist())
                                     for c in chunks])
            row = trials[(trials.config == config) & (trials.snr_db == snr) & (trials.trial == 0)].iloc[0]
            np.testing.assert_array_equal(np.unique(logged), [row.threshold])
    assert rerun_path("/summary/table") in paths
    proc = subprocess.run([os.path.join(os.path.dirname(sys.executable), "rerun"), "rrd", "verify", str(rrd)],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


@pytest.mark.slow
def test_plan_toml_reruns_to_the_same_results(bench_cli, small_run, tmp_path):
    a, b = small_run, tmp_path / "b"
    bench_cli("run", a / "plan.toml", "--out", b, "--workers", 1, "--quiet", "--no-record", check=True)
    assert (a / "trials.csv").read_text() == (b / "trials.csv").read_text()


# Same results whatever the executor, workers and chunks: tests/test_executors.py


@pytest.mark.parametrize("text, field", [
    ('name = "x"\nscenario = [', "invalid TOML"),
    ('name = "x"\nscenario = "cv-turn-cv"\nsnr_db = [0]\n[[methods]]\nname = "magic"\n', "methods[0].name"),
    ('name = "x"\nscenario = "cv-turn-cv"\nsnr_db = [0]\n[[methods]]\nname = "innovation"\n'
     'params = { size = 3 }\n', "methods[0].params.size"),
    ('name = "x"\nscenario = "cv-turn-cv"\nsnr_db = [0]\n[[methods]]\nname = "innovation"\n'
     'params = { window = "five" }\n', "methods[0].params.window"),
    ('name = "x"\nscenario = "cv-turn-cv"\nsnr_db = []\n[[methods]]\nname = "innovation"\n', "snr_db"),
    ('name = "x"\nscenario = "cv-turn-cv"\ntrials = 1.5\nsnr_db = [0]\n[[methods]]\nname = "innovation"\n',
     "trials"),
])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(bench_cli, write_sweep, tmp_path, text, field):
    out = tmp_path / "never"
    proc = bench_cli("run", write_sweep(text=text), "--out", out, "--quiet")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and field in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_bad_command_line_is_one_line_too(bench_cli, tmp_path):
    for args in (["run"], ["run", "--preset", "nope"], ["run", "x.toml", "--workers", "0"], ["frobnicate"],
                 ["run", tmp_path / "missing.toml"]):
        proc = bench_cli(*args)
        assert proc.returncode == 2, args
        assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr, proc.stderr


def _as_from_a_terminal() -> None:
    """In the child: Ctrl-C handled as in a terminal. A test run started in the
    background by a non-interactive shell inherits SIGINT ignored (POSIX), and an
    ignored disposition survives exec, so the run would never see the signal."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _stored_units(db) -> int:
    try:
        with sqlite3.connect(db, timeout=scaled(60)) as con:
            return con.execute("SELECT count(*) FROM units").fetchone()[0]
    except sqlite3.Error:
        return 0


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """A sweep long enough to interrupt, and its uninterrupted results."""
    from conftest import run_bench, small_sweep_text
    root = tmp_path_factory.mktemp("resume")
    sweep = root / "sweep.toml"
    sweep.write_text(small_sweep_text(trials=40, snr="[-3, 0, 3, 6, 9]", chunk=4, h0=200))
    run_bench("run", sweep, "--out", root / "whole", "--workers", 1, "--quiet", "--no-record", check=True)
    return sweep, root / "whole"


@pytest.mark.slow
@pytest.mark.parametrize("sig, workers", [(signal.SIGKILL, 1), (signal.SIGINT, 2)])
def test_interrupted_run_resumes_to_the_uninterrupted_results(bench_cli, uninterrupted, tmp_path, sig, workers):
    sweep, whole = uninterrupted
    part = tmp_path / "part"
    # a session of its own, so the signal goes to the whole group as a terminal's Ctrl-C does
    proc = subprocess.Popen([sys.executable, "-m", "radarbench.bench", "run", str(sweep), "--out", str(part), "--workers",
                             str(workers), "--quiet", "--no-record"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=_as_from_a_terminal)
    deadline = time.monotonic() + scaled(600)
    while _stored_units(part / "results.sqlite") < 60 and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
    assert proc.poll() is None, "the run finished before it could be interrupted; make the sweep larger"
    os.killpg(proc.pid, sig)
    err = proc.communicate(timeout=scaled())[1]
    stored = _stored_units(part / "results.sqlite")
    assert 60 <= stored < 100, stored       # 50 calibration + 50 evaluation units in all
    assert not (part / "summary.csv").exists()
    if sig == signal.SIGINT:
        assert proc.returncode == 130 and "Traceback" not in err, err
        assert "again to resume" in err.strip().splitlines()[-1]

    bench_cli("run", sweep, "--out", part, "--workers", workers, "--quiet", "--no-record", check=True)
    assert (part / "trials.csv").read_text() == (whole / "trials.csv").read_text()
    # every column but the timing is a result and must be identical
    results = lambda d: pd.read_csv(d / "summary.csv").drop(columns="seconds_per_trial")  # noqa: E731
    pd.testing.assert_frame_equal(results(part), results(whole))


UNITS = 100          # of the `uninterrupted` sweep: 50 calibration + 50 evaluation units
CALIBRATION_UNITS = 50


def _start(sweep, out, workers):
    # a session of its own, so the signal goes to the whole group as a terminal's Ctrl-C does
    return subprocess.Popen([sys.executable, "-m", "radarbench.bench", "run", str(sweep), "--out", str(out), "--workers",
                             str(workers), "--quiet", "--no-record"], stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True, preexec_fn=_as_from_a_terminal)


def written_since(path, t: float) -> bool:
    return path.exists() and path.stat().st_mtime >= t


@pytest.mark.slow
def test_a_run_killed_at_several_points_resumes_to_the_uninterrupted_results(bench_cli, uninterrupted, tmp_path):
    """One run stopped again and again — after its first unit, during calibration, during
    evaluation, with every unit stored but the report not yet written — alternating Ctrl-C
    and kill -9 and the number of workers: nothing stored is ever lost, Ctrl-C says how to
    resume, and the last re-run ends with the uninterrupted results."""
    sweep, whole = uninterrupted
    part = tmp_path / "part"
    stops = [
        (signal.SIGKILL, 2, "after the first unit", lambda n: n >= 1),
        (signal.SIGINT, 2, "during calibration", lambda n: n >= CALIBRATION_UNITS // 2),
        (signal.SIGKILL, 1, "early in evaluation", lambda n: n >= CALIBRATION_UNITS + 5),
        (signal.SIGINT, 2, "late in evaluation", lambda n: n >= UNITS - 10),
        # reached after this run stored the last units: all stored, the report being made
        (signal.SIGINT, 1, "all units stored, report not written",
         lambda n: n == UNITS and not (part / "report.md").exists()),
        # this run has nothing left to compute: it is killed while it writes the report's files
        (signal.SIGKILL, 2, "while the report is written",
         lambda n: written_since(part / "trials.csv", started) and not (part / "report.md").exists()),
    ]
    stored = 0
    for sig, workers, when, ready in stops:
        started = time.time() - 1
        proc = _start(sweep, part, workers)
        deadline = time.monotonic() + scaled(600)
        while not ready(_stored_units(part / "results.sqlite")) and time.monotonic() < deadline \
                and proc.poll() is None:
            time.sleep(0.005)
        assert proc.poll() is None, f"{when}: the run ended before it could be stopped"
        at_signal = _stored_units(part / "results.sqlite")
        os.killpg(proc.pid, sig)
        err = proc.communicate(timeout=scaled())[1]
        after = _stored_units(part / "results.sqlite")
        assert stored <= at_signal <= after, (when, stored, at_signal, after)   # nothing stored is lost
        if at_signal < UNITS:
            assert not (part / "summary.csv").exists(), when
        if sig == signal.SIGINT:
            assert proc.returncode == 130 and "Traceback" not in err, (when, err)
            last = err.strip().splitlines()[-1]
            assert last.startswith("interrupted: ") and "run the same command again to resume" in last, last
            if at_signal < UNITS:
                assert f"{after} of {UNITS} units stored" in last, last
        stored = after
    bench_cli("run", sweep, "--out", part, "--workers", 2, "--quiet", "--no-record", check=True)
    assert (part / "trials.csv").read_text() == (whole / "trials.csv").read_text()
    for d in (part, whole):
        assert (d / "summary.csv").exists()
    pd.testing.assert_frame_equal(pd.read_csv(part / "summary.csv").drop(columns="seconds_per_trial"),
                                  pd.read_csv(whole / "summary.csv").drop(columns="seconds_per_trial"))


@pytest.mark.slow
def test_a_run_folder_takes_an_edited_sweep(bench_cli, write_sweep, small_run_copy):
    out = small_run_copy                       # the small sweep's run folder
    proc = bench_cli("run", write_sweep("other.toml", trials=13), "--out", out, "--no-record")
    assert proc.returncode == 0 and "the sweep changed: reusing" in proc.stderr, proc.stderr
    assert len(pd.read_csv(out / "trials.csv")) == 3 * 2 * 13
