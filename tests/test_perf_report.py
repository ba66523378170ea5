"""``bench perf`` report layout: the scene-generation table (no speed is asserted)."""

import re

import numpy as np
import pandas as pd
import pytest

from radarbench.bench import registry
from radarbench.bench.sweep.capabilities import fits
from radarbench.bench.cli.perf import PERF_COLUMNS, SCENE_COLUMNS, accepted_sizes, jobs, scene_jobs, write_report


def test_scene_jobs_cover_every_scenarios_sizes():
    """Every size of every registered scenario is timed, also those no method job reaches
    (generic: no scenario is named); ``--methods`` keeps the scenes the methods accept."""
    registry.discover()
    every = {(j.scenario, j.size): j.trials for j in scene_jobs()}
    assert every == {(name, size): trials for name, cls in registry.scenarios().items()
                     for size, (_, trials) in cls.perf_sizes.items()}
    reached = {(j.scenario, j.size) for j in jobs()}
    assert reached <= set(every)                          # every size a method job times is a scene job
    for method in ("cv-kf", "dp-tbd"):
        cls = registry.get_method(method)
        picked = {(j.scenario, j.size) for j in scene_jobs([method])}
        assert picked == {(name, size) for name, scenario in registry.scenarios().items()
                          for size in accepted_sizes(cls, scenario)}
        assert {(j.scenario, j.size) for j in jobs([method])} <= picked
        assert all(cls.task in registry.get_scenario(name).tasks for name, _ in picked)
    assert [(j.scenario, j.size) for j in scene_jobs(sizes=["small"])] == \
        [key for key in every if key[1] == "small"]


def test_a_size_reading_a_file_is_timed_on_one_its_scenario_writes(monkeypatch):
    """A scenario's ``perf_data`` writes the file its size reads into the measuring process's
    temporary folder (removed after); a size that cannot be generated is reported, not timed."""
    from dataclasses import dataclass
    from pathlib import Path

    from radarbench.bench.cli import perf
    from radarbench.bench.core import Scenario
    from radarbench.bench.errors import ConfigError

    registry.discover()
    written = []

    class ReadsAFile(Scenario):
        name = "reads-a-file"
        perf_sizes = {"tiny": ({}, 3), "absent": ({"needs": "an extra"}, 3)}

        @dataclass(frozen=True)
        class Params:
            path: str = ""
            needs: str = ""

        def perf_data(self, size, folder):
            written.append(folder / "data.txt")
            written[-1].write_text("3")
            return {"path": str(written[-1])}

        def generate(self, params, snr_db, n, rng):
            if params.needs:
                raise ConfigError("needs", f"install {params.needs}")
            return int(Path(params.path).read_text()) * n

    monkeypatch.setitem(registry._SCENARIOS, ReadsAFile.name, ReadsAFile)
    monkeypatch.setattr(registry, "discover", lambda: None)
    tiny, absent = [j for j in scene_jobs() if j.scenario == ReadsAFile.name]
    assert (tiny.size, absent.size) == ("tiny", "absent")
    timed = perf.measure_scene(tiny)
    assert timed["seconds_per_trial"] >= 0 and timed["skipped"] == ""
    assert written and not written[0].exists()                       # the temporary folder is gone
    refused = perf.measure_scene(absent)
    assert refused["skipped"] == "needs: install an extra" and pd.isna(refused["seconds_per_trial"])


def test_report_has_scene_generation_table_and_csv(tmp_path):
    registry.discover()
    scenes = pd.DataFrame([["tbd-grid", "paper", 4, 0.0123, 400.0, ""],
                           ["tbd-grid", "small", 20, float("nan"), float("nan"), "path: no such file"]],
                          columns=SCENE_COLUMNS)
    report = write_report(tmp_path, pd.DataFrame(columns=PERF_COLUMNS), [], None, scenes=scenes)
    text = re.sub(" +", " ", report.read_text())                                  # padded cells
    assert "## Scene generation" in text
    assert "| `tbd-grid` | paper | 4 | 12.3 | 400 | ≤ 0.02 s/trial: 0.0123 ✓ |" in text
    assert "| `tbd-grid` | small | 20 | – | – | not timed: path: no such file |" in text
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "scene.csv", keep_default_na=False, na_values=[""])
                                  .fillna({"skipped": ""}), scenes)


def test_each_method_is_timed_on_a_scenario_it_accepts(monkeypatch):
    """``bench perf`` times a method on the first scenario of its task whose perf size its
    ``check_scenario`` accepts, never on one it refuses (generic: no scenario is named)."""
    from dataclasses import dataclass

    from radarbench.bench.core import TRACKING, Method
    from radarbench.bench.params import build_params
    from radarbench.bench.cli.perf import jobs

    registry.discover()
    tracking = [s for s in registry.scenarios().values() if TRACKING in s.tasks]
    assert len(tracking) >= 2
    refused_name = tracking[0].name

    class RefusesTheFirst(Method):
        name, task = "refuses-the-first", TRACKING

        @dataclass(frozen=True)
        class Params:
            pass

        def check_scenario(self, params, scenario_params):
            return "not this one" if type(scenario_params) is tracking[0].Params else None

    monkeypatch.setitem(registry._METHODS, RefusesTheFirst.name, RefusesTheFirst)
    picked = {job.scenario for job in jobs([RefusesTheFirst.name])}
    assert picked == {tracking[1].name} != {refused_name}
    for job in jobs():
        cls = registry.get_method(job.method)
        scenario = registry.get_scenario(job.scenario)
        resolved = build_params(scenario.Params, job.scenario_params)
        assert fits(cls, scenario, resolved)
        assert cls().check_scenario(build_params(cls.Params, {}), resolved) is None


def _perf_rows():
    base = {"trials": 100, "seconds_per_trial": 1e-4, "reference": "ref", "reference_seconds_per_trial": 2e-3,
            "speedup": 20.0, "peak_rss_mb": 300.0}
    return [{**base, "method": "ca-cfar", "size": "small", "trials_per_second": 1e4, "cells_per_second": 4.6e7},
            {**base, "method": "dp-tbd", "size": "paper", "trials_per_second": 1e4,
             "transitions_per_second": 3e10},
            {**base, "method": "cv-kf", "size": "default", "trials_per_second": 1e4, "chunk": 25,
             "chunk_seconds_per_trial": 3e-4}]


def test_perf_csv_has_a_rate_column_per_work_unit(tmp_path):
    """Every row has trials_per_second; each other work unit (``Method.work``) gets its
    ``<unit>_per_second`` column, empty for methods counting another unit."""
    from radarbench.bench.cli.perf import perf_table, rate_columns

    registry.discover()
    perf = perf_table(_perf_rows())
    assert list(perf.columns) == PERF_COLUMNS + ["cells_per_second", "transitions_per_second"]
    assert rate_columns(perf) == ["trials_per_second", "cells_per_second", "transitions_per_second"]
    extra = [{"scenario": "rd-map", "params": {}, "reference_trials": 100, "targets": {}},
             {"scenario": "tbd-grid", "params": {}, "reference_trials": 4,
              "targets": {"paper": {"transitions_per_second": 1e10}}},
             {"scenario": "maneuvering-1d", "params": {}, "reference_trials": 20,
              "targets": {"*": {"cells_per_second": 1.0}}}]
    text = re.sub(" +", " ", write_report(tmp_path, perf, extra, None).read_text())
    assert "| trials/s per core | cells/s per core | transitions/s per core |" in text
    assert "| `ca-cfar` | small | 100 | 0.1 | – | 1e+04 | 4.6e+07 | – | ref |" in text
    assert "| `cv-kf` | default | 100 | 0.1 | 0.3 (25 trials; ×3) | 1e+04 |" in text   # the fixed cost per call
    assert "≥ 1e+10 transitions/s: 3.00e+10 ✓" in text
    assert "≥ 1e+00 cells/s: nan ✗" in text                     # a goal in a unit the method does not count
    written = pd.read_csv(tmp_path / "perf.csv")
    assert written["cells_per_second"].tolist()[0] == 4.6e7 and written["cells_per_second"].isna().tolist()[1:] \
        == [True, True]
    assert written["transitions_per_second"].notna().tolist() == [False, True, False]


def _burn(seconds: float) -> float:
    """Spend ``seconds`` of this thread's CPU time; return what was spent."""
    import time

    t0 = time.thread_time()
    while time.thread_time() - t0 < seconds:
        pass
    return time.thread_time() - t0


def _burning_method(monkeypatch, name: str, reference_name: str, reference_trials: int, reference_run,
                    **members) -> str:
    """Register a tracking method ``name`` whose run burns 1 ms of CPU and whose reference is
    ``reference_run(method, batch)``; returns its name."""
    from dataclasses import dataclass

    from radarbench.bench.core import TRACKING, Method

    @dataclass(frozen=True)
    class Params:
        pass

    cls = type(name, (Method,), {"name": name, "task": TRACKING, "Params": Params, "reference_name": reference_name,
                                 "reference_trials": reference_trials, "run": lambda self, batch, params: _burn(1e-3),
                                 "reference_run": lambda self, batch, params: reference_run(self, batch), **members})
    monkeypatch.setitem(registry._METHODS, name, cls)
    return name


def test_a_reference_part_timed_apart_gets_a_second_row(monkeypatch, tmp_path):
    """A reference declaring ``reference_parts`` gets two rows against the same method time:
    the whole reference, and the reference less the CPU seconds it reported for the part."""
    from radarbench.bench.cli import perf

    registry.discover()

    def reference_run(method, batch):
        method.reference_part_seconds = {"setup": _burn(6e-3)}
        _burn(3e-3)

    name = _burning_method(monkeypatch, "with-a-part", "a loop", 2, reference_run,
                           reference_parts={"setup": "set-up"})
    _in_this_process(monkeypatch)
    perf.run_perf(tmp_path, methods=[name], progress=lambda _: None)
    rows = pd.read_csv(tmp_path / "perf.csv")
    assert rows.reference.tolist() == ["a loop", "a loop, without its set-up (timed apart)"]
    assert rows.seconds_per_trial.nunique() == 1                          # one method time, two references
    whole, less = rows.reference_seconds_per_trial * perf.jobs([name])[0].reference_trials   # per call
    assert 6e-3 <= whole - less < whole and less >= 3e-3


def test_a_reference_is_timed_on_its_whole_batch_and_per_trial_the_faster_kept(monkeypatch, tmp_path):
    """A reference whose cost grows faster than its batch (a vectorised peer outgrowing the
    caches) is timed one trial per call; one with a large cost per call on its whole batch;
    the row says which, and its time is that way's."""
    from radarbench.bench.cli import perf

    registry.discover()

    def reference(name: str, seconds_of_call):
        return _burning_method(monkeypatch, name, "a peer", 4, lambda method, batch: _burn(seconds_of_call(batch.n)))

    quadratic = reference("grows-with-its-batch", lambda n: 1e-3 * n * n)      # 16 ms whole, 4 x 1 ms per trial
    fixed = reference("costs-per-call", lambda n: 4e-3 + 1e-4 * n)             # 4.4 ms whole, 4 x 4.1 ms per trial
    _in_this_process(monkeypatch)
    perf.run_perf(tmp_path, methods=[quadratic, fixed], progress=lambda _: None)
    rows = pd.read_csv(tmp_path / "perf.csv").set_index("method")
    assert rows.reference_mode.to_dict() == {quadratic: "per trial", fixed: "whole batch"}
    assert 1e-3 <= rows.reference_seconds_per_trial[quadratic] < 4e-3
    assert 1.1e-3 <= rows.reference_seconds_per_trial[fixed] < 4.1e-3
    text = re.sub(" +", " ", (tmp_path / "report.md").read_text())
    assert "(4 trials, per trial)" in text and "(4 trials, whole batch)" in text


#: limits of a made-up machine (``bench.run.limits.measure_limits``' keys)
MACHINE = {"bytes_per_second": 1e10, "float32_operations_per_second": 4e10, "float64_operations_per_second": 2e10,
           "stream_bytes": 1 << 28, "last_level_cache_bytes": 1 << 27}


def _in_this_process(monkeypatch):
    """``run_perf`` measuring in this process (no spawn), on :data:`MACHINE`'s limits, without scenes."""
    from radarbench.bench.cli import perf

    monkeypatch.setattr(perf, "_in_fresh_process", perf.measure)
    monkeypatch.setattr(perf, "machine_limits", lambda: MACHINE)
    monkeypatch.setattr(perf, "measure_scenes", lambda jobs, progress: pd.DataFrame(columns=SCENE_COLUMNS))


def test_the_least_time_at_the_limits_is_the_larger_of_bytes_and_operations():
    """A roofline: a cost's least time is its slowest kind of work at the machine's limits."""
    from radarbench.bench.run.limits import limit_fraction

    assert limit_fraction({"bytes": 2e9}, 1.0, MACHINE) == (0.2, "bytes_per_second")
    assert limit_fraction({"bytes": 2e9, "float32_operations": 2e10}, 1.0, MACHINE) == \
        (0.5, "float32_operations_per_second")
    assert limit_fraction({"float64_operations": 1e10}, 2.0, MACHINE) == (0.25, "float64_operations_per_second")


def test_the_add_max_loop_computes_what_it_counts():
    """The compute ceiling's loop does one add and one max per element and pass (so its count is honest)."""
    from radarbench.bench.run.limits import _add_max_kernel

    x = np.linspace(-3.0, 1.0, 40, dtype=np.float32)
    acc = np.zeros_like(x)
    _add_max_kernel()(acc, x, np.arange(3, dtype=np.float32))
    np.testing.assert_array_equal(acc, np.maximum(0, x + 2))


def test_the_last_level_cache_is_the_largest_one_listed(tmp_path):
    from radarbench.bench.run.limits import last_level_cache_bytes

    for index, size in enumerate(["48K", "2048K", "300M", "garbage"]):
        (tmp_path / f"index{index}").mkdir()
        (tmp_path / f"index{index}" / "size").write_text(size + "\n")
    assert last_level_cache_bytes(tmp_path) == 300 << 20
    assert last_level_cache_bytes(tmp_path / "absent") is None


def test_a_rows_fraction_of_the_machine_limit_is_its_least_cost_over_its_time(monkeypatch, tmp_path):
    """The limits measured are in the report's header and ``limits.csv``; a method declaring its least
    cost gets its fraction with the binding limit, one giving a reason a dash and that reason as a note."""
    from dataclasses import dataclass

    from radarbench.bench.cli import perf
    from radarbench.bench.core import TRACKING, Method

    registry.discover()

    @dataclass(frozen=True)
    class NoParams:
        pass

    class Streams(Method):
        name, task, Params = "streams", TRACKING, NoParams

        def run(self, batch, params):
            _burn(2e-3)

        def least_cost(self, batch, params, output):
            return {"bytes": 1e6 * batch.n, "float64_operations": 1e3}

    class Branches(Streams):
        name = "branches"

        def least_cost(self, batch, params, output):
            return "it branches on the data"

    for cls in (Streams, Branches):
        monkeypatch.setitem(registry._METHODS, cls.name, cls)
    _in_this_process(monkeypatch)
    perf.run_perf(tmp_path, methods=[Streams.name, Branches.name], progress=lambda _: None)
    rows = pd.read_csv(tmp_path / "perf.csv").set_index("method")
    seconds = rows.loc["streams", "seconds_per_trial"]                 # per trial: 1e6 bytes at 1e10 B/s
    assert rows.loc["streams", "limit_fraction"] == pytest.approx(1e-4 / seconds)
    assert rows.loc["streams", "limit"] == "bytes_per_second"
    assert pd.isna(rows.loc["branches", "limit_fraction"]) and rows.loc["branches", "limit_note"] == \
        "it branches on the data"
    text = re.sub(" +", " ", (tmp_path / "report.md").read_text())
    assert "memory bandwidth 10 GB/s" in text and "40 G float32 and 20 G float64 operations/s" in text
    assert f"| {1e-4 / seconds:.2g} (memory bandwidth) |" in text
    assert "| — (note 1) |" in text and "Notes: (1) it branches on the data" in text
    assert pd.read_csv(tmp_path / "limits.csv").iloc[0].to_dict() == MACHINE


def test_a_reference_whose_peer_is_not_installed_is_reported_not_timed(monkeypatch, tmp_path):
    """A reference that needs an optional extra absent here (the Stone Soup peers without
    ``[peers]``) leaves its row's reference columns empty with the reason, the method timed,
    and its speed-up target *not measured*; ``bench perf`` does not stop."""
    from radarbench.bench.cli import perf

    registry.discover()

    def reference_run(method, batch):
        raise registry.PluginError('needs the [peers] extra (pip install -e ".[peers]"): no stonesoup')

    name = _burning_method(monkeypatch, "peer-absent", "a peer", 2, reference_run)
    monkeypatch.setattr(registry.get_method(name), "perf_targets", {"*": {"speedup": 20.0}})
    _in_this_process(monkeypatch)
    perf.run_perf(tmp_path, methods=[name], progress=lambda _: None)
    row = pd.read_csv(tmp_path / "perf.csv").iloc[0]
    assert row.reference == 'a peer: not timed, needs the [peers] extra (pip install -e ".[peers]"): no stonesoup'
    assert np.isnan(row.reference_seconds_per_trial) and np.isnan(row.speedup) and row.seconds_per_trial > 0
    assert "speed-up ≥ 20: – not measured" in (tmp_path / "report.md").read_text()
