"""Every packaged preset is a valid sweep; the big ones run through the CLI at reduced size."""

import importlib.resources
import tomllib

import pandas as pd
import pytest

from bench import tomlw
from bench.config import parse_sweep

PRESETS = sorted(p.name[:-5] for p in (importlib.resources.files("bench") / "presets").iterdir()
                 if p.name.endswith(".toml"))


def _preset(name: str) -> dict:
    return tomllib.loads((importlib.resources.files("bench") / "presets" / f"{name}.toml").read_text())


@pytest.mark.parametrize("name", PRESETS)
def test_preset_is_a_valid_sweep(name):
    plan = parse_sweep(_preset(name), f"preset {name}")
    assert plan.name == name


def test_quick_preset_runs_as_the_readme_says(bench_cli, tmp_path):
    bench_cli("run", "--preset", "quick", "--quiet", cwd=tmp_path, check=True)
    out = tmp_path / "reports" / "quick"
    for name in ("plan.toml", "results.sqlite", "trials.csv", "summary.csv", "report.md", "recording.rrd",
                 "figures/pd_vs_snr.png"):
        assert (out / name).exists(), name
    assert set(pd.read_csv(out / "summary.csv").method) == {"innovation", "cumulant", "wavelet"}


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
