"""The default view of a recording (docs/architecture.md, 'Recordings'): which trials get
a tab and in what order, the summary charts split by task, unit and scenario config,
the colour key, and the onset and colour-scale entities."""

import numpy as np
import pandas as pd
import pytest

from bench.recording import blueprint as bp
from bench.recording.layout import TrialLayout
from bench.recording.summary import informative_snr, summary_charts, summary_markdown
from bench.tasks.detection import DetectionTask
from bench.tasks.tbd import TBDTask
from bench.tasks.tracking import TrackingTask

DET, TRK, TBD = DetectionTask(), TrackingTask(), TBDTask()


def _tab(scenario: str, snr: float | None, trial: int = 0) -> bp.TrialTab:
    layout = TrialLayout(root=f"/{scenario}/x/trial_{trial:03d}", scenario=scenario, title=f"{snr} {trial}",
                         sort_key=(scenario, snr is None, snr or 0.0, trial), methods=(), tasks=(), has_xy=False)
    return bp.TrialTab(layout, ())


def _snrs(tabs, scenario):
    return [t.layout.sort_key[2] for t in tabs if t.layout.scenario == scenario]


def test_every_scenario_config_gets_a_tab_from_its_most_informative_level():
    tabs = [_tab("cv", snr) for snr in range(-15, 12, 3)] + [_tab("glint", s) for s in (0, 10)] + \
        [_tab("grid", s) for s in (-6, 0, 6)] + [_tab("cv", None)]
    picked = bp.chosen(tabs, {"cv": 0.0, "grid": 6.0})
    assert len(picked) == bp.MAX_TABS
    assert {t.layout.scenario for t in picked} == {"cv", "glint", "grid"}
    cv = _snrs(picked, "cv")
    assert cv[0] == 0.0 and [abs(x) for x in cv] == sorted(abs(x) for x in cv)   # outwards from 0 dB
    assert _snrs(picked, "grid")[0] == 6.0
    assert _snrs(picked, "glint")[0] == 0.0            # no informative level: the middle (lower) one
    order = [t.layout.scenario for t in picked]
    assert order == sorted(order, key=["cv", "glint", "grid"].index)      # grouped by scenario config


def test_null_trials_come_last():
    picked = bp.chosen([_tab("cv", None, 0), _tab("cv", 3.0), _tab("cv", -3.0)], {"cv": 3.0})
    assert [t.layout.sort_key[1] for t in picked] == [False, False, True]


def _summary() -> tuple[pd.DataFrame, dict]:
    rows = []
    for scenario, snrs, pds in (("cv-a", (-6, 0, 6), (0.1, 0.45, 0.9)), ("cv-b", (-6, 0, 6), (0.05, 0.2, 0.52))):
        for method, shift in (("cum", 0.0), ("nis", 0.05)):
            rows += [dict(scenario=scenario, method=method, snr_db=s, pd=min(1.0, p + shift), delay_mean=5.0)
                     for s, p in zip(snrs, pds)]
    rows += [dict(scenario="glint", method="ekf", snr_db=s, rmse_mean=r, divergence_rate=0.0)
             for s, r in ((0, 100.0), (10, 20.0))]
    rows += [dict(scenario="grid", method="dp", snr_db=s, pd=p, rmse_mean=2.0) for s, p in ((0, 0.3), (6, 0.8))]
    return pd.DataFrame(rows), {"cum": DET, "nis": DET, "ekf": TRK, "dp": TBD}


def test_summary_charts_are_split_by_task_unit_and_scenario_config():
    summary, tasks = _summary()
    charts = {c.root: c for c in summary_charts(summary, tasks)}
    assert set(charts) == {
        "/summary/maneuver-detection/pd_vs_snr/cv-a", "/summary/maneuver-detection/pd_vs_snr/cv-b",
        "/summary/maneuver-detection/delay_vs_snr/cv-a", "/summary/maneuver-detection/delay_vs_snr/cv-b",
        "/summary/tracking/rmse_vs_snr", "/summary/tracking/divergence_rate_vs_snr",
        "/summary/tbd/pd_vs_snr", "/summary/tbd/rmse_vs_snr"}
    for chart in charts.values():
        methods = {str(rows["method"].iloc[0]) for _, _, rows in chart.bars}
        assert len({tasks[m].name for m in methods}) == 1                  # one task per chart
        assert all(rows["scenario"].nunique() == 1 for _, _, rows in chart.bars)
    assert charts["/summary/tracking/rmse_vs_snr"].title == "tracking · RMSE (m) vs SNR (dB)"
    assert charts["/summary/tbd/rmse_vs_snr"].title == "tbd · RMSE of detected tracks (m) vs SNR (dB)"
    assert charts["/summary/maneuver-detection/pd_vs_snr/cv-b"].title == "cv-b, maneuver-detection · Pd vs SNR (dB)"


def test_informative_snr_is_where_pd_is_nearest_one_half():
    summary, tasks = _summary()
    # cv-a: mean Pd 0.125, 0.475, 0.925 -> 0 dB; cv-b: 0.075, 0.225, 0.545 -> 6 dB; grid: 0.3, 0.8 -> 0 dB
    assert informative_snr(summary, tasks) == {"cv-a": 0.0, "cv-b": 6.0, "grid": 0.0}


def test_summary_table_starts_with_the_colour_key():
    summary, tasks = _summary()
    text = summary_markdown(summary, tasks)
    key = text.split("## ")[0]
    # one colour per config across the recording: its rank among all the run's configs
    assert "- blue: `cum`\n- orange: `dp`\n- green: `ekf`\n- red: `nis`" in key


def test_legend_headroom_is_above_the_data():
    assert bp.legend_headroom(0.0, 10.0) == pytest.approx(10.0 * (1 + bp.LEGEND_HEADROOM))
    assert bp.legend_headroom(5.0, 5.0) > 5.0


@pytest.fixture
def detection_rrd(tmp_path):
    """A detection trial with an onset, drawn to a file."""
    from bench.recording import write_recording
    from bench.recording.record import TrialRecord
    from bench.tasks import detection

    k = 60
    t = np.arange(k, dtype=float)
    rng = np.random.default_rng(3)
    stat = rng.chisquare(2, k)
    methods = {"nis": detection.method_trace(stat, 6.0, stat >= 6.0, {})}
    rec = TrialRecord(scenario="cv", snr_db=0.0, trial=0, t=t, truth_xy=np.c_[t, t], measurements_xy=np.c_[t, t],
                      methods=methods, info={"onset_step": 30})
    path = write_recording(tmp_path / "r.rrd", [rec], None, tasks={"nis": DET}, recording_id="views")
    return path


def test_the_onset_is_marked_above_the_data(detection_rrd):
    from rerun.chunk import RrdReader

    from bench.recording.paths import entity_root, rerun_path

    onset = rerun_path(f"{entity_root('cv', 0.0, 0)}/nis/onset")
    chunks = RrdReader(detection_rrd).stream().filter(content=onset, is_static=False,
                                                      components="Scalars:scalars").to_chunks()
    rows = [chunk.to_record_batch().to_pylist() for chunk in chunks]
    rows = [row for batch in rows for row in batch]
    steps = [row["step"] for row in rows]
    values = sorted(v for row in rows for key, v in row.items() if key.endswith("Scalars:scalars") for v in v)
    assert steps == [30]                                       # one marker at the onset step
    assert values[0] > float(np.max(np.random.default_rng(3).chisquare(2, 60))) and values[0] > 6.0   # above the data
