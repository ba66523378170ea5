"""What a user reads is right, results come first, comparisons
are paired, ``bench compare`` gates a change, report.html stands alone.

Small runs (seconds); every check could fail on a wrong report."""

from __future__ import annotations

import re
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.cli import EXIT_BAD_INPUT, EXIT_REGRESSION, main
from radarbench.bench.metrics import (bootstrap_statistic_interval, fit_crossing, mcnemar_exact, paired_difference,
                           time_averaged_rmse)
from radarbench.bench.report import non_default

MIXED = """
name = "mixed"
description = "detectors, trackers and TBD in one small run"
trials = 24
seed = 11
chunk = 12

[[scenarios]]
name = "cv-turn-cv"
params = {{ turn_rate_deg_s = 4.0, detect_window_steps = 30 }}
snr_db = [-9, -3, 3, 9]

[[scenarios]]
name = "glint"
params = {{ sensor = "active", epsilon = 0.1, steps = 30 }}
snr_db = [0, 10]
trials = 6

[[scenarios]]
name = "tbd-grid"
params = {{ cells = 16, frames = 8 }}
snr_db = [0, 6, 12]
trials = 8

[[methods]]
name = "innovation"
params = {{ window = [1, 5] }}

[[methods]]
name = "cumulant"
params = {{ window = 16, normalisation = "paper" }}

[[methods]]
name = "ekf"

[[methods]]
name = "viterbi"
params = {{ survivors = 64 }}

[[methods]]
name = "dp-tbd"

[calibration]
pfa = {pfa}
mode = "empirical"
h0_trials = 60

[record]
trials = 1
"""

DETECTORS = """
name = "detectors"
scenario = "cv-turn-cv"
trials = 40
seed = 5
chunk = 40
snr_db = [-9, -3, 3]

[[methods]]
name = "innovation"
label = "candidate"
params = {{ window = {window} }}

[[methods]]
name = "wavelet"

[calibration]
pfa = 0.02
mode = "empirical"
h0_trials = 100

[record]
trials = 1
"""


def _run(folder: Path, text: str) -> Path:
    sweep = folder.with_suffix(".toml")
    sweep.write_text(textwrap.dedent(text))
    assert main(["run", str(sweep), "--out", str(folder), "--workers", "1", "--quiet", "--no-record"]) == 0
    return folder


@pytest.fixture(scope="module")
def mixed(tmp_path_factory) -> Path:
    return _run(tmp_path_factory.mktemp("ux") / "mixed", MIXED.format(pfa=0.02))


@pytest.fixture(scope="module")
def detectors(tmp_path_factory) -> tuple[Path, Path]:
    """The same detector sweep twice: as is, and with its config "candidate" weakened (a
    sliding window of 60 steps instead of 5 dilutes the turn; the calibration and the
    trials, and so their seeds, are the same)."""
    root = tmp_path_factory.mktemp("cmp")
    return _run(root / "base", DETECTORS.format(window=5)), _run(root / "weak", DETECTORS.format(window=60))


def _section(report: str, title: str) -> str:
    """The text of the level-2 section ``title`` (to the next level-2 heading)."""
    m = re.search(rf"^## {re.escape(title)}\n(.*?)(?=^## |\Z)", report, re.S | re.M)
    assert m, f"no section {title!r}"
    return m.group(1)


def _task_of(folder: Path) -> dict:
    plan = tomllib.loads((folder / "plan.toml").read_text())
    return {m["label"]: registry.get_task(registry.get_method(m["name"]).task) for m in plan["methods"]}


# ------------------------------------------------------------------ correctness

def test_results_at_a_glance_come_first(mixed):
    report = (mixed / "report.md").read_text()
    headings = re.findall(r"^## (.+)$", report, re.M)
    assert headings[0] == "Results at a glance"


def test_the_roc_has_only_detectors(mixed):
    roc = _section((mixed / "report.md").read_text(), "ROC")
    task_of = _task_of(mixed)
    drawn = re.findall(r"`([^`]+)`", roc.split("),")[0])
    assert drawn and all(task_of[c].has_roc for c in drawn), drawn
    assert {c for c, t in task_of.items() if t.has_roc} == set(drawn)
    assert "dp-tbd" not in roc


def test_every_non_default_parameter_is_listed(mixed):
    plan = tomllib.loads((mixed / "plan.toml").read_text())
    plan_section = _section((mixed / "report.md").read_text(), "What was run")
    rows = {m.group(1): m.group(2) for m in re.finditer(r"^\| `([^`]+)`\s*\|(.*)$", plan_section, re.M)}
    listed = 0
    for kind, entries in (("scenario", plan["scenarios"]), ("method", plan["methods"])):
        for entry in entries:
            cls = registry.get_scenario(entry["name"]) if kind == "scenario" else registry.get_method(entry["name"])
            changed = non_default(cls, entry["params"])
            row = rows[entry["label"]]
            for k, v in changed.items():
                assert f"{k}={v}" in row, (entry["label"], k, row)
                listed += 1
            assert ("defaults" in row) == (not changed), (entry["label"], row)
    # what this sweep set away from the defaults, whatever the defaults are
    assert listed >= 5
    assert "cells=16" in rows["tbd-grid"] and "frames=8" in rows["tbd-grid"]
    assert "epsilon=0.1" in rows["glint"] and "survivors=64" in rows["viterbi[survivors=64]"]


def test_text_that_does_not_apply_is_left_out(mixed):
    report = (mixed / "report.md").read_text()
    calibration_row = next(line for line in report.splitlines() if line.startswith("| calibration"))
    assert "`cv-turn-cv`" in calibration_row and "`tbd-grid`" in calibration_row
    assert "`glint`" not in calibration_row          # trackers have no null trials


def test_db_values_are_rounded_to_a_tenth(mixed):
    report = (mixed / "report.md").read_text()
    for m in re.finditer(r"(-?\d+\.\d+)(?= dB\b)", report):
        assert len(m.group(1).split(".")[1]) == 1, report[m.start() - 80:m.end() + 20]


def test_glance_winner_matches_the_summary(mixed):
    glance = _section((mixed / "report.md").read_text(), "Results at a glance")
    summary = pd.read_csv(mixed / "summary.csv")
    trials = pd.read_csv(mixed / "trials.csv")
    task_of = _task_of(mixed)
    blocks = re.findall(r"on `([^`]+)`\*\*.*?\n\n\| rank.*?\n\|[-| ]+\n\| 1\s+\| `([^`]+)`", glance, re.S)
    assert len(blocks) == 3
    for scenario, first in blocks:
        task = task_of[first]
        if task.equal_chance_metric:                 # detectors: Pd at equal chance Pd, from summary.csv
            means = summary[summary.scenario == scenario].groupby("config").pd_equal_chance.mean()
        elif task.ranking_metric == "detected":      # Pd averaged over the levels, from summary.csv
            means = summary[summary.scenario == scenario].groupby("config").pd.mean()
        else:                                          # the per-trial metric, from trials.csv
            means = trials[trials.scenario == scenario].groupby("config")[task.ranking_metric].mean()
        best = means.idxmax() if task.ranking_higher_is_better else means.idxmin()
        assert first == best, (scenario, means)


def test_glance_ranks_detectors_at_equal_chance_pd_with_any_alarm_pd_beside(mixed):
    glance = _section((mixed / "report.md").read_text(), "Results at a glance")
    block = re.search(r"\*\*Detectors on `cv-turn-cv`\*\*(.*?)(?=\n\*\*\w+ on `|\Z)", glance, re.S).group(1)
    assert "Pd at equal chance Pd, higher is better" in block
    assert "| Pd at equal chance Pd [95% CI] | Pd (any alarm) [95% CI] | chance Pd (any alarm) |" in \
        re.sub(r" +", " ", block)
    trials = pd.read_csv(mixed / "trials.csv")
    detectors = trials[trials.scenario == "cv-turn-cv"]
    assert set(detectors.detected_equal_chance.unique()) <= {0.0, 1.0}      # a 0/1 outcome per trial
    assert trials[trials.scenario != "cv-turn-cv"].detected_equal_chance.isna().all()


@pytest.mark.parametrize("per_level, words", [(1, "not enough trials to rank"), (6, "winner")])
def test_glance_does_not_rank_on_single_trials(per_level, words):
    """One trial per level (or identical trials) gives a zero-width interval: no winner."""
    from types import SimpleNamespace
    from radarbench.bench.report.glance import comparisons_frame, glance
    from radarbench.bench.report.render import glance_markdown
    task = SimpleNamespace(name="t", noun="trackers", ranking_metric="err", ranking_higher_is_better=False,
                           ranking_label="error (m)", ranking_binary=False, equal_chance_metric="",
                           ranking_undefined="no trial has a value", unranked_reason=lambda trials: "")
    rng = np.random.default_rng(3)
    trials = pd.DataFrame([{"scenario": "s", "config": c, "snr_db": snr, "trial": i,
                            "err": base + (rng.normal() if per_level > 1 else 0.0)}
                           for c, base in (("x", 1.0), ("y", 78.0)) for snr in (0.0, 10.0) for i in range(per_level)])
    task_of = {"x": task, "y": task}
    comparisons = comparisons_frame(trials, task_of)
    text = glance_markdown(glance(trials, task_of, comparisons, {}))
    assert words in text and ("-77 on every trial" in text) == (per_level == 1) and "[-77, -77]" not in text


def test_comparisons_are_paired_differences_of_the_trials(mixed):
    comparisons = pd.read_csv(mixed / "comparisons.csv")
    trials = pd.read_csv(mixed / "trials.csv")
    det = comparisons[(comparisons.scenario == "cv-turn-cv") & comparisons.snr_db.notna()]
    assert len(det) == 2 * 3 * 4                  # any alarm and equal chance Pd: 3 pairs of 3 detectors, 4 levels
    assert set(det.metric) == {"detected", "detected_equal_chance"}
    for r in det.itertuples():
        at = trials[trials.snr_db == r.snr_db].sort_values("trial")
        a, b = (at[at.config == c][r.metric].astype(bool).to_numpy() for c in (r.config_a, r.config_b))
        assert r.difference == pytest.approx(b.mean() - a.mean())
        assert (r.only_a, r.only_b) == (int((a & ~b).sum()), int((b & ~a).sum()))
        assert r.difference_low <= r.difference <= r.difference_high
        assert (r.better == "tie") == (not r.significant)
    tracking = comparisons[comparisons.scenario == "glint"]
    assert set(tracking.metric) == {"rmse"} and tracking.mcnemar_p.isna().all()


# ------------------------------------------------------------------ report.html

def test_html_report_is_valid_and_self_contained(mixed):
    import html5lib
    text = (mixed / "report.html").read_text()
    doc = html5lib.HTMLParser(strict=True, namespaceHTMLElements=False).parse(text)
    for el in doc.iter():
        for attr in ("src", "href"):
            value = el.get(attr)
            assert value is None or value.startswith(("data:", "#")), (el.tag, attr, value[:80])
    images = [el.get("src") for el in doc.iter("img")]
    assert images and all(src.startswith("data:image/png;base64,") for src in images)
    assert len(list(doc.iter("table"))) >= 5
    assert "Plotly.newPlot" in text and "bench-interactive" not in text
    headings = [el.text for el in doc.iter("h2")]
    assert headings[0] == "Results at a glance"
    md_tables = len(re.findall(r"^\|-[-| ]+\|$", (mixed / "report.md").read_text(), re.M))
    assert len(list(doc.iter("table"))) == md_tables     # every table of report.md, the folded ones too
    # a table of contents first, linking every section and subsection, the glance first
    nav = next(doc.iter("nav"))
    links = [a.get("href") for a in nav.iter("a")]
    sections = [el for el in doc.iter() if el.tag in ("h2", "h3")]
    assert links == [f"#{el.get('id')}" for el in sections] and len(set(links)) == len(links)
    assert next(nav.iter("a")).text == "Results at a glance" and len(links) >= 5


def test_the_contents_link_each_heading_once_with_its_text_escaped():
    from radarbench.bench.report.html import with_contents
    body, contents = with_contents("<h2>A &amp; B</h2><p>x</p><h3>Sub <code>c</code></h3><h2>A &amp; B</h2>")
    assert body == ('<h2 id="a-b">A &amp; B</h2><p>x</p><h3 id="sub-c">Sub <code>c</code></h3>'
                    '<h2 id="a-b-2">A &amp; B</h2>')
    assert contents == ('<nav class="toc" aria-label="Contents"><p>Contents</p><ul>'
                        '<li class="toc-h2"><a href="#a-b">A &amp; B</a></li>'
                        '<li class="toc-h3"><a href="#sub-c">Sub c</a></li>'
                        '<li class="toc-h2"><a href="#a-b-2">A &amp; B</a></li></ul></nav>')


# ------------------------------------------------------------------ bench compare

def test_compare_a_run_with_itself_finds_nothing(detectors, capsys):
    base, _weak = detectors
    assert main(["compare", str(base), str(base), "--fail-on-regression"]) == 0
    out = capsys.readouterr().out
    assert "paired (the runs share their trials)" in out and "No significant change" in out
    assert "worse" not in out.replace("no significant change", "")


def test_compare_finds_a_weakened_method(detectors, tmp_path, capsys):
    base, weak = detectors
    code = main(["compare", str(base), str(weak), "--out", str(tmp_path / "cmp"), "--fail-on-regression"])
    captured = capsys.readouterr()
    assert code == EXIT_REGRESSION, captured.out
    diffs = pd.read_csv(tmp_path / "cmp" / "compare.csv")
    overall = diffs[diffs.snr_db.isna()]
    assert overall.paired.all()
    assert dict(zip(overall.config, overall.change)) == {"candidate": "worse", "wavelet": "no significant change"}
    assert (overall.set_index("config").difference["wavelet"] == 0)      # unchanged: the same trials, the same Pd
    assert "regression:" in captured.err
    # without the flag, the same comparison is a report, not a failure
    assert main(["compare", str(base), str(weak)]) == 0


def test_compare_refuses_pd_at_another_false_alarm_level_only_for_calibrated_configs(mixed, tmp_path, capsys):
    """The same run with its stored Pfa changed: the detectors and TBD are not comparable,
    the tracker (no calibration) is still compared, and the gate fails on the others."""
    import json
    import shutil
    import sqlite3
    other = Path(shutil.copytree(mixed, tmp_path / "other"))
    with sqlite3.connect(other / "results.sqlite") as con:
        plan = json.loads(con.execute("SELECT value FROM meta WHERE key='plan'").fetchone()[0])
        plan["sweep"]["calibration"]["pfa"] = 0.2
        con.execute("UPDATE meta SET value=? WHERE key='plan'", (json.dumps(plan),))
    assert main(["compare", str(mixed), str(other), "--out", str(tmp_path / "cmp"), "--fail-on-regression"]) \
        == EXIT_REGRESSION
    overall = pd.read_csv(tmp_path / "cmp" / "compare.csv").query("snr_db != snr_db")       # NaN: over all levels
    calibrated = overall.config.map(lambda c: _task_of(mixed)[c].calibrated)
    assert (overall[calibrated].change == "not comparable").all() and calibrated.any()
    assert (overall[~calibrated].change == "no significant change").all() and (~calibrated).any()
    assert "Pfa 0.02 in A, 0.2 in B" in capsys.readouterr().out


def test_compare_refuses_what_is_not_a_run(detectors, tmp_path, capsys):
    base, _ = detectors
    assert main(["compare", str(tmp_path), str(base)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "not a bench run folder" in err[0]


# ------------------------------------------------------------------ statistics

def test_crossing_between_levels_when_pd_jumps():
    c = fit_crossing([0, 6, 12], [0, 0, 25], [25, 25, 25])
    assert (c.kind, c.low, c.high) == ("between", 6.0, 12.0)


def test_crossing_fit_recovers_the_model_and_covers_it():
    """Counts at their expected values under a probit with floor 0.2, s50 = -4 dB:
    the MLE is the truth, and the profile interval holds it and is finite."""
    from scipy.special import ndtr, ndtri
    snr = np.arange(-15.0, 7.0, 3.0)
    floor, s50, slope, n = 0.2, -4.0, 0.3, 400
    z = ndtri((0.5 - floor) / (1 - floor))
    k = n * (floor + (1 - floor) * ndtr(z + slope * (snr - s50)))
    c = fit_crossing(snr, k, np.full(snr.size, n), floor=floor)
    assert c.kind == "fit" and c.mid == pytest.approx(s50, abs=0.01)
    assert c.low < s50 < c.high and np.isfinite(c.low) and np.isfinite(c.high) and c.high - c.low < 3


def test_paired_difference_and_mcnemar():
    a = np.array([1, 1, 1, 1, 1, 1, 0, 0, 1, 0] * 4, float)
    b = a.copy()
    assert paired_difference(a, b, np.zeros(a.size)) == (0.0, 0.0, 0.0)
    b[:6] = 0                                          # 6 trials only a detects, none only b
    assert mcnemar_exact(a, b) == (6, 0, pytest.approx(2 * 0.5 ** 6))
    diff, low, high = paired_difference(a, b, np.zeros(a.size))
    assert diff == pytest.approx(-6 / 40) and low <= diff <= high < 0


def test_vectorised_bootstrap_equals_the_resample_loop():
    from radarbench.bench.metrics import BOOTSTRAP_SEED
    sq = np.random.default_rng(3).gamma(2.0, 3.0, size=(37, 11))
    low, high = bootstrap_statistic_interval(sq, time_averaged_rmse, resamples=300)
    idx = np.random.default_rng(BOOTSTRAP_SEED).integers(0, 37, size=(300, 37))
    loop = np.array([time_averaged_rmse(sq[i]) for i in idx])
    assert (low, high) == (float(np.quantile(loop, 0.025)), float(np.quantile(loop, 0.975)))


def test_single_scenario_grids_list_each_configs_own_parameters():
    """``scenario = ...`` with a grid axis in [scenario_params]: plan.toml merges the axis
    back into one list, and each scenario config must still show its own value."""
    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.report import _params_text, _resolved_scenario_params
    sweep = tomllib.loads(textwrap.dedent("""
        name = "grid"
        scenario = "cv-turn-cv"
        trials = 4
        seed = 1
        snr_db = [0]
        [scenario_params]
        turn_rate_deg_s = [2.0, 4.5]
        detect_window_steps = 30
        [[methods]]
        name = "innovation"
    """))
    plan = parse_sweep(sweep)
    resolved = _resolved_scenario_params({"sweep": plan.to_dict()})
    texts = {label: _params_text(non_default(registry.get_scenario("cv-turn-cv"), p)) for label, p in resolved.items()}
    assert len(texts) == 2
    assert {("turn_rate_deg_s=2.0" in t, "turn_rate_deg_s=4.5" in t) for t in texts.values()} == {(True, False),
                                                                                                  (False, True)}
    assert all("detect_window_steps=30" in t for t in texts.values())


def test_differences_of_crossings_keep_their_resolution():
    from radarbench.bench.markdown import crossing_difference
    from radarbench.bench.metrics import Crossing
    fit_a, fit_b = Crossing("fit", -6.0, -6.6, -5.5), Crossing("fit", -4.0, -5.0, -3.0)
    between = Crossing("between", np.nan, 6.0, 12.0)
    assert crossing_difference(fit_a, fit_b) == "+2.0"
    assert crossing_difference(fit_a, between) == "between +12.0 and +18.0"
    assert crossing_difference(fit_a, Crossing("above", np.nan, 12.0, np.inf)) == "–"
