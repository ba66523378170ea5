"""One method's failure never stops the others; a broken plugin never breaks the registry."""

import sys
from dataclasses import dataclass

import pandas as pd
import pytest

from bench import registry
from bench.config import parse_sweep
from bench.core import MANEUVER_DETECTION, Method
from bench.params import param
from bench.report import build_outputs
from bench.runner import plan_record, run_sweep
from methods.innovation import Innovation


class Fragile(Method):
    """Innovation detector that raises at high SNR (a stand-in for a buggy plugin)."""

    name = "fragile"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        fail_above_db: float = param(5.0, "raise on units above this SNR (dB)")

    def run(self, batch, params):
        if batch.meta["realised_snr_db"].mean() > params.fail_above_db:
            raise FloatingPointError("simulated failure")
        return Innovation().run(batch, Innovation.Params(window=1))

    def nominal_threshold(self, params, pfa, batch):
        return Innovation().nominal_threshold(Innovation.Params(window=1), pfa, batch)


@pytest.fixture
def fragile():
    registry.register_method(Fragile)
    yield
    registry._METHODS.pop("fragile", None)


def test_a_failing_method_is_recorded_and_the_rest_completes(fragile, tmp_path):
    plan = parse_sweep({"name": "iso", "scenario": "cv-turn-cv", "trials": 6, "chunk": 3, "snr_db": [0, 10],
                        "methods": [{"name": "fragile"}, {"name": "innovation"}],
                        "calibration": {"h0_trials": 30}})
    store = run_sweep(plan, tmp_path, plan_record=plan_record(plan, "test"), workers=1, quiet=True)
    runs = store.runs()
    store.close()
    failed = runs[runs.error.notna()]
    assert set(failed.method) == {"fragile"} and set(failed.snr_db) == {10.0}
    assert failed.error.str.contains("FloatingPointError: simulated failure").all()
    build_outputs(tmp_path, recording=False)
    trials = pd.read_csv(tmp_path / "trials.csv")
    assert len(trials[trials.config == "innovation"]) == 12          # untouched
    assert len(trials[trials.config == "fragile"]) == 6              # only the 0 dB units
    report = (tmp_path / "report.md").read_text()
    assert "simulated failure" in report.split("## Failures")[1]


def test_a_broken_plugin_module_is_listed_as_unavailable(tmp_path, monkeypatch):
    pkg = tmp_path / "someplugins"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "broken.py").write_text("import numpy\nraise ImportError('needs libfoo 2.0')\n")
    (pkg / "fine.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "_UNAVAILABLE", [])
    registry._import_package_modules("someplugins")
    assert registry._UNAVAILABLE == [registry.Unavailable("someplugins.broken", "ImportError: needs libfoo 2.0")]
    assert "someplugins.fine" in sys.modules
