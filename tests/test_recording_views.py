"""The default view of a recording (docs/architecture.md, 'Recordings'): which trials get
a tab and in what order, the summary charts split by task, unit and scenario config,
the colour key, and the onset and colour-scale entities."""

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.recording import blueprint as bp
from radarbench.bench.recording.layout import PALETTE, TrialLayout, method_colors
from radarbench.bench.recording.plot import PLOT_WIDTH, Plot, legend_heights, ticks
from radarbench.bench.recording.summary import SNR_AXIS_TITLE, informative_snr, summary_charts, summary_markdown
from radarbench.bench.tasks.detection import DetectionTask
from radarbench.bench.tasks.tbd import TBDTask
from radarbench.bench.tasks.tracking import TrackingTask

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
            rows += [dict(scenario=scenario, method=method, snr_db=s, pd=min(1.0, p + shift),
                          pd_equal_chance=min(1.0, p + shift) / 2, delay_mean=5.0) for s, p in zip(snrs, pds)]
    rows += [dict(scenario="glint", method="ekf", snr_db=s, rmse_mean=r, divergence_rate=0.0)
             for s, r in ((0, 100.0), (10, 20.0))]
    rows += [dict(scenario="grid", method="dp", snr_db=s, pd=p, rmse_mean=2.0) for s, p in ((0, 0.3), (6, 0.8))]
    return pd.DataFrame(rows), {"cum": DET, "nis": DET, "ekf": TRK, "dp": TBD}


def test_summary_charts_are_split_by_task_unit_and_scenario_config():
    summary, tasks = _summary()
    charts = {c.root: c for c in summary_charts(summary, tasks)}
    assert set(charts) == {
        "/summary/maneuver-detection/pd_equal_chance_vs_snr/cv-a",
        "/summary/maneuver-detection/pd_equal_chance_vs_snr/cv-b",
        "/summary/maneuver-detection/delay_vs_snr/cv-a", "/summary/maneuver-detection/delay_vs_snr/cv-b",
        "/summary/tracking/rmse_vs_snr", "/summary/tracking/divergence_rate_vs_snr",
        "/summary/tbd/pd_vs_snr", "/summary/tbd/rmse_vs_snr"}
    for chart in charts.values():
        methods = {s.label for s in chart.series}
        assert {tasks[m].name for m in methods} == {chart.task}              # one task per chart
        assert all(s.rows["scenario"].nunique() == 1 and set(s.rows["method"]) == {s.label} for s in chart.series)
    # the scenario config leads (the task is the chart's tab); one SNR level: "at", not "vs"
    assert charts["/summary/tracking/rmse_vs_snr"].title == "glint · RMSE (m) vs SNR"
    assert charts["/summary/tbd/rmse_vs_snr"].title == "grid · RMSE of detected tracks (m) vs SNR"
    # a detector's first chart is what the glance ranks on
    assert charts["/summary/maneuver-detection/pd_equal_chance_vs_snr/cv-b"].title == \
        "cv-b · Pd at equal chance Pd vs SNR"
    # in the summary's order: task by task, scenario config by scenario config
    assert [c.root.split("/")[2:] for c in summary_charts(summary, tasks)][:4] == [
        ["maneuver-detection", "pd_equal_chance_vs_snr", "cv-a"], ["maneuver-detection", "delay_vs_snr", "cv-a"],
        ["maneuver-detection", "pd_equal_chance_vs_snr", "cv-b"], ["maneuver-detection", "delay_vs_snr", "cv-b"]]


def test_one_colour_per_config_distinct_within_a_task():
    summary, tasks = _summary()
    many = {f"det{i:02d}": DET for i in range(10)} | {f"trk{i}": TRK for i in range(3)}
    colors = method_colors(many)
    assert len({colors[label] for label in many if label.startswith("det")}) == 10    # the palette's ten
    assert [colors[f"trk{i}"] for i in range(3)] == PALETTE[:3]                       # ranks within the task
    charts = summary_charts(summary, tasks)
    used = {}
    for chart in charts:
        for s in chart.series:
            assert used.setdefault(s.label, s.color) == s.color                       # the same in every chart
        assert len({s.color for s in chart.series}) == len(chart.series)


def test_a_chart_with_one_snr_level_is_a_comparison_at_it():
    summary, tasks = _summary()
    single = summary[(summary.method != "ekf") | (summary.snr_db == 10)]
    chart = next(c for c in summary_charts(single, tasks) if c.root == "/summary/tracking/rmse_vs_snr")
    assert chart.single_level and chart.title == "glint · RMSE (m) at +10 dB"


def test_a_chart_plots_its_values_between_round_ticks_of_each_axis():
    assert list(ticks(-15.0, 10.0)) == [-15.0, -10.0, -5.0, 0.0, 5.0, 10.0]
    assert list(ticks(0.03, 0.97)) == pytest.approx([0.0, 0.2, 0.4, 0.6, 0.8, 1.0])
    plot = Plot.covering(np.array([-2.5, 0.0, 6.5]), np.array([0.1, 0.5, 0.9]))
    corners = plot.screen([plot.x_ticks[0], plot.x_ticks[-1]], [plot.y_ticks[0], plot.y_ticks[-1]])
    assert corners[0, 0] == 0.0 and corners[1, 0] == PLOT_WIDTH          # x right
    assert corners[0, 1] == 0.0 and corners[1, 1] < 0.0                  # y up (negated on screen)
    xy = plot.screen([-2.5, 6.5], [0.1, 0.9])
    assert (xy[:, 0] >= 0).all() and (xy[:, 0] <= PLOT_WIDTH).all()       # every value inside the plot


def test_identical_configs_are_named_so_in_every_chart():
    summary, tasks = _summary()
    twin = summary[summary.method == "cum"].assign(method="cum2")
    charts = summary_charts(pd.concat([summary, twin]), {**tasks, "cum2": DET})
    legends = {s.legend for c in charts for s in c.series}
    assert "cum2 (identical to cum)" in legends and "cum" in legends


def test_informative_snr_is_where_pd_is_nearest_one_half():
    summary, tasks = _summary()
    # cv-a: mean Pd 0.125, 0.475, 0.925 -> 0 dB; cv-b: 0.075, 0.225, 0.545 -> 6 dB; grid: 0.3, 0.8 -> 0 dB
    assert informative_snr(summary, tasks) == {"cv-a": 0.0, "cv-b": 6.0, "grid": 0.0}


def test_legend_entries_stay_apart_and_near_where_their_curves_end():
    ends = np.array([-30.0, -31.0, -30.5, 0.0])
    placed = legend_heights(ends, line=5.0)
    order = np.sort(placed)
    assert np.all(np.diff(order) >= 5.0 - 1e-9)                               # none overlaps
    assert abs(placed[3] - 0.0) < 1e-9 or placed[3] > placed[:3].max()       # the far one keeps its place
    assert abs(placed[:3].mean() - ends[:3].mean()) < 5.0                     # the crowd stays centred
    far = np.array([-50.0, -20.0, 0.0])
    assert np.array_equal(legend_heights(far, line=5.0), far)                 # no crowding: as wished


def test_summary_table_starts_with_the_colour_key():
    summary, tasks = _summary()
    text = summary_markdown(summary, tasks)
    key = text.split("## ")[0]
    # one colour per config across the recording: its rank among its task's configs
    assert "- maneuver-detection: blue `cum`, orange `nis`\n- tracking: blue `ekf`\n- tbd: blue `dp`" in key


def test_legend_headroom_is_above_the_data():
    assert bp.legend_headroom(0.0, 10.0) == pytest.approx(10.0 * (1 + bp.LEGEND_HEADROOM))
    assert bp.legend_headroom(5.0, 5.0) > 5.0


@pytest.fixture
def detection_rrd(tmp_path):
    """A detection trial with an onset, drawn to a file."""
    from radarbench.bench.recording import write_recording
    from radarbench.bench.recording.record import TrialRecord
    from radarbench.bench.tasks import detection

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

    from radarbench.bench.recording.paths import entity_root, rerun_path

    onset = rerun_path(f"{entity_root('cv', 0.0, 0)}/nis/onset")
    chunks = RrdReader(detection_rrd).stream().filter(content=onset, is_static=False,
                                                      components="Scalars:scalars").to_chunks()
    rows = [chunk.to_record_batch().to_pylist() for chunk in chunks]
    rows = [row for batch in rows for row in batch]
    steps = [row["step"] for row in rows]
    values = sorted(v for row in rows for key, v in row.items() if key.endswith("Scalars:scalars") for v in v)
    assert steps == [30]                                       # one marker at the onset step
    assert values[0] > float(np.max(np.random.default_rng(3).chisquare(2, 60))) and values[0] > 6.0   # above the data


def _series_names(rrd, path: str) -> list[str]:
    """The names of the series (lines and points) the static styles at ``path`` give."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    names = []
    for component in ("SeriesLines:names", "SeriesPoints:names"):
        chunks = RrdReader(rrd).stream().filter(content=path, is_static=True, components=component).to_chunks()
        if chunks:
            names += [n for row in pa.Table.from_batches([c.to_record_batch() for c in chunks]).column(component)
                      .to_pylist() for n in row]
    return names


def test_the_first_screen_is_the_summary_with_a_named_curve_per_config(small_run):
    """What the viewer opens on: the side panels collapsed, the summary tab, in
    it a sub-tab per task whose views are time series with their legend on, one series per
    config named by its label, lines through the SNR levels; and no view of the recording
    empty."""
    import pandas as pd

    from tests.rrd_blueprint import TABS, axes_of, read_blueprint, static_values, track_views
    from tests.rrd_blueprint import entities as entities_of

    rrd = small_run / "recording.rrd"
    blueprint, entities = read_blueprint(rrd), entities_of(rrd)
    assert set(blueprint.panels.values()) == {2}                  # blueprint, selection and time: collapsed
    root = blueprint.containers[blueprint.root]
    assert root.kind == TABS and blueprint.child(root.contents[0]).name == "summary"
    summary = blueprint.tab("summary")
    assert [blueprint.child(c).name for c in summary.contents] == ["maneuver-detection", "summary table"]
    configs = sorted(pd.read_csv(small_run / "summary.csv")["config"].unique())
    charts = blueprint.views_under(blueprint.tab("summary", "maneuver-detection"))
    assert [v.name for v in charts] == ["cv-turn-cv · Pd at equal chance Pd vs SNR",
                                        "cv-turn-cv · mean delay (steps) vs SNR"]
    for view, y_title in zip(charts, ["Pd at equal chance Pd", "mean delay (steps)"]):
        # a plot drawn in a 2-D view: axes titled with their units, every config named beside it
        assert view.kind == "2D"
        lines, labels = axes_of(rrd, view, entities)
        assert labels[-2:] == [SNR_AXIS_TITLE, y_title] and lines >= 5
        legend = static_values(rrd, f"{view.origin}/legend", "Points2D:labels")
        assert sorted(name.split(" (identical to ")[0] for name in legend) == configs
    empty = [(v.kind, v.name) for v in blueprint.views.values() if not v.shows(entities)]
    assert not empty
    # every trial's 2-D track: an L with a mark per tick, the ticks' values and the titles in
    # one unit, and the truth named on the plot
    assert track_views(blueprint)
    for view in track_views(blueprint):
        lines, labels = axes_of(rrd, view, entities)
        unit = "km" if "x east (km)" in labels else "m"
        assert labels[-2:] == [f"x east ({unit})", f"y north ({unit})"], (view.origin, labels)
        assert lines == 1 + len(labels[:-2]) >= 5 and all(float(v) == float(v) for v in labels[:-2])
        assert f"{view.origin}/truth/label" in view.shows(entities), view.origin


def test_nice_ticks_one_step_for_both_axes():
    from radarbench.bench.recording.axes import frame_of, xy_extent

    frame = frame_of(xy_extent(np.array([[2030.0, 1480.0], [4960.0, 3020.0]])))
    step = np.diff(frame.x_ticks)
    assert np.allclose(step, step[0]) and np.allclose(np.diff(frame.y_ticks), step[0])     # one scale: x and y
    mantissa = step[0] / 10 ** np.floor(np.log10(step[0]))
    assert min(abs(mantissa - m) for m in (1, 2, 5)) < 1e-9                                 # 1, 2 or 5 x 10^k
    assert 4 <= frame.x_ticks.size <= 7                                                    # the longer side
    assert frame.x_ticks[0] <= 2030 and frame.x_ticks[-1] >= 4960 and frame.y_ticks[0] <= 1480
    assert frame.unit == "km" and frame.text(3000.0) == "3"
    assert frame_of(np.array([[0.0, 0.0], [2200.0, 1000.0]])).text(1500.0) == "1.5"                # half km steps
    near = frame_of(xy_extent(np.array([[10.0, -40.0], [180.0, 25.0]])))
    assert near.unit == "m" and near.text(near.x_ticks[1]) == f"{near.x_ticks[1]:.0f}"
    still = frame_of(xy_extent(np.array([[7.0, 7.0], [7.0, 7.0]])))                       # nothing moves
    assert still.x_ticks.size >= 2 and still.y_ticks.size >= 2 and still.x_ticks[0] <= 7 <= still.x_ticks[-1]
    assert xy_extent(np.full((3, 2), np.nan), None) is None                                 # nothing drawn: no axes
    left, right = frame.bounds()[0]
    assert left < frame.x_ticks[0] and right > frame.x_ticks[-1]                           # room for the labels


def test_a_trackers_error_views_name_their_units():
    assert [TRK.trace_unit(name) for name in ("error_x", "error_vy", "error_az", "estimate_y", "nis")] == \
        ["m", "m/s", "m/s²", "m", ""]
    layout = TrialLayout(root="/glint/x/trial_000", scenario="glint", title="t", sort_key=("glint", False, 0.0, 0),
                         methods=(), tasks=(TRK,), has_xy=False)
    assert bp._with_unit(layout, "error_vx") == "error_vx (m/s)" and bp._with_unit(layout, "nis") == "nis"


def test_a_trials_plots_show_its_own_steps():
    layout = TrialLayout(root="/mt/x/trial_000", scenario="mt", title="t", sort_key=("mt", False, 0.0, 0),
                         methods=(), tasks=(), has_xy=False, steps=25)
    axis = bp.trial_time_axis(layout)
    text = repr(axis)
    assert axis is not None and "24" in text and "160" not in text
    assert bp.trial_time_axis(TrialLayout(root="/x", scenario="x", title="t", sort_key=("x", False, 0.0, 0),
                                          methods=(), tasks=(), has_xy=False)) is None
