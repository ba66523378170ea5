"""A unit's results taken from the user's results cache instead of computed
(docs/architecture.md, 'Results cache'; the cache itself: :mod:`bench.run.results_cache`).

A unit's results are cached in parts, each keyed by everything that computes it and by
nothing that merely names it (no label, no sweep, no run folder):

- its **scene part**: the columns every method config shares (trial, seed, realised SNR),
  the scene's seconds and SNR definition, and what its tasks record of each recorded
  trial's scene; keyed by the scenario config's content key and identity
  (:func:`bench.run.identity.content_keys`, :func:`bench.run.identity.plan_identities`: every
  parameter, the seed, the code, data files and library versions), the phase, the SNR
  level, the trials (first and count: each trial's stream is its own, :mod:`bench.sweep.rng`),
  how many of them are recorded and, then, the tasks that record them;
- one **run part** per method config: its per-trial metrics or null statistics (with
  the nominal threshold), its seconds and its trace on each recorded trial; keyed by the
  scene part's key, the method config's content key and identity, and the calibration it
  depends on: the threshold it ran at (an evaluation unit, the exact float) or the Pfa
  (a calibration unit's nominal threshold).

Only runs that succeeded are cached. A unit whose scene part and every run part are
cached is stored without being computed; one with some run parts cached runs only the
other method configs, and is stored once those are back (merged), so a run stopped in
between stores nothing half.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from radarbench.bench.run.identity import content_keys
from radarbench.bench.sweep.plan import Plan, snr_key
from radarbench.bench.recording.record import TrialRecord
from radarbench.bench.run.results_cache import ResultsCache, key_digest
from radarbench.bench.results.store import MethodRun, UnitResult
from radarbench.bench.run.units import Unit, UnitTask, plan_units, task_of, unit_methods

#: how a unit's parts are keyed and laid out; changing either changes this
SCHEME = 1
#: the one label a cached trace is kept under (the config's own label is the plan's)
_TRACE = "m"


def merge_records(parts: list[UnitResult], order: list[str]) -> list[tuple[int, bytes]]:
    """The trial records of one unit whose method configs ran separately (or came in part
    from the cache): one record per trial holding every config's trace (in the order
    ``order``, labels) and every task's view of the scene."""
    if len(parts) == 1:
        return parts[0].records
    records: dict[int, TrialRecord] = {}
    for part in parts:
        for trial, blob in part.records:
            rec = TrialRecord.from_bytes(blob)
            if trial not in records:
                records[trial] = rec
                continue
            base = records[trial]
            base.methods.update(rec.methods)
            base.arrays.update(rec.arrays)
            base.images.update(rec.images)
            base.info.update(rec.info)
    rank = {label: i for i, label in enumerate(order)}
    out = []
    for trial in sorted(records):
        rec = records[trial]
        rec.methods = dict(sorted(rec.methods.items(), key=lambda kv: rank.get(kv[0], len(rank))))
        out.append((trial, rec.to_bytes()))
    return out


def merged(parts: list[UnitResult], order: list[str]) -> UnitResult:
    """One unit's result from parts holding different method configs (the first part's
    scene columns and seconds), its runs in the order ``order`` (labels)."""
    rank = {label: i for i, label in enumerate(order)}
    runs = {run.label: run for part in parts for run in part.runs}
    return replace(parts[0], runs=sorted(runs.values(), key=lambda run: rank.get(run.label, len(rank))),
                   records=merge_records(parts, order))


class Reuse:
    """The results cache as one run of ``plan`` uses it: serves tasks, keeps what was computed."""

    def __init__(self, plan: Plan, identities: dict[str, dict[str, str]], cache: ResultsCache):
        self.plan, self.cache, self.identities = plan, cache, identities
        self.contents = content_keys(plan)
        self.thresholds: dict[str, dict[str, float | None]] = {}    # evaluation: set once calibrated
        self.pending: dict[str, UnitResult] = {}                   # unit key -> its cached part
        self.units = {u.key: u for phase in plan_units(plan) for u in phase}
        self.whole = 0            # units taken from the cache whole
        self.partly = 0           # units of which some method configs were taken from the cache

    # ---------------------------------------------------------------- keys
    def recorded(self, unit: Unit) -> list[int]:
        """The trials of ``unit`` whose records are kept."""
        if unit.phase != "evaluation":
            return []
        return list(range(unit.trial_start, min(unit.trial_start + unit.n, self.plan.record_trials)))

    def _scene_parts(self, unit: Unit) -> list:
        label = unit.scenario_label
        recorded = len(self.recorded(unit))
        tasks = [task_of(mc).name for mc in unit_methods(UnitTask(self.plan, unit))] if recorded else []
        return [SCHEME, self.contents["scenarios"][label], self.identities["scenarios"].get(label), unit.phase,
                snr_key(unit.snr_db), unit.trial_start, unit.n, recorded, list(dict.fromkeys(tasks))]

    def scene_key(self, unit: Unit) -> str:
        return key_digest(["scene", *self._scene_parts(unit)])

    def run_key(self, unit: Unit, label: str) -> str:
        if unit.phase == "calibration":
            calibration = ["pfa", self.plan.calibration.pfa]
        else:
            threshold = self.thresholds.get(unit.scenario_label, {}).get(label)
            calibration = ["threshold", None if threshold is None else float(threshold).hex()]
        return key_digest(["run", *self._scene_parts(unit), self.contents["methods"][label],
                           self.identities["methods"].get(label), calibration])

    # ---------------------------------------------------------------- serving
    def serve(self, task: UnitTask) -> tuple[UnitResult | None, tuple[str, ...]]:
        """What the cache holds of ``task``'s unit (None: nothing usable) and the method
        configs still to compute (labels)."""
        labels = [mc.label for mc in unit_methods(task)]
        scene = self.cache.get(self.scene_key(task.unit))
        if scene is None:
            return None, tuple(labels)
        runs, missing = [], []
        for label in labels:
            entry = self.cache.get(self.run_key(task.unit, label))
            if entry is None:
                missing.append(label)
            else:
                runs.append(self._run_of(label, entry))
        if not runs:
            return None, tuple(labels)
        return self._result(task.unit, scene, runs), tuple(missing)

    def _run_of(self, label: str, entry) -> tuple[MethodRun, dict[int, bytes]]:
        header, arrays = entry
        run = MethodRun(label, header["seconds"], nominal_threshold=header["nominal"])
        metrics = {name[len("metric:"):]: a for name, a in arrays.items() if name.startswith("metric:")}
        run.metrics = metrics if header["phase"] == "evaluation" else None
        run.null_values, run.null_peaks, run.null_cells = (arrays.get(f"null:{part}")
                                                           for part in ("values", "peaks", "cells"))
        return run, {int(name[len("trace:"):]): a.tobytes() for name, a in arrays.items()
                     if name.startswith("trace:")}

    def _result(self, unit: Unit, scene, runs: list[tuple[MethodRun, dict[int, bytes]]]) -> UnitResult:
        header, arrays = scene
        common = {name[len("common:"):]: a for name, a in arrays.items() if name.startswith("common:")}
        records = []
        for trial in self.recorded(unit):
            rec = TrialRecord.from_bytes(arrays[f"record:{trial}"].tobytes())
            rec.scenario = unit.scenario_label
            rec.methods = {run.label: TrialRecord.from_bytes(traces[trial]).methods[_TRACE] for run, traces in runs}
            records.append((trial, rec.to_bytes()))
        return UnitResult(unit.key, unit.phase, unit.scenario_label, unit.snr_db, unit.trial_start, unit.n,
                          header["seconds"], runs=[run for run, _ in runs], common=common, records=records,
                          snr_definition=header["snr_definition"])

    # ---------------------------------------------------------------- keeping
    def completed(self, result: UnitResult, whole: bool) -> UnitResult:
        """Keep ``result`` (computed; ``whole``: by one task of every method config of its
        unit) in the cache, and return it merged with the unit's cached part, if any."""
        unit = self.units.get(result.key)
        if unit is not None:
            labels = [mc.label for mc in unit_methods(UnitTask(self.plan, unit))]
            if whole and {run.label for run in result.runs} >= set(labels) and result.common:
                self._keep_scene(unit, result)
            for run in result.runs:
                if run.error is None:
                    self._keep_run(unit, result, run)
        cached = self.pending.pop(result.key, None)
        if cached is None:
            return result
        return merged([cached, result], [m.label for m in self.plan.methods])

    def _keep_scene(self, unit: Unit, result: UnitResult) -> None:
        records = dict(result.records)
        if any(trial not in records for trial in self.recorded(unit)):
            return
        arrays = {f"common:{name}": np.asarray(a) for name, a in result.common.items()}
        for trial in self.recorded(unit):
            rec = TrialRecord.from_bytes(records[trial])
            arrays[f"record:{trial}"] = np.frombuffer(replace(rec, scenario="", methods={}).to_bytes(), np.uint8)
        self.cache.put(self.scene_key(unit), {"seconds": result.generate_seconds,
                                              "snr_definition": result.snr_definition}, arrays)

    def _keep_run(self, unit: Unit, result: UnitResult, run: MethodRun) -> None:
        arrays = {f"metric:{name}": np.asarray(a) for name, a in (run.metrics or {}).items()}
        for part in ("values", "peaks", "cells"):
            value = getattr(run, f"null_{part}")
            if value is not None:
                arrays[f"null:{part}"] = np.asarray(value)
        records = dict(result.records)
        for trial in self.recorded(unit):
            rec = TrialRecord.from_bytes(records[trial]) if trial in records else None
            if rec is None or run.label not in rec.methods:
                return                      # a trace it lacks: not kept (never served short)
            trace = TrialRecord(scenario="", snr_db=rec.snr_db, trial=rec.trial, t=rec.t,
                                methods={_TRACE: rec.methods[run.label]})
            arrays[f"trace:{trial}"] = np.frombuffer(trace.to_bytes(), np.uint8)
        self.cache.put(self.run_key(unit, run.label), {"seconds": run.seconds, "nominal": run.nominal_threshold,
                                                       "phase": unit.phase}, arrays)
