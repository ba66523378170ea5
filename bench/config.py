"""Sweep files: reading and checking the TOML into the resolved plan.

A sweep file (TOML; its fields are described in docs/architecture.md,
'Sweep files and presets') is validated completely before any work is done.
Every problem raises :class:`~bench.errors.ConfigError` naming the field,
e.g. ``methods[1].params.window: expected int >= 3, got -2``.

The result is a :class:`~bench.plan.Plan` (:mod:`bench.plan`: the plan's dataclasses,
importable from here too); grid axes and config labels expand in :mod:`bench.grid`.
``plan.toml`` keeps each method's label, so re-running it gives the same identities and
the same results.

Scenarios: either one ``scenario`` name with ``[scenario_params]``, or
several ``[[scenarios]]`` tables, each with ``name``, ``params`` (grid axes
allowed) and optionally its own ``snr_db``, ``trials`` and ``label``; the
top-level ``snr_db`` and ``trials`` are their defaults. Each method config
runs on every scenario config that serves its task (``Scenario.tasks``), so
one sweep (the ``quick`` preset) can cover detection, tracking and
track-before-detect.
"""

from __future__ import annotations

import math
import os
import re
import dataclasses
import itertools
import tomllib
from pathlib import Path
from typing import Any, Mapping

from radarbench.bench import capabilities, feasibility, registry
from radarbench.bench.errors import ConfigError
from radarbench.bench.grid import MAX_CONFIGS, expand, label_problem, params_text_of_label
from radarbench.bench.params import as_float, show
from radarbench.bench.plan import (SNR_KEY_DIGITS, CalibrationConfig, ComponentConfig, Plan,  # noqa: F401 - importable from here
                        ScenarioConfig, snr_key)

#: trials per unit when a sweep sets no ``chunk``
DEFAULT_CHUNK = 50
TOP_KEYS = {"name", "description", "scenario", "scenarios", "trials", "seed", "snr_db", "chunk",
            "scenario_params", "methods", "calibration", "record", "provenance", "unit_timeout_s",
            "max_unit_memory_gb"}
SCENARIO_KEYS = {"name", "params", "label", "snr_db", "trials"}
METHOD_KEYS = {"name", "params", "label", "optional"}
CALIBRATION_MODES = ("nominal", "empirical", "gumbel", "pot")
NAME_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}\Z")     # \Z: "$" would let a final newline in
#: config labels: readable like "cumulant-as-printed", "glint[epsilon=0.05]" or "mylab:glr" (a
#: qualified name, bench.registry), never path-like: a file or entity name made of a label
#: goes through bench.recording.paths.entity_name, which keeps only letters, digits and '_.-'

LABEL_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.,:=+\-\[\]() ]{0,199}\Z")
MAX_SNR_LEVELS = 1000
#: |SNR| bound (dB): beyond it powers overflow and nothing physical is left to measure
MAX_ABS_SNR_DB = 200.0
#: a sweep file is read only up to this size: a bigger one is refused before it is parsed
MAX_SWEEP_BYTES = 1_000_000
#: trial-runs (trials x SNR levels x configs) above which a sweep needs --yes
LARGE_SWEEP_TRIAL_RUNS = 50_000_000
#: longest per-unit time limit (``unit_timeout_s``): a week
MAX_UNIT_TIMEOUT_S = 7 * 24 * 3600.0
#: the smallest ``calibration.pfa``: every nominal threshold (chi-square upper quantiles by
#: the survival-function inverse, Sidak shares pfa / k down to k = 8 levels) is finite at it,
#: where a share of a smaller pfa could underflow to 0 (an infinite threshold)
MIN_PFA = 1e-300
#: bounds of ``max_unit_memory_gb`` (GB = 2^30 bytes): a megabyte at least, a petabyte at most
MIN_UNIT_MEMORY_GB, MAX_UNIT_MEMORY_GB = 0.001, 1e6


# --------------------------------------------------------------------------- checks

def _expect_table(value: Any, field: str) -> dict:
    if not isinstance(value, dict):
        raise ConfigError(field, f"expected a table, got {type(value).__name__} {value!r}"[:200])
    return value


def _expect_int(value: Any, field: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise ConfigError(field, f"expected int in [{lo}, {hi}], got {show(value)}"[:200])
    return value


def _expect_number(value: Any, field: str) -> float:
    number = as_float(value)           # None for non-numbers and integers beyond a float's range
    if number is None or not math.isfinite(number):
        raise ConfigError(field, f"expected a finite number, got {show(value)}"[:200])
    return number


def _reject_unknown(table: Mapping, allowed: set, field: str) -> None:
    for key in table:
        if key not in allowed:
            where = f"{field}.{key}" if field else str(key)
            raise ConfigError(where, f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _check_snr_bound(value: float, field: str) -> float:
    if abs(value) > MAX_ABS_SNR_DB:
        raise ConfigError(field, f"expected an SNR in [-{MAX_ABS_SNR_DB:g}, {MAX_ABS_SNR_DB:g}] dB, got {value:g}")
    return value


def _parse_snr(value: Any, field: str = "snr_db") -> tuple[float, ...]:
    if isinstance(value, dict):
        _reject_unknown(value, {"start", "stop", "step"}, field)
        for key in ("start", "stop", "step"):
            if key not in value:
                raise ConfigError(f"{field}.{key}", "missing (a range needs start, stop and step)")
        start, stop, step = (_expect_number(value[k], f"{field}.{k}") for k in ("start", "stop", "step"))
        if step <= 0:
            raise ConfigError(f"{field}.step", f"expected a number > 0, got {step!r}")
        if stop < start:
            raise ConfigError(f"{field}.stop", f"expected >= start ({start:g}), got {stop:g}")
        _check_snr_bound(start, f"{field}.start")
        _check_snr_bound(stop, f"{field}.stop")
        levels = (stop - start) / step       # counted, never built, before it is known to be small
        count = math.floor(levels + 1e-9) + 1 if levels < MAX_SNR_LEVELS else math.inf
        if count > MAX_SNR_LEVELS:
            raise ConfigError(field, f"{levels + 1:.3g} levels; at most {MAX_SNR_LEVELS}")
        values = [round(start + i * step, 9) for i in range(count)]
    elif isinstance(value, list):
        if not value:
            raise ConfigError(field, "empty list: give at least one SNR value")
        if len(value) > MAX_SNR_LEVELS:
            raise ConfigError(field, f"{len(value)} levels; at most {MAX_SNR_LEVELS}")
        values = [round(_check_snr_bound(_expect_number(v, f"{field}[{i}]"), f"{field}[{i}]"), 9)
                  for i, v in enumerate(value)]
    else:
        values = [round(_check_snr_bound(_expect_number(value, field), field), 9)]
    seen: dict[str, float] = {}
    for v in values:
        if v in seen.values():         # by value: -0.0 repeats 0.0
            raise ConfigError(field, f"repeated SNR value {v:g}")
        key = snr_key(v)
        if key in seen:
            raise ConfigError(field, f"SNR levels {seen[key]!r} and {v!r} are one level at the precision of "
                                     f"a unit's key ({SNR_KEY_DIGITS} significant digits, {key}); "
                                     "keep one of them")
        seen[key] = v
    return tuple(sorted(values))


def _parse_methods(value: Any, scenarios: tuple[ScenarioConfig, ...], base: str | None = None
                   ) -> tuple[tuple[ComponentConfig, ...], tuple[str, ...], tuple[tuple[dict, str], ...]]:
    """The method configs, the sweep field (``methods[i]``) each comes from, and
    the ``optional = true`` entries skipped because their method is unavailable
    here (each with the reason)."""
    if not isinstance(value, list) or not value:
        raise ConfigError("methods", "expected at least one [[methods]] table")
    configs: list[ComponentConfig] = []
    fields: list[str] = []
    skipped: list[tuple[dict, str]] = []
    seen: dict[str, str] = {}
    for i, entry in enumerate(value):
        field = f"methods[{i}]"
        entry = _expect_table(entry, field)
        _reject_unknown(entry, METHOD_KEYS, field)
        if "name" not in entry or not isinstance(entry["name"], str):
            raise ConfigError(f"{field}.name", "missing method name (a string)")
        optional = entry.get("optional", False)
        if not isinstance(optional, bool):
            raise ConfigError(f"{field}.optional", f"expected true or false, got {optional!r}"[:200])
        reason = registry.missing_reason("method", entry["name"])
        if optional and reason is not None:
            skipped.append(({k: v for k, v in entry.items() if k != "optional"}, reason))
            continue
        cls = registry.get_method(entry["name"], f"{field}.name")
        _check_runs_somewhere(cls, scenarios, f"{field}.name")
        params = _expect_table(entry.get("params", {}), f"{field}.params")
        # the name as written: a qualified name ("mylab:glr") stays in the labels and plan.toml
        expanded = expand(entry["name"], cls.Params, params, f"{field}.params", base=base)
        if "label" in entry:
            label = entry["label"]
            if not isinstance(label, str) or not LABEL_PATTERN.match(label):
                raise ConfigError(f"{field}.label", "expected letters, digits, spaces or '_.,:=+-[]()' "
                                                    f"(at most 200, no path separators), got {label!r}"[:200])
            if len(expanded) != 1:
                raise ConfigError(f"{field}.label", "a label names one config; remove the grid (list) values")
            c = expanded[0]
            problem = label_problem(c.name, label, c.params, bare_means_defaults=True)
            if problem:
                raise ConfigError(f"{field}.label", problem)
            expanded = [ComponentConfig(c.name, c.params, label, params_text_of_label(c.name, label))]
        for c in expanded:
            if c.label in seen:
                raise ConfigError(field, f"config {c.label!r} repeats {seen[c.label]}")
            seen[c.label] = field
        configs.extend(expanded)
        fields.extend([field] * len(expanded))
    if not configs:
        raise ConfigError("methods", "every method of the sweep is optional and unavailable here: "
                                     + "; ".join(f"{e['name']}: {r}" for e, r in skipped))
    if len(configs) > MAX_CONFIGS:
        raise ConfigError("methods", f"{len(configs)} method configs; at most {MAX_CONFIGS}")
    return tuple(configs), tuple(fields), tuple(skipped)


def _check_runs_somewhere(cls, scenarios: tuple[ScenarioConfig, ...], field: str) -> None:
    """ConfigError naming what is missing unless method ``cls`` runs on some scenario
    config of the sweep (:func:`bench.capabilities.missing`): the first config of its
    task that lacks a capability, or the tasks the sweep's scenarios serve."""
    if any(capabilities.fits(cls, registry.get_scenario(s.name), s.params) for s in scenarios):
        return
    same_task = [s for s in scenarios if cls.task in s.tasks]
    if not same_task:
        names = ", ".join(sorted({f"{s.name!r} ({'/'.join(s.tasks)})" for s in scenarios}))
        raise ConfigError(field, f"method {cls.name!r} ({cls.task}) cannot run on any scenario of the sweep: "
                                 f"{names} (none serves {cls.task})")
    s = same_task[0]
    problem = capabilities.missing(cls, registry.get_scenario(s.name), s.params)
    where = "" if s.label == s.name else f" (config {s.label!r})"
    raise ConfigError(field, f"{problem}{where}"[:400])


def _why_idle(plan: Plan, scenario: ScenarioConfig) -> str:
    """': ' and what the first method config of its task lacks on ``scenario``, if one does."""
    for m in plan.methods:
        problem = capabilities.missing(registry.get_method(m.name), registry.get_scenario(scenario.name),
                                       scenario.params)
        if problem and registry.get_method(m.name).task in scenario.tasks:
            return f": {problem}"
    return ""


def _scenario_configs(name: str, params: Any, field: str, snr_db: tuple[float, ...], trials: int,
                      identity: str, label: Any = None, base: str | None = None) -> list[ScenarioConfig]:
    cls = registry.get_scenario(name, f"{field}.name" if field != "scenario_params" else "scenario")
    table = _expect_table(params, field)
    expanded = expand(name, cls.Params, table, field, identity=identity, base=base)
    if label is not None:
        if not isinstance(label, str) or not LABEL_PATTERN.match(label):
            raise ConfigError(field.replace(".params", ".label"), "expected letters, digits, spaces or "
                                                                  f"'_.,:=+-[]()' (at most 200), got {label!r}"[:200])
        if len(expanded) != 1:
            raise ConfigError(field.replace(".params", ".label"), "a label names one config; remove the grid")
        problem = label_problem(name, label, expanded[0].params, bare_means_defaults=False)
        if problem:
            raise ConfigError(field.replace(".params", ".label"), problem)
        expanded = [ComponentConfig(name, expanded[0].params, label, expanded[0].params_text)]
    labels = [c.label for c in expanded]
    for i, label in enumerate(labels):
        if label in labels[:i]:                  # e.g. a float axis [1, 1.0]
            raise ConfigError(field, f"two configs of the grid are both {label!r}; remove the repeated value")
    return [ScenarioConfig(c.name, c.params, c.label, c.params_text, snr_db, trials, tuple(cls.tasks))
            for c in expanded]


def _parse_scenarios(data: Mapping[str, Any], trials: int, base: str | None = None
                     ) -> tuple[str, tuple[ScenarioConfig, ...], tuple[str, ...]]:
    """``(scenario name or "", configs, the sweep field of each config's params)`` from
    either scenario form."""
    if "scenarios" in data:
        for key in ("scenario", "scenario_params"):
            if key in data:
                raise ConfigError(key, "give either 'scenario' (+ 'scenario_params') or [[scenarios]], not both")
        entries = data["scenarios"]
        if not isinstance(entries, list) or not entries:
            raise ConfigError("scenarios", "expected at least one [[scenarios]] table")
        if len(entries) > MAX_CONFIGS:
            raise ConfigError("scenarios", f"{len(entries)} entries; at most {MAX_CONFIGS}")
        names = [e.get("name") if isinstance(e, dict) else None for e in entries]
        configs: list[ScenarioConfig] = []
        fields: list[str] = []
        for i, entry in enumerate(entries):
            field = f"scenarios[{i}]"
            entry = _expect_table(entry, field)
            _reject_unknown(entry, SCENARIO_KEYS, field)
            if not isinstance(entry.get("name"), str):
                raise ConfigError(f"{field}.name", "missing scenario name (a string)")
            if "snr_db" not in entry and "snr_db" not in data:
                raise ConfigError(f"{field}.snr_db", "missing (and no top-level snr_db to default to)")
            snr = _parse_snr(entry["snr_db"], f"{field}.snr_db") if "snr_db" in entry \
                else _parse_snr(data["snr_db"])
            n = _expect_int(entry.get("trials", trials), f"{field}.trials", 1, 10_000_000)
            identity = "explicit" if names.count(entry["name"]) > 1 else "grid"
            added = _scenario_configs(entry["name"], entry.get("params", {}), f"{field}.params", snr, n,
                                      identity, entry.get("label"), base)
            configs += added
            fields += [f"{field}.params"] * len(added)
        seen: set[str] = set()
        for c in configs:
            if c.label in seen:
                raise ConfigError("scenarios", f"two scenario configs are both named {c.label!r}; "
                                               "give one of them a 'label'")
            seen.add(c.label)
        return "", tuple(configs), tuple(fields)
    for key in ("scenario", "snr_db"):
        if key not in data:
            raise ConfigError(key, "missing")
    if not isinstance(data["scenario"], str):
        raise ConfigError("scenario", f"expected a scenario name, got {data['scenario']!r}"[:200])
    configs = _scenario_configs(data["scenario"], data.get("scenario_params", {}), "scenario_params",
                                _parse_snr(data["snr_db"]), trials, "grid", base=base)
    return configs[0].name, tuple(configs), ("scenario_params",) * len(configs)


def _parse_calibration(value: Any) -> CalibrationConfig:
    table = _expect_table(value, "calibration")
    _reject_unknown(table, {"pfa", "mode", "h0_trials", "chance_pd"}, "calibration")
    default = CalibrationConfig()
    pfa = _expect_number(table.get("pfa", default.pfa), "calibration.pfa")
    if not MIN_PFA <= pfa < 0.5:
        raise ConfigError("calibration.pfa", f"expected a number in [{MIN_PFA:g}, 0.5), got {pfa!r} "
                                             "(smaller ones underflow the thresholds' tail probabilities)")
    mode = table.get("mode", default.mode)
    if mode not in CALIBRATION_MODES:
        raise ConfigError("calibration.mode", f"expected one of {', '.join(map(repr, CALIBRATION_MODES))}, got {mode!r}"[:200])
    h0 = _expect_int(table.get("h0_trials", default.h0_trials), "calibration.h0_trials", 10, 10_000_000)
    chance_pd = _expect_number(table.get("chance_pd", default.chance_pd), "calibration.chance_pd")
    if not 0 < chance_pd <= 0.5:
        raise ConfigError("calibration.chance_pd", f"expected a number in (0, 0.5], got {chance_pd!r}")
    if mode == "pot":
        _check_pot(pfa, h0)
    return CalibrationConfig(pfa, mode, h0, float(chance_pd))


def _check_pot(pfa: float, h0_trials: int) -> None:
    """``pot`` fits the largest POT_TAIL_FRACTION of the null scores: the Pfa must lie in
    that tail, and the tail must hold enough scores to fit (:func:`bench.calibration.pot_fit`)."""
    from radarbench.bench.calibration import POT_MIN_TAIL, POT_TAIL_FRACTION, pot_tail_count
    if pfa >= POT_TAIL_FRACTION:
        raise ConfigError("calibration.pfa", f"'pot' fits the largest {POT_TAIL_FRACTION:g} of the null scores "
                                             f"and needs a Pfa below it, got {pfa!r}")
    if pot_tail_count(h0_trials) < POT_MIN_TAIL:
        least = next(n for n in itertools.count(h0_trials) if pot_tail_count(n) >= POT_MIN_TAIL)
        raise ConfigError("calibration.h0_trials", f"'pot' fits at least {POT_MIN_TAIL} null scores in its tail: "
                                                   f"needs h0_trials >= {least}, got {h0_trials}")


def parse_sweep(data: Mapping[str, Any], source: str = "<sweep>", *, allow_large: bool = False,
                base: str | os.PathLike | None = None) -> Plan:
    """Validate a parsed sweep mapping and resolve it into a :class:`Plan`. ``base``: the
    folder of the sweep file, from which its data paths (``kind="path"`` parameters) are
    read and made absolute; None: they are kept as written (a resolved plan)."""
    _reject_unknown(data, TOP_KEYS, "")
    for key in ("name", "methods"):
        if key not in data:
            raise ConfigError(key, "missing")
    name = data["name"]
    if not isinstance(name, str) or not NAME_PATTERN.match(name):
        raise ConfigError("name", "expected letters, digits, '_', '-' or '.' (at most 64, no path "
                                  f"separators), got {name!r}"[:200])
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ConfigError("description", f"expected a string, got {description!r}"[:200])
    trials = _expect_int(data.get("trials", 100), "trials", 1, 10_000_000)
    base = None if base is None else os.path.abspath(base)
    scenario, scenarios, scenario_fields = _parse_scenarios(data, trials, base)
    seed = _expect_int(data.get("seed", 0), "seed", 0, 2**63 - 1)
    chunk = _expect_int(data.get("chunk", DEFAULT_CHUNK), "chunk", 1, 1_000_000)
    snr_db = _parse_snr(data["snr_db"]) if "snr_db" in data else scenarios[0].snr_db
    methods, method_fields, skipped = _parse_methods(data["methods"], scenarios, base)
    method_tasks = tuple(registry.get_method(m.name).task for m in methods)
    calibration = _parse_calibration(data.get("calibration", {}))
    for i, (m, task) in enumerate(zip(methods, method_tasks)):
        modes = registry.get_task(task, f"{method_fields[i]}.name").calibration_modes
        if calibration.mode not in modes:
            raise ConfigError("calibration.mode", f"{calibration.mode!r} does not apply to {m.label!r} ({task}); "
                                                  f"use one of {', '.join(map(repr, modes))}")
        cls = registry.get_method(m.name)
        if calibration.mode == "nominal" and registry.get_task(task).calibrated and not cls.has_nominal_threshold():
            others = ", ".join(repr(x) for x in modes if x != "nominal")
            raise ConfigError("calibration.mode", f"'nominal' needs an analytic threshold and {m.label!r} has none "
                                                  f"(it is calibrated on null trials): use {others}")
    record = _expect_table(data.get("record", {}), "record")
    _reject_unknown(record, {"trials", "timeline_snr_db"}, "record")
    record_trials = _expect_int(record.get("trials", 1), "record.trials", 0, 1000)
    timeline_snr_db = None if "timeline_snr_db" not in record else \
        _check_snr_bound(_expect_number(record["timeline_snr_db"], "record.timeline_snr_db"), "record.timeline_snr_db")
    unit_timeout_s = _parse_unit_timeout(data["unit_timeout_s"]) if "unit_timeout_s" in data else None
    memory_gb = None
    if "max_unit_memory_gb" in data:
        memory_gb = _expect_number(data["max_unit_memory_gb"], "max_unit_memory_gb")
        if not MIN_UNIT_MEMORY_GB <= memory_gb <= MAX_UNIT_MEMORY_GB:
            raise ConfigError("max_unit_memory_gb", f"expected a number in [{MIN_UNIT_MEMORY_GB:g}, "
                                                    f"{MAX_UNIT_MEMORY_GB:g}] (GB), got {memory_gb:g}")
    axes = tuple(k for k in data.get("scenario_params", {}) if isinstance(k, str)) if scenario else ()
    plan = Plan(name, description, scenario, scenarios, trials, seed, snr_db, chunk,
                methods, calibration, record_trials, source, method_tasks, timeline_snr_db, unit_timeout_s, axes, memory_gb,
                skipped)
    feasibility.check_snr_levels(plan, scenario_fields)
    plan = dataclasses.replace(plan, skipped=feasibility.check_pairs(plan, method_fields))
    idle = [s for s in scenarios if not plan.pairs(s)]
    if idle:
        raise ConfigError("methods", f"no method of the sweep runs on scenario config {idle[0].label!r}"
                                     f"{_why_idle(plan, idle[0])}"[:400])
    feasibility.check_unit_memory(plan, scenario_fields)
    feasibility.check_scenario_configs(plan, scenario_fields)
    if plan.trial_runs > LARGE_SWEEP_TRIAL_RUNS and not allow_large:
        raise ConfigError("trials", f"the sweep asks for {plan.trial_runs:,} trial-runs "
                                    f"(trials x SNR levels x configs); pass --yes to run it anyway")
    calibration_runs = _calibration_trial_runs(plan)
    if plan.trial_runs + calibration_runs > LARGE_SWEEP_TRIAL_RUNS and not allow_large:
        raise ConfigError("calibration.h0_trials", f"the sweep asks for {calibration_runs:,} null-hypothesis "
                                                   f"trial-runs (h0_trials x calibrated configs) besides "
                                                   f"{plan.trial_runs:,} others; pass --yes to run it anyway")
    return plan


def _parse_unit_timeout(value: Any) -> float:
    """``unit_timeout_s``: seconds in (0, a week] (an int too large for a float is out of range too)."""
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not number or not (isinstance(value, float) and math.isfinite(value) or isinstance(value, int)) \
            or not 0 < value <= MAX_UNIT_TIMEOUT_S:
        raise ConfigError("unit_timeout_s", f"expected seconds in (0, {MAX_UNIT_TIMEOUT_S:g}], got {value!r}"[:200])
    return float(value)


def _calibration_trial_runs(plan: Plan) -> int:
    """h0_trials x (scenario config, method config) pairs whose threshold is calibrated."""
    pairs = sum(1 for s in plan.scenarios for m in plan.pairs(s)
                if registry.get_task(registry.get_method(m.name).task).calibrated)
    return plan.calibration.h0_trials * pairs


def load_sweep(path: str | Path, *, allow_large: bool = False) -> Plan:
    """Read and validate a sweep file. Raises ConfigError (field '' for file-level problems)."""
    path = Path(path)
    try:
        with path.open("rb") as f:
            raw = f.read(MAX_SWEEP_BYTES + 1)      # bounded: never a huge file (or a pipe) in memory
    except OSError as exc:
        raise ConfigError("", f"cannot read the file ({exc.strerror or exc})") from None
    return parse_sweep_text(raw, str(path), allow_large=allow_large, base=path.parent)


def parse_sweep_text(raw: bytes, source: str, *, allow_large: bool = False,
                     base: str | os.PathLike | None = None) -> Plan:
    if len(raw) > MAX_SWEEP_BYTES:
        raise ConfigError("", f"more than {MAX_SWEEP_BYTES:,} bytes; a sweep file is at most that "
                              "(a grid axis that long would not run anyway)")
    try:
        text = raw.decode("utf-8-sig")        # a leading byte-order mark (Windows editors) is fine
    except UnicodeDecodeError as exc:
        raise ConfigError("", f"not UTF-8 text (byte {exc.start})") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", f"invalid TOML: {exc}") from None
    except ValueError as exc:                 # an integer of more than 4300 digits
        raise ConfigError("", f"invalid TOML: {str(exc).split(';')[0]}") from None
    except RecursionError:
        raise ConfigError("", "invalid TOML: nested too deeply") from None
    return parse_sweep(data, source, allow_large=allow_large, base=base)
