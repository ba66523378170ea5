"""Every packaged preset is a valid sweep; the big ones run through the CLI at reduced size."""

import importlib.resources
import re
import tomllib

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep import tomlw
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.sweep.listing import presets
from tests.conftest import parse_sweep_or_skip

PRESETS = sorted(presets())


def _preset(name: str) -> dict:
    return tomllib.loads((importlib.resources.files("radarbench.bench") / "presets" / f"{name}.toml").read_text())


@pytest.mark.parametrize("name", PRESETS)
def test_preset_is_a_valid_sweep(name):
    plan = parse_sweep_or_skip(_preset(name), f"preset {name}")
    assert plan.name == name


@pytest.mark.slow
def test_quick_preset_runs_as_the_readme_says(bench_cli, tmp_path):
    bench_cli("run", "--preset", "quick", "--quiet", cwd=tmp_path, check=True)
    out = tmp_path / "runs" / "quick"          # the default folder (git-ignored)
    for name in ("plan.toml", "results.sqlite", "trials.csv", "summary.csv", "report.md", "recording.rrd",
                 "figures/pd_vs_snr.png"):
        assert (out / name).exists(), name
    assert set(pd.read_csv(out / "summary.csv").method) == set(registry.methods())   # every method shows
    assert "None: every method config ran on every unit." in (out / "report.md").read_text().split("## Failures")[1]


@pytest.mark.slow
def test_maneuver_detection_preset_smoke(bench_cli, tmp_path):
    """The paper preset, every config, at reduced trials and SNR levels."""
    sweep = _preset("maneuver-detection")
    sweep.update(trials=8, chunk=8, snr_db={"start": -5, "stop": 15, "step": 10})
    sweep["calibration"]["h0_trials"] = 60
    path = tmp_path / "smoke.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 1, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert summary.config.nunique() == len(parse_sweep(sweep).methods)
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## ROC" in report and "## Ranking of methods" in report
    # every detector ranked under the three Pd definitions; the extra Pd columns are filled
    section = report.split("## Pd under three definitions", 1)[1].split("\n## ", 1)[0]
    assert all(f"`{c}`" in section for c in summary.config.unique())
    assert summary.pd_step.notna().all() and summary.pd_equal_chance.notna().all()
    assert "![per-step average Pd vs SNR](figures/pd_step_vs_snr.png)" in section     # the paper's Figs. 3-4
    assert (tmp_path / "out" / "figures" / "pd_step_vs_snr.png").stat().st_size > 0
    assert "at 5.0 dB" in report.split("## One trial over time", 1)[1]    # the paper's Fig. 2 level (dB to 0.1)


@pytest.mark.slow
def test_tbd_small_preset_runs_through_the_cli(bench_cli, tmp_path):
    bench_cli("run", "--preset", "tbd-small", "--quiet", "--out", tmp_path / "tbd", cwd=tmp_path, check=True)
    out = tmp_path / "tbd"
    summary = pd.read_csv(out / "summary.csv")
    assert set(summary.method) == {"dp-tbd", "dp-tbd-mf", "pf-tbd"}
    assert summary.groupby("config").pd.max().min() == 1.0          # each reaches Pd = 1 in the swept range
    assert (summary.pfa <= 0.05).all()                              # scene Pfa of the fitted tail's threshold
    report = (out / "report.md").read_text()
    assert "## Track-before-detect: null scenes and the scene threshold" in report
    for name in ("figures/tbd_pd_vs_snr.png", "figures/tbd_null_scores.png", "steps.csv", "recording.rrd"):
        assert (out / name).exists(), name


@pytest.mark.slow
def test_tbd_preset_smoke(bench_cli, tmp_path):
    """The paper preset's methods and calibration on a small grid, few trials and levels."""
    sweep = _preset("tbd")
    sweep.update(trials=6, chunk=6, snr_db=[-4, 14], scenario_params={"cells": 40})
    # 'pot' needs a tail of at least 30 of its null scenes (h0_trials >= 295, too slow for a smoke run with
    # the preset's 100 000 particles): the smoke checks the plumbing with a Gumbel fit; tbd-small runs 'pot'
    sweep["calibration"].update(h0_trials=40, mode="gumbel")
    path = tmp_path / "smoke.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 1, check=True)
    assert set(pd.read_csv(tmp_path / "out" / "summary.csv").method) == {"dp-tbd", "dp-tbd-mf", "pf-tbd"}


@pytest.mark.slow
def test_tbd_ablations_preset_smoke(bench_cli, tmp_path):
    """The ablation preset's scenarios, configs and calibration on a small grid, few trials and levels."""
    sweep = _preset("tbd-ablations")
    sweep.update(trials=4, chunk=4)
    for sc in sweep["scenarios"]:
        sc.update(snr_db=[sc["snr_db"][0], sc["snr_db"][-1]], params=sc["params"] | {"cells": 40})
    sweep["calibration"].update(h0_trials=30, mode="gumbel")     # as in test_tbd_preset_smoke
    path = tmp_path / "smoke.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 1, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert summary.groupby("scenario").config.nunique().to_dict() == {"ar": 7, "white": 7, "ar-swerling1": 7}
    assert (summary[summary.scenario == "white"].snr_offset_unit_innovation_db == 0).all()
    assert summary[summary.scenario == "ar"].snr_offset_unit_innovation_db.iloc[0] > 12
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Track-before-detect: SNR reference" in report
    assert "Reduction of the all-runs average RMSE" in report
    cal = pd.read_csv(tmp_path / "out" / "calibration.csv")
    assert (cal.cell_pfa_low <= cal.cell_pfa).all() and (cal.cell_pfa <= cal.cell_pfa_high).all()
    assert "per-cell Pfa" in report


def _run_reduced(bench_cli, tmp_path, sweep: dict):
    """Run a reduced copy of a preset (a sweep file in ``tmp_path``) on two workers; its run folder."""
    path = tmp_path / "reduced.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 2, check=True)
    return tmp_path / "out"


@pytest.mark.slow
def test_glint_tracking_preset_at_reduced_size(bench_cli, tmp_path):
    """The glint preset through the CLI at reduced trials and duration (the end-to-end test of the tracking suite)."""
    sweep = _preset("glint-tracking")
    sweep.update(trials=4, chunk=4)
    for entry in sweep["scenarios"]:
        entry["params"]["steps"] = 40
    out = _run_reduced(bench_cli, tmp_path, sweep)
    summary = pd.read_csv(out / "summary.csv")
    assert summary.config.nunique() == 9 and summary.scenario.nunique() == 7
    assert {f"viterbi-paper-1d[n={n}]" for n in (1, 3, 9, 27)} | {"huber-ekf"} <= set(summary.config)
    assert summary.rmse_mean.notna().all() and (summary.rmse_low <= summary.rmse_high).all()
    # the bound is the scene's, the same for every config; efficiency = bound / RMSE (with 4 trials it
    # may exceed 1 by sampling error)
    assert (summary.pcrb_rmse > 0).all() and (summary.groupby(["scenario", "snr_db"]).pcrb_rmse.nunique() == 1).all()
    np.testing.assert_allclose(summary.efficiency, summary.pcrb_rmse / summary.rmse_mean)
    steps = pd.read_csv(out / "steps.csv")
    assert {"rmse_position", "mean_est_x", "mean_true_x", "pcrb_position"} <= set(steps.columns)
    report = (out / "report.md").read_text()
    assert "## Tracking: position RMSE" in report and "## Calibration" not in report


@pytest.mark.slow
def test_cfar_preset_smoke(bench_cli, tmp_path):
    """The CFAR preset's scenario configs, detectors and calibration on small maps, few maps and levels."""
    from radarbench.scenarios.rd_map import RdMap

    sweep = _preset("cfar")
    sweep.update(trials=6, chunk=6, snr_db=[8, 24])
    for sc in sweep["scenarios"]:
        sc["params"] = dict(RdMap.small_params) | sc["params"]
        sc.pop("trials", None)
        sc.pop("snr_db", None)
    sweep["calibration"]["h0_trials"] = 20
    path = tmp_path / "smoke.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 1, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    assert set(summary.method) == {"ca-cfar", "os-cfar", "go-cfar", "so-cfar", "regression-cfar", "region-adaptive"}
    assert set(summary.scenario) == {"rd-map-mixed", "rd-map-homogeneous", "rd-map-edge"} | {
        f"rd-map-bragg-{strength}-{offset}" for strength in ("strong", "weak") for offset in (0, 2, 4)}
    report = (tmp_path / "out" / "report.md").read_text()
    assert "which detector wins where" in report and "CFAR loss" in report
    assert "None: every method config ran on every unit." in report.split("## Failures")[1], "a config failed"
    assert (tmp_path / "out" / "figures" / "cells_rd_map_detections.png").exists()


@pytest.mark.slow
def test_multi_target_preset_smoke(bench_cli, tmp_path):
    """The multi-target preset's scenario configs and trackers, few trials and short runs; the
    Stone Soup peers run when the [peers] extra is installed and are listed as not run otherwise
    (the MFA peer also needs the extra's OR-Tools)."""
    sweep = _preset("multi-target")
    sweep.update(trials=2, chunk=2)
    for sc in sweep["scenarios"]:
        sc["params"] |= {"scans": 12, "targets": 3}
    path = tmp_path / "smoke.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 1, check=True)
    summary = pd.read_csv(tmp_path / "out" / "summary.csv")
    report = (tmp_path / "out" / "report.md").read_text()
    ran = {peer: peer in registry.methods() for peer in ("stonesoup-jpda", "stonesoup-gmphd", "stonesoup-mfa")}
    assert ran["stonesoup-gmphd"] == ran["stonesoup-jpda"] >= ran["stonesoup-mfa"]   # one extra; MFA: OR-Tools too
    assert set(summary.method) == {"jpda-ukf", "gnn-ekf"} | {peer for peer, here in ran.items() if here}
    assert summary.scenario.nunique() == 5 and summary.gospa_mean.notna().all()
    assert "## Multi-target tracking: paired comparison" in report
    for peer, here in ran.items():                                            # Markdown-escaped
        assert (f"`{peer}` ({peer}): needs the \\[peers\\] extra" in report) != here


@pytest.mark.slow
def test_ar_tracking_preset_at_reduced_size(bench_cli, tmp_path):
    """The ar-tracking preset through the CLI at reduced trials: every tracker on every
    maneuvering config, the quiet / maneuver / onset split and the paired table."""
    sweep = _preset("ar-tracking")
    sweep.update(trials=6, chunk=6)
    for entry in sweep["scenarios"]:
        entry.pop("trials", None)
    path = tmp_path / "ar.toml"
    path.write_text(tomlw.dumps(sweep))
    bench_cli("run", path, "--out", tmp_path / "out", "--quiet", "--workers", 2, check=True)
    out = tmp_path / "out"
    summary = pd.read_csv(out / "summary.csv")
    configs = tomllib.loads((out / "plan.toml").read_text())["methods"]      # a grid entry is several configs
    assert summary.config.nunique() == len(configs) and {"ar-adaptive", "vd-filter"} <= set(summary.config)
    assert set(summary[summary.config == "imm-cv-ct"].scenario) == {"planar-turn"}     # a turn needs two axes
    maneuvering = summary[summary.scenario != "no-maneuver"]
    assert maneuvering.rmse_onset.notna().all() and summary[summary.scenario == "no-maneuver"].rmse_onset.isna().all()
    assert (maneuvering.rmse_onset_low <= maneuvering.rmse_onset_high).all()
    report = (out / "report.md").read_text()
    assert "### Paired differences against the first method config" in report
    assert re.search(r"\|\s*`default`\s*\|\s*0\s*\|\s*`vd-filter`\s*\|", report)


@pytest.mark.slow
def test_real_trajectories_preset_at_reduced_size(bench_cli, tmp_path):
    """The real-aircraft preset through the CLI at reduced trials (needs the [data] extra):
    every tracker and detector on both scenario configs, a trial in the plane (the claims
    table is a preset's own: a reduced copy is a sweep file, without it)."""
    parse_sweep_or_skip(_preset("real-trajectories"), "preset real-trajectories")
    sweep = _preset("real-trajectories")
    sweep.update(trials=8, chunk=8, snr_db=[0, 10])
    sweep["calibration"]["h0_trials"] = 100
    out = _run_reduced(bench_cli, tmp_path, sweep)
    summary = pd.read_csv(out / "summary.csv")
    assert set(summary.scenario) == {s["label"] for s in _preset("real-trajectories")["scenarios"]}
    assert {"imm-cv-ca", "ar-adaptive", "innovation[window=1]", "cumulant[window=16]"} <= set(summary.config)
    assert summary[summary.method == "cv-kf"].rmse_maneuver.notna().all()
    report = (out / "report.md").read_text()
    assert "## Tracking: one trial in the plane" in report
    assert (out / "figures" / "tracking_trial_plane_calibration.png").exists()
