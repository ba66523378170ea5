"""Sweep files: reading and checking the TOML into the resolved plan.

A sweep file (TOML; its fields are described in docs/architecture.md,
'Sweep files and presets') is validated completely before any work is done.
Every problem raises :class:`~bench.errors.ConfigError` naming the field,
e.g. ``methods[1].params.window: expected int >= 3, got -2``.

The result is a :class:`~bench.sweep.plan.Plan` (:mod:`bench.sweep.plan`: the plan's dataclasses,
importable from here too); grid axes and config labels expand in :mod:`bench.sweep.grid`.
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

import copy
import dataclasses
import itertools
import math
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from radarbench.bench.sweep import capabilities, feasibility
from radarbench.bench import registry
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.grid import MAX_CONFIGS, expand, named
from radarbench.bench.params import as_float, show
from radarbench.bench.sweep.plan import (SNR_KEY_DIGITS, CalibrationConfig, ComponentConfig, Plan,  # noqa: F401 - importable from here
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
        if "label" in entry and len(expanded) != 1:
            raise ConfigError(f"{field}.label", "a label names one config; remove the grid (list) values")
        expanded = [named(c, entry.get("label"), f"{field}.params", bare_means_defaults=True) for c in expanded]
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
    config of the sweep (:func:`bench.sweep.capabilities.missing`): the first config of its
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
    if label is not None and len(expanded) != 1:
        raise ConfigError(field.replace(".params", ".label"), "a label names one config; remove the grid")
    # a scenario config's params column stays what its parameters say, whatever its label
    expanded = [dataclasses.replace(named(c, label, field, bare_means_defaults=False), params_text=c.params_text)
                for c in expanded]
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
                base: str | os.PathLike | None = None, drop_idle_scenarios: bool = False) -> Plan:
    """Validate a parsed sweep mapping and resolve it into a :class:`Plan`. ``base``: the
    folder of the sweep file, from which its data paths (``kind="path"`` parameters) are
    read and made absolute; None: they are kept as written (a resolved plan).
    ``drop_idle_scenarios``: a scenario config no method config runs on is left out
    (``bench run --methods``) rather than refused."""
    fields = check_sweep_fields(data)
    name, trials, calibration = fields["name"], fields["trials"], fields["calibration"]
    base = None if base is None else os.path.abspath(base)
    scenario, scenarios, scenario_fields = _parse_scenarios(data, trials, base)
    snr_db = fields["snr_db"] if fields["snr_db"] is not None else scenarios[0].snr_db
    methods, method_fields, skipped = _parse_methods(data["methods"], scenarios, base)
    method_tasks = tuple(registry.get_method(m.name).task for m in methods)
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
    axes = tuple(k for k in data.get("scenario_params", {}) if isinstance(k, str)) if scenario else ()
    plan = Plan(name, fields["description"], scenario, scenarios, trials, fields["seed"], snr_db, fields["chunk"],
                methods, calibration, fields["record_trials"], source, method_tasks, fields["timeline_snr_db"],
                fields["unit_timeout_s"], axes, fields["max_unit_memory_gb"], skipped,
                sweep_folder=base)
    feasibility.check_snr_levels(plan, scenario_fields)
    plan = dataclasses.replace(plan, skipped=feasibility.check_pairs(plan, method_fields))
    idle = [s for s in scenarios if not plan.pairs(s)]
    if idle and drop_idle_scenarios and len(idle) < len(scenarios):
        kept = [i for i, s in enumerate(scenarios) if s not in idle]
        scenarios, scenario_fields = tuple(scenarios[i] for i in kept), tuple(scenario_fields[i] for i in kept)
        plan, idle = dataclasses.replace(plan, scenarios=scenarios), []
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


def check_sweep_fields(data: Mapping[str, Any]) -> dict[str, Any]:
    """The sweep's own fields, those no plugin is needed to check (name, trials, seed,
    chunk, snr_db, calibration, record, limits), checked and resolved: ``bench run`` calls
    it before the plugins are imported, so a mistake there is answered at once."""
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
    record = _expect_table(data.get("record", {}), "record")
    _reject_unknown(record, {"trials", "timeline_snr_db"}, "record")
    memory_gb = None
    if "max_unit_memory_gb" in data:
        memory_gb = _expect_number(data["max_unit_memory_gb"], "max_unit_memory_gb")
        if not MIN_UNIT_MEMORY_GB <= memory_gb <= MAX_UNIT_MEMORY_GB:
            raise ConfigError("max_unit_memory_gb", f"expected a number in [{MIN_UNIT_MEMORY_GB:g}, "
                                                    f"{MAX_UNIT_MEMORY_GB:g}] (GB), got {memory_gb:g}")
    return {
        "name": name, "description": description,
        "trials": _expect_int(data.get("trials", 100), "trials", 1, 10_000_000),
        "seed": _expect_int(data.get("seed", 0), "seed", 0, 2**63 - 1),
        "chunk": _expect_int(data.get("chunk", DEFAULT_CHUNK), "chunk", 1, 1_000_000),
        "snr_db": _parse_snr(data["snr_db"]) if "snr_db" in data else None,
        "calibration": _parse_calibration(data.get("calibration", {})),
        "record_trials": _expect_int(record.get("trials", 1), "record.trials", 0, 1000),
        "timeline_snr_db": None if "timeline_snr_db" not in record else _check_snr_bound(
            _expect_number(record["timeline_snr_db"], "record.timeline_snr_db"), "record.timeline_snr_db"),
        "unit_timeout_s": _parse_unit_timeout(data["unit_timeout_s"]) if "unit_timeout_s" in data else None,
        "max_unit_memory_gb": memory_gb,
    }


def check_names(data: Mapping[str, Any], absent: Callable[[str, str], str]) -> None:
    """The plugin names of a sweep whose fields passed :func:`check_sweep_fields` checked
    before the plugins are imported: each scenario's and each method's that is not
    ``optional``, in the order :func:`parse_sweep` meets them, ``absent(kind, name)``
    saying why a name names none ("" when it does; :func:`bench.registry.absent_from`).
    What is not a name here (a wrong type) is left to :func:`parse_sweep`."""
    wanted: list[tuple[str, Any, str]] = []
    if isinstance(data.get("scenarios"), list):
        wanted += [("scenario", e.get("name"), f"scenarios[{i}].name")
                   for i, e in enumerate(data["scenarios"]) if isinstance(e, dict)]
    else:
        wanted.append(("scenario", data.get("scenario"), "scenario"))
    if isinstance(data.get("methods"), list):
        wanted += [("method", e.get("name"), f"methods[{i}].name")
                   for i, e in enumerate(data["methods"]) if isinstance(e, dict) and not e.get("optional", False)]
    for kind, name, field in wanted:
        problem = absent(kind, name) if isinstance(name, str) else ""
        if problem:
            raise ConfigError(field, problem)


@dataclass(frozen=True)
class Overrides:
    """Changes the command line makes to a sweep before it is checked
    (``bench run --methods ... --snr ... --set KEY=VALUE``; docs/running.md)."""

    methods: tuple[str, ...] = ()        # method names or config labels: the sweep's matching entries, or new ones
    scenarios: tuple[str, ...] = ()      # scenario names or labels, likewise
    snr_db: tuple[float, ...] = ()
    trials: int | None = None
    seed: int | None = None
    sets: tuple[str, ...] = ()           # "KEY=VALUE": a dotted key of the sweep, a TOML value

    def __bool__(self) -> bool:
        return self != Overrides()

    def origin(self, field: str) -> str | None:
        """Where sweep field ``field`` came from when the command line wrote it, for an
        error's first words (``--snr: snr_db[0]``, ``--trials``, ``--set calibration.pfa``);
        None when the sweep did."""
        written = [(key.partition("=")[0].strip(), "--set " + key.partition("=")[0].strip()) for key in self.sets]
        written += [(k, o) for k, o, v in (("methods", "--methods", self.methods), ("scenario", "--scenarios",
                    self.scenarios), ("scenarios", "--scenarios", self.scenarios), ("snr_db", "--snr", self.snr_db),
                    ("trials", "--trials", self.trials), ("seed", "--seed", self.seed)) if v not in ((), None)]
        dotted = re.sub(r"\[(\d+)\]", r".\1", field)         # methods[0].params -> methods.0.params
        for key, option in written:
            if key in (field, dotted):
                return option
            if field.startswith((f"{key}.", f"{key}[")) or dotted.startswith(f"{key}."):
                return f"{option}: {field}"
        return None


def apply_overrides(data: Mapping[str, Any], overrides: Overrides) -> dict[str, Any]:
    """A copy of sweep ``data`` with ``overrides`` applied; the result is checked like any
    sweep (:func:`parse_sweep`), so the command line gets the TOML's messages."""
    if not overrides:
        return dict(data)
    try:
        out = copy.deepcopy(dict(data))
    except RecursionError:
        raise ConfigError("", "invalid TOML: nested too deeply") from None
    if overrides.methods:
        out["methods"] = _chosen(out.get("methods"), overrides.methods, "--methods")
    if overrides.scenarios:
        if "scenarios" in out or "scenario" not in out:
            out["scenarios"] = _chosen(out.get("scenarios"), overrides.scenarios, "--scenarios")
        else:
            single = {"name": out.pop("scenario"), "params": out.pop("scenario_params", {})}
            out["scenarios"] = _chosen([single], overrides.scenarios, "--scenarios")
    for key, value in (("snr_db", list(overrides.snr_db)), ("trials", overrides.trials)):
        if value not in ([], None):
            out[key] = value
            for entry in out.get("scenarios", []) if isinstance(out.get("scenarios"), list) else []:
                if isinstance(entry, dict):
                    entry.pop(key, None)          # the command line's value for every scenario config
    if overrides.seed is not None:
        out["seed"] = overrides.seed
    for assignment in overrides.sets:
        _set(out, assignment)
    return out


def _chosen(entries: Any, names: tuple[str, ...], option: str) -> list:
    """The ``[[methods]]`` (or ``[[scenarios]]``) entries named (by name or label) in
    ``names``, in that order; a name no entry has becomes a new entry of its defaults."""
    entries = entries if isinstance(entries, list) else []
    chosen = []
    for name in names:
        matching = [e for e in entries if isinstance(e, dict) and name in (e.get("name"), e.get("label"))]
        chosen += copy.deepcopy(matching) or [{"name": name}]
    return chosen


def _set(data: dict, assignment: str) -> None:
    """``--set KEY=VALUE``: KEY a dotted path into the sweep (``calibration.h0_trials``,
    ``methods.0.params.window``), VALUE a TOML value (a bare word is a string)."""
    key, sep, text = assignment.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError("--set", f"expected KEY=VALUE (e.g. calibration.h0_trials=500), got {assignment!r}"[:200])
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text.strip()
    *path, last = key.split(".")
    node: Any = data
    for i, part in enumerate(path):
        node = _step(node, part, ".".join(path[:i + 1]), key, create=True)
    if isinstance(node, list):
        _step(node, last, key, key, create=False)
        node[int(last)] = value
    elif isinstance(node, dict):
        node[last] = value
    else:
        raise ConfigError(f"--set {key}", f"{'.'.join(path)} is not a table")


def _step(node: Any, part: str, where: str, key: str, *, create: bool) -> Any:
    if isinstance(node, list):
        if not part.isdigit() or int(part) >= len(node):
            raise ConfigError(f"--set {key}", f"{where}: expected an index below {len(node)}, got {part!r}"[:200])
        return node[int(part)]
    if not isinstance(node, dict):
        raise ConfigError(f"--set {key}", f"{where.rpartition('.')[0] or where} is not a table")
    if part not in node and create:
        node[part] = {}
    return node[part]


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
    return parse_sweep_text(read_sweep_file(path), str(path), allow_large=allow_large, base=Path(path).parent)


def read_sweep_file(path: str | Path) -> bytes:
    """A sweep file's bytes, at most :data:`MAX_SWEEP_BYTES` + 1 (never a huge file, or a
    pipe, in memory)."""
    try:
        with Path(path).open("rb") as f:
            return f.read(MAX_SWEEP_BYTES + 1)
    except OSError as exc:
        raise ConfigError("", f"cannot read the file ({exc.strerror or exc})") from None


def sweep_data(raw: bytes) -> dict[str, Any]:
    """A sweep file's bytes as TOML data (ConfigError, field '', when they are not)."""
    if len(raw) > MAX_SWEEP_BYTES:
        raise ConfigError("", f"more than {MAX_SWEEP_BYTES:,} bytes; a sweep file is at most that "
                              "(a grid axis that long would not run anyway)")
    try:
        text = raw.decode("utf-8-sig")        # a leading byte-order mark (Windows editors) is fine
    except UnicodeDecodeError as exc:
        raise ConfigError("", f"not UTF-8 text (byte {exc.start})") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError("", f"invalid TOML: {exc}") from None
    except ValueError as exc:                 # an integer of more than 4300 digits
        raise ConfigError("", f"invalid TOML: {str(exc).split(';')[0]}") from None
    except RecursionError:
        raise ConfigError("", "invalid TOML: nested too deeply") from None


def parse_sweep_text(raw: bytes, source: str, *, allow_large: bool = False,
                     base: str | os.PathLike | None = None) -> Plan:
    return parse_sweep(sweep_data(raw), source, allow_large=allow_large, base=base)
