"""A run's results as tidy pandas frames: ``radarbench.load_run`` and ``bench export``
(docs/outputs.md, 'Results in pandas')."""

from __future__ import annotations

import contextlib
import io
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pandas as pd
import pytest

import radarbench
from radarbench.bench import cli, registry
from radarbench.bench.results import tidy
from radarbench.bench.sweep.config import parse_sweep_text
from radarbench.bench.params import params_as_dict
from radarbench.bench.run.runner import write_plan_toml
from radarbench.bench.tasks import summary_columns
from radarbench.bench.results.tables import read_csv
from conftest import run_bench

ROOT = Path(__file__).resolve().parents[1]
QUICK = ROOT / "reports" / "quick"
KEYS = ["scenario", "config", "snr_db", "metric"]


def _docs_example() -> str:
    """The worked example of docs/outputs.md, 'Comparing two runs'."""
    page = (ROOT / "docs" / "outputs.md").read_text(encoding="utf-8")
    section = page.split("### Comparing two runs", 1)[1]
    return re.search(r"```python\n(.*?)```", section, re.DOTALL).group(1)


def _wide_long(folder: Path) -> pd.DataFrame:
    """summary.csv's metrics, melted by hand: (scenario, config, snr_db, metric) -> value."""
    wide = read_csv(folder / "summary.csv")
    metrics = list(tidy.metric_columns(wide.columns))
    return wide.melt(id_vars=["scenario", "config", "snr_db"], value_vars=metrics, var_name="metric")


def test_the_docs_example_compares_two_runs_in_five_lines(small_run):
    code = _docs_example()
    assert len(code.strip().splitlines()) <= 5
    assert "runs/before" in code and "runs/after" in code
    code = code.replace('"runs/before"', repr(str(QUICK))).replace('"runs/after"', repr(str(small_run)))
    namespace, shown = {}, io.StringIO()
    with contextlib.redirect_stdout(shown):
        exec(compile(code, "docs/outputs.md", "exec"), namespace)
    both = namespace["both"]
    pd_rows = both[both.metric == "pd"]
    # the configs and the SNR level the two runs share on cv-turn-cv
    assert sorted(pd_rows.config) == ["innovation[window=1]", "innovation[window=5]"]
    assert set(pd_rows.snr_db) == {0.0}
    wide = _wide_long(QUICK).merge(_wide_long(small_run), on=KEYS, suffixes=("_wide_a", "_wide_b"))
    checked = both.merge(wide, on=KEYS)
    assert len(checked) == len(both) > 0
    for side in "ab":
        pd.testing.assert_series_equal(checked[f"value_{side}"], checked[f"value_wide_{side}"].astype(float),
                                       check_names=False)
    pd.testing.assert_series_equal(checked.change, checked.value_b - checked.value_a, check_names=False)
    assert "innovation[window=5]" in shown.getvalue()


def test_a_committed_report_loads_one_row_per_key_with_every_metric():
    run = radarbench.load_run(QUICK)
    assert isinstance(run, radarbench.Run) and run.name == "quick"
    summary, wide = run.summary, read_csv(QUICK / "summary.csv")
    assert not summary.duplicated(KEYS).any()
    melted = _wide_long(QUICK)
    filled = melted.groupby(["scenario", "config", "metric"]).value.transform(lambda v: v.notna().any())
    assert set(map(tuple, summary[KEYS].values)) == set(map(tuple, melted[filled][KEYS].values))
    assert {"pd", "pd_equal_chance", "rmse_mean", "gospa_mean", "seconds_per_trial"} <= set(summary.metric)
    assert not {"pd_low", "delay_high", "n_trials", "params"} & set(summary.metric)
    joined = summary.merge(melted, on=KEYS, how="left", suffixes=("", "_wide"))
    pd.testing.assert_series_equal(joined.value, joined.value_wide.astype(float), check_names=False)
    # intervals: X_low of X, of X_mean and of X_rate
    cells = wide.set_index(["scenario", "config", "snr_db"])
    for metric, low in (("pd", "pd_low"), ("delay_mean", "delay_low"), ("divergence_rate", "divergence_low"),
                        ("gospa_mean", "gospa_low")):
        rows = summary[summary.metric == metric].set_index(["scenario", "config", "snr_db"])
        assert len(rows) > 0
        pd.testing.assert_series_equal(rows.ci_low, cells.loc[rows.index, low], check_names=False)
    assert summary[summary.metric == "delay_median"].ci_low.isna().all()
    assert (summary.n_trials == summary.merge(wide, on=["scenario", "config", "snr_db"]).n_trials_y).all()
    assert "params" not in summary and run.trials.empty      # a committed report has no trials.csv


def test_parameters_are_typed_prefixed_columns():
    run = radarbench.load_run(QUICK)
    s = run.summary
    params = [c for c in s.columns if "." in c]
    assert params and all(c.split(".")[0] in ("scenario", "method") for c in params)
    assert not set(c.split(".", 1)[1] for c in params) & {"value", "metric"}
    assert str(s["method.window"].dtype) == "Int64"
    assert str(s["scenario.process_noise"].dtype) == "boolean"
    assert str(s["method.normalisation"].dtype) == "string"
    assert s["scenario.dt_s"].dtype == float

    def one(column, where):
        return set(s.loc[where, column].dropna())
    assert one("method.window", s.config == "innovation[window=5]") == {5}
    assert one("method.normalisation", s.config == "cumulant[window=32,normalisation=paper]") == {"paper"}
    assert one("scenario.control_m_s2", s.scenario == "glint") == {(1.5, 0.07, 0.06)}
    assert s.loc[s.method == "innovation", "method.normalisation"].isna().all()
    assert set(run.calibration.config) <= set(s.config)
    assert str(run.calibration["method.window"].dtype) == "Int64"


def test_a_run_folder_gives_its_trials_and_calibration(small_run):
    run = radarbench.load_run(small_run)
    trials, wide = run.trials, read_csv(small_run / "trials.csv")
    assert len(trials) == len(wide) and not trials.duplicated(["scenario", "config", "snr_db", "trial"]).any()
    pd.testing.assert_series_equal(trials.detected, wide.detected)
    assert dict(zip(trials.config, trials["method.window"])) == {
        "innovation[window=1]": 1, "innovation[window=5]": 5, "cumulant[window=16]": 16}
    cal = read_csv(small_run / "calibration.csv")
    assert list(run.calibration.config) == list(cal.method)
    assert list(run.calibration.method) == ["innovation", "innovation", "cumulant"]
    assert (run.calibration["scenario.steps"] == 160).all()


def test_every_interval_bound_of_every_task_belongs_to_one_metric():
    """The metric / interval rule holds for the columns every task declares: a new task's
    ``foo_low`` without its ``foo`` (or ``foo_mean``, ``foo_rate``) fails here."""
    columns = summary_columns(registry.tasks().values())
    metrics = tidy.metric_columns(columns)
    bounds = [b for pair in metrics.values() for b in pair if b]
    assert len(bounds) == len(set(bounds))
    assert not [m for m in metrics if m.endswith(("_low", "_high"))]
    assert metrics["divergence_rate"] == ("divergence_low", "divergence_high")
    assert metrics["delay_mean"] == ("delay_low", "delay_high")
    assert metrics["delay_median"] == (None, None)


def test_a_scenario_grid_gives_each_config_its_own_values(tmp_path):
    plan = parse_sweep_text(b'''
name = "g"
scenario = "glint"
trials = 4
snr_db = [0]
[scenario_params]
epsilon = [0.05, 0.2]
control_m_s2 = [[1.5, 0.07, 0.06], [1.0, 0.0, 0.0]]
[[methods]]
name = "ekf"
''', "sweep.toml")
    write_plan_toml(tmp_path / "plan.toml", plan, "bench run sweep.toml")
    labels = [s.label for s in plan.scenarios]
    assert len(labels) == 4
    got = tidy.scenario_params(tomllib.loads((tmp_path / "plan.toml").read_text()), labels)
    assert got == {s.label: params_as_dict(s.params) for s in plan.scenarios}


def test_export_parquet_reads_back_the_same_frames(small_run, tmp_path):
    out = tmp_path / "out"
    proc = run_bench("export", small_run, "--format", "parquet", "--out", out, check=True)
    assert "summary.parquet" in proc.stdout
    run = radarbench.load_run(small_run)
    for name, frame in run.frames().items():
        pd.testing.assert_frame_equal(pd.read_parquet(out / f"{name}.parquet"), frame)
    assert sorted(p.name for p in out.iterdir()) == ["calibration.parquet", "summary.parquet", "trials.parquet"]


def test_export_csv_into_the_run_folder_is_in_its_manifest(small_run_copy):
    before = (small_run_copy / "summary.csv").read_bytes()
    run_bench("export", small_run_copy, "--format", "csv", check=True)
    assert (small_run_copy / "summary.csv").read_bytes() == before       # the wide CSV stays
    manifest = (small_run_copy / "bench-manifest.txt").read_text().splitlines()
    assert {"tidy/", "tidy/summary.csv", "tidy/trials.csv", "tidy/calibration.csv"} <= set(manifest)
    back = read_csv(small_run_copy / "tidy" / "summary.csv")
    expected = radarbench.load_run(small_run_copy).summary
    assert list(back.columns) == list(expected.columns)
    pd.testing.assert_series_equal(back.value, expected.value)


@pytest.mark.parametrize("make", ["missing", "empty", "file"])
def test_export_refuses_what_is_not_a_run_in_one_line(tmp_path, make):
    target = tmp_path / "run"
    if make == "empty":
        target.mkdir()
    elif make == "file":
        target.write_text("x")
    proc = run_bench("export", target, "--format", "csv", "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith(f"error: {target}")
    assert not (tmp_path / "out").exists()


def test_parquet_without_pyarrow_is_one_line_naming_it(small_run, tmp_path, monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "pyarrow", None)       # import pyarrow raises ImportError
    code = cli.main(["export", str(small_run), "--format", "parquet", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "pyarrow" in err
    assert not (tmp_path / "out").exists()


def test_importing_radarbench_does_not_import_pandas():
    probe = "import sys, radarbench; assert 'pandas' not in sys.modules; radarbench.load_run; " \
            "assert 'pandas' in sys.modules"
    subprocess.run([sys.executable, "-c", probe], check=True)
