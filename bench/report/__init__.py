"""Stage ``report/`` of the harness. A run's outputs rebuilt from its store: report.md and
report.html, the figures, the claims of a paper preset and their baselines, the quantities
they measure, `bench compare`.

It may import the top modules of ``bench/``, ``tasks/`` and ``recording/``, and the stages
``sweep/``, ``results/``, ``run/``; never ``cli/`` (docs/architecture.md, 'Layout';
tests/test_layout.py holds it).

Outputs of a run, all rebuilt from ``results.sqlite`` (``bench report DIR``).

Writes ``trials.csv``, ``summary.csv``, ``calibration.csv``, ``steps.csv``
(per-step tables of the tasks that have them), ``comparisons.csv`` (paired
comparisons, :mod:`bench.report.glance`), ``report.md``, ``report.html``
(:mod:`bench.report.html`), ``figures/*.png`` and ``recording.rrd``
(docs/architecture.md, 'Outputs of a run' and 'Report'). The report is the
title, *Results at a glance*, the preset's notes, the sweep's plan (every
parameter that differs from its default) and calibration, then each task's own
sections (:meth:`bench.tasks.base.Task.report_sections`: the calibrated tasks
first, next to their calibration), the paired comparisons, single-trial
sections, runtime, failures, the recording and provenance; the page and the
harness's sections are Jinja2 templates (``bench/templates``,
:mod:`bench.report.render`). Every file is written to a temporary name and
renamed, so no reader ever sees a half-written output.
"""

from __future__ import annotations

import importlib
import time
from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench.report import claims
from radarbench.bench import figures, registry
from radarbench.bench.results import runfolder
from radarbench.bench.calibration import EQUAL_CHANCE_PD
from radarbench.bench.errors import ConfigError
from radarbench.bench.escapes import escape_controls
from radarbench.bench.run.progress import Progress
from radarbench.bench.report.building import (Sections, each_done, figure_pool, interactive_html, interactive_job,
                                              reused_output)
from radarbench.bench.markdown import code, fmt_db, text
from radarbench.bench.markdown import fmt as _fmt
from radarbench.bench.markdown import table as _table
from radarbench.bench.results.provenance import WALL_TIME_ROW, origin_text, provenance
from radarbench.bench.report.quantities import plan_calibration
from radarbench.bench.report.glance import comparisons_frame, draw_glance_figures, glance
from radarbench.bench.report.html import interactive_specs, markdown_to_html
from radarbench.bench.report.render import comparisons_markdown, glance_markdown, render, section_macro
from radarbench.bench.recording import TrialRecord, write_recording
from radarbench.bench.run.runner import calibrations
from radarbench.bench.results.store import Store
from radarbench.bench.results.figure_cache import FigureReuse, reused, reusing, write_if_changed
from radarbench.bench.results.tables import csv_text
from radarbench.bench.tasks import ReportContext, summary_columns

TRIAL_KEYS = ["scenario", "method", "config", "params", "snr_db", "trial", "seed", "realised_snr_db",
              "threshold"]
#: Summary columns the recording's table always shows, besides the tasks' headline columns.
RECORDING_KEYS = ("scenario", "method", "snr_db", "n_trials")


def _write_text(path: Path, text: str) -> None:
    write_if_changed(path, text.encode("utf-8"))


def _scenario_order(record: dict) -> dict[str, int]:
    """Scenario config label -> its position in the sweep (tables follow the sweep's order)."""
    return {sc["label"]: i for i, sc in enumerate(record["scenarios"])}


def trials_frame(store: Store, record: dict) -> tuple[pd.DataFrame, dict]:
    """One row per (scenario config, method config, SNR, trial), in a fixed
    order, and the series: ``{(scenario, config, snr_db): {name: (n, K)}}``
    with rows in trial order."""
    info = {m["label"]: m for m in record["methods"]}
    frames = []
    parts: dict[tuple, list] = {}
    for _unit, label, scenario, snr, cols in store.iter_metrics():
        two_d = {k: v for k, v in cols.items() if np.ndim(v) == 2}
        if two_d:
            parts.setdefault((scenario, label, snr), []).append((cols["trial"], two_d))
        one_d = {k: v for k, v in cols.items() if np.ndim(v) == 1}
        frames.append(pd.DataFrame({"scenario": scenario, "method": info[label]["name"], "config": label,
                                    "params": info[label]["params"], "snr_db": snr, **one_d},
                                   index=pd.RangeIndex(len(cols["trial"]))))
    series = {}
    for key, chunks in parts.items():
        order = np.argsort(np.concatenate([t for t, _ in chunks]), kind="stable")
        series[key] = {name: np.concatenate([c[name] for _, c in chunks])[order] for name in chunks[0][1]}
    if not frames:
        return pd.DataFrame(columns=TRIAL_KEYS), series
    df = pd.concat(frames, ignore_index=True)
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    df = df.assign(_s=df.scenario.map(_scenario_order(record)), _o=df.config.map(order))
    df = df.sort_values(["_s", "_o", "snr_db", "trial"])
    rest = [c for c in df.columns if c not in TRIAL_KEYS and c not in ("_o", "_s")]
    return df[TRIAL_KEYS + rest].reset_index(drop=True), series


def require_plugins(record: dict, db: Path) -> None:
    """Rebuilding the report needs every task, scenario and method the stored plan ran:
    one line naming the store and what is not installed here (with the reason ``bench
    list`` gives, when the plugin is there but failed to load)."""
    missing = []
    for kind, names in (("task", [m["task"] for m in record["methods"]]),
                        ("scenario", [s["name"] for s in record["scenarios"]]),
                        ("method", [m["name"] for m in record["methods"]])):
        for name in dict.fromkeys(names):
            problem = registry.problem(kind, name)
            if problem and registry.claimed(kind, name):      # claimed twice, or not by that qualifier
                raise ConfigError(str(db), problem)
            if problem:
                reason = registry.unavailable_reason(name)
                missing.append(f"{kind} {name!r}" + (f" ({reason})" if reason else ""))
    if missing:
        raise ConfigError(str(db), f"the run was made with plugins not installed here: {', '.join(missing)}; "
                                   "install them to rebuild its report"[:600])


def _of_the_plan(blobs: list[bytes], task_of: dict) -> list[TrialRecord]:
    """The stored trial records with the traces of the plan's method configs only: a record
    merges the traces of every config that ran on its unit, and a config an edited sweep
    removed leaves the report but not the store (docs/architecture.md, 'Results cache')."""
    records = [TrialRecord.from_bytes(b) for b in blobs]
    for r in records:
        r.methods = {label: trace for label, trace in r.methods.items() if label in task_of}
    return [r for r in records if r.methods]


def _task_of(record: dict) -> dict:
    """Method config label -> its task (bench.tasks), from the stored plan."""
    return {m["label"]: registry.get_task(m["task"]) for m in record["methods"]}


def summary_frame(trials: pd.DataFrame, series: dict, runs: pd.DataFrame, record: dict,
                  cals=()) -> pd.DataFrame:
    """One row per (scenario config, method config, SNR): each task's summary
    of its trials, completed by its calibrations (:meth:`Task.apply_calibration`)."""
    tasks = {m["label"]: m["task"] for m in record["methods"]}
    present = set(tasks.values())               # only the run's tasks: no columns that are empty by design
    columns = summary_columns(t for name, t in registry.tasks().items() if name in present)
    parts = [_task_summary(registry.get_task(task), g, series, cals) for task, g in trials.groupby(trials.config.map(tasks))] \
        if len(trials) else []
    summary = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=columns)
    summary = summary.reindex(columns=list(dict.fromkeys([*columns, *summary.columns])))
    # The tasks' parts and the calibrations' in-place writes leave pandas' column blocks
    # split: one block again (a frame of 100+ blocks makes every later operation slow, and
    # pandas says so on the user's terminal). For the same reason, columns are taken with
    # .loc and converted one by one: drop() and astype({...}) split every column (pandas 3).
    summary = summary.copy()
    ev = runs[(runs.phase == "evaluation") & runs.error.isna()]
    speed = ev.groupby(["scenario", "method", "snr_db"]).agg(s=("seconds", "sum"), n=("n", "sum"))
    speed = (speed.s / speed.n).rename("seconds_per_trial").reset_index().rename(columns={"method": "config"})
    keys = {"scenario": str, "config": str, "snr_db": float}
    summary = _without_runtime(summary)
    summary = summary.assign(**{k: summary[k].astype(t) for k, t in keys.items()})
    summary = summary.merge(speed.assign(**{k: speed[k].astype(t) for k, t in keys.items()}), on=list(keys),
                            how="left")
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    summary = summary.assign(_s=summary.scenario.map(_scenario_order(record)), _o=summary.config.map(order))
    summary = summary.sort_values(["_s", "_o", "snr_db"])
    return summary[columns].reset_index(drop=True)


def _task_summary(task, trials: pd.DataFrame, series: dict, cals: list) -> pd.DataFrame:
    """A task's summary of its trials and their series (:meth:`Task.summarise`), completed by its
    configs' calibrations (:meth:`Task.apply_calibration`) in the task's columns; reused for
    equal trials, series and calibrations (:func:`reused`)."""
    configs = set(trials.config)
    mine = {key: value for key, value in series.items() if key[1] in configs}
    cals = [c for c in cals if c.method in configs]

    def summarised(trials: pd.DataFrame, series: dict, cals: list) -> pd.DataFrame:
        summary = task.summarise(trials, series)
        summary = summary.reindex(columns=list(dict.fromkeys([*summary_columns([task]), *summary.columns])))
        for c in cals:
            if ((summary.scenario == c.scenario) & (summary.config == c.method)).any():
                task.apply_calibration(summary, trials, c)
        return summary
    return reused(summarised, trials, mine, cals, key=(trials, mine, [c.as_row() for c in cals]), code=_task_code(task))


def _task_code(*tasks) -> str | None:
    """The code of ``tasks`` beyond the harness's, for the values a report reuses (:func:`reused`):
    a harness task by its name, a plugin's by its name and code identity
    (:func:`bench.run.identity.code_identity`); None when one has no file to identify."""
    from radarbench.bench.run.identity import code_identity, is_harness, module_file
    out = []
    for task in tasks:
        module = type(task).__module__
        file = module_file(module)
        if file is None:
            return None
        out.append(task.name if is_harness(file) else f"{task.name} {code_identity(module).hash}")
    return ";".join(out)


def store_tables(store: Store, record: dict, runs: pd.DataFrame) -> tuple[pd.DataFrame, dict, list, pd.DataFrame]:
    """(trials with their calibrated columns, series, calibrations, summary) of a store:
    what summary.csv and trials.csv hold, rebuilt from the store alone, so that a reader
    (the report, ``bench compare``) never depends on a CSV written earlier, or not at all."""
    sweep, task_of = record["sweep"], _task_of(record)
    trials, series = trials_frame(store, record)
    cals = calibrations(store, [s["label"] for s in record["scenarios"]], [m["label"] for m in record["methods"]],
                        sweep["calibration"]["pfa"], sweep["calibration"]["mode"],
                        sweep["calibration"].get("chance_pd", EQUAL_CHANCE_PD),
                        frozenset(label for label, task in task_of.items() if task.pfa_per_cell))
    trials = _calibrated_trials(trials, cals, task_of)
    return trials, series, cals, summary_frame(trials, series, runs, record, cals)


def _calibrated_trials(trials: pd.DataFrame, cals, task_of: dict) -> pd.DataFrame:
    """``trials`` with the per-trial columns the calibrations give (:meth:`Task.calibrated_trial_columns`:
    e.g. detection at the threshold of equal chance Pd), NaN for the other rows."""
    parts: dict[str, list[pd.Series]] = {}
    for c in cals:
        for name, values in task_of[c.method].calibrated_trial_columns(trials, c).items():
            parts.setdefault(name, []).append(values)
    return trials.assign(**{name: pd.concat(values).reindex(trials.index) for name, values in parts.items()})


def steps_frame(trials: pd.DataFrame, series: dict, record: dict, t_of: dict) -> pd.DataFrame:
    """Per (scenario, config, SNR, step): the task's per-step table
    (:meth:`Task.steps`), with the step's time."""
    task_of = _task_of(record)
    rows = []
    for (scenario, config, snr), cols in series.items():
        g = trials[(trials.scenario == scenario) & (trials.config == config) & (trials.snr_db == snr)]
        df = task_of[config].steps(g, cols) if config in task_of else None
        if df is None:
            continue
        t = t_of.get(scenario)
        df.insert(0, "t", t[:len(df)] if t is not None and len(t) >= len(df) else np.nan)
        df.insert(0, "step", np.arange(len(df)))
        for i, (k, v) in enumerate([("scenario", scenario), ("method", g.method.iloc[0] if len(g) else ""),
                                    ("config", config), ("snr_db", snr)]):
            df.insert(i, k, v)
        rows.append(df)
    if not rows:
        return pd.DataFrame()
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    out = pd.concat(rows, ignore_index=True)
    out = out.assign(_s=out.scenario.map(_scenario_order(record)), _o=out.config.map(order))
    return out.sort_values(["_s", "_o", "snr_db", "step"]).drop(columns=["_s", "_o"]).reset_index(drop=True)


# ------------------------------------------------------------------ report sections

def _snr_text(snr: list) -> str:
    if len(snr) > 2:
        return f"{fmt_db(snr[0])} to {fmt_db(snr[-1])} dB ({len(snr)} levels)"
    return ", ".join(f"{fmt_db(x)} dB" for x in snr)


def _tasks_present(task_of: dict) -> list:
    """The tasks of the sweep's method configs, in registry order."""
    present = set(task_of.values())
    return [t for t in registry.tasks().values() if t in present]


def _same(a, b) -> bool:
    norm = (lambda v: list(v) if isinstance(v, (list, tuple)) else v)
    return norm(a) == norm(b)


def non_default(cls, params: dict) -> dict:
    """The entries of the resolved ``params`` that differ from the plugin's
    declared defaults (``cls.Params``); every entry when they cannot be built."""
    from radarbench.bench.params import build_params, params_as_dict
    try:
        defaults = params_as_dict(build_params(cls.Params, {}))
    except Exception:      # a Params without defaults for everything: show all
        return dict(params)
    return {k: v for k, v in params.items() if k not in defaults or not _same(v, defaults[k])}


def _params_text(params: dict) -> str:
    return text(", ".join(f"{k}={v}" for k, v in params.items())) or "defaults"


def _section(name: str, *args) -> str:
    """The harness section ``name``: a macro of ``sections.md.j2``."""
    return section_macro(name)(*args).strip("\n")


def _resolved_scenario_params(record: dict) -> dict[str, dict]:
    """Scenario config label -> its resolved parameters, from the stored sweep resolved
    again (a single-scenario sweep keeps its grid axes merged in ``scenario_params``), its
    data files named as a report shows them (:func:`_shown_params`)."""
    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.params import params_as_dict
    plan = parse_sweep(record["sweep"], allow_large=True)
    return {sc.label: _shown_params(type(sc.params), params_as_dict(sc.params), record) for sc in plan.scenarios}


def _shown_params(cls: type, params: dict, record: dict) -> dict:
    """``params`` (of the params dataclass ``cls``) with its data files named relative to the
    sweep's folder, never absolute (a shared report must not disclose its author's folders):
    by their name alone for a store that did not record the folder."""
    from radarbench.bench.params import shown_paths
    return shown_paths(cls, params, record.get("sweep_folder"))


def _method_params_text(cls, params: dict, record: dict) -> str:
    """A method config's parameters that differ from its defaults, as the plan section shows them."""
    return _params_text(non_default(cls, _shown_params(cls.Params, params, record)))


def _section_plan(record: dict, store: Store, tasks: list) -> str:
    sweep = record["sweep"]
    cal = sweep["calibration"]
    units = ", ".join(f"{t.pfa_unit} for {t.short_noun}" for t in tasks if t.calibrated)
    calibrated = {t.name for t in tasks if t.calibrated}
    null_for = [code(sc["label"]) for sc in record["scenarios"] if calibrated & set(sc.get("tasks", []))]
    rows = [["seed", sweep["seed"]], ["trials per unit (chunk)", sweep["chunk"]]]
    if null_for:
        rows.append(["calibration", f"{cal['mode']}, requested Pfa {cal['pfa']:g}{f' ({units})' if units else ''}, "
                                    f"{cal['h0_trials']} null trials per scenario config of a calibrated task "
                                    f"({', '.join(null_for)})"])
    resolved = _resolved_scenario_params(record)
    scenarios = [[code(sc["label"]), text(sc["name"]), text(", ".join(sc.get("tasks", []))),
                  _params_text(non_default(registry.get_scenario(sc["name"]), resolved.get(sc["label"], {}))),
                  _snr_text(sc.get("snr_db", sweep.get("snr_db", []))), sc.get("trials", sweep.get("trials"))]
                 for sc in record["scenarios"]]
    methods = [[code(m["label"]), text(m["name"]), text(m["task"]),
                _method_params_text(registry.get_method(m["name"]), sweep["methods"][i]["params"], record)]
               for i, m in enumerate(record["methods"])]
    return _section(
        "plan",
        _table(["scenario config", "scenario", "tasks", "parameters (not default)", "SNR", "trials per level"],
               scenarios),
        _table(["", ""], rows), text(store.meta("snr_definition") or "see the scenario's documentation"),
        _table(["config", "method", "task", "parameters (not default)"], methods),
        _unavailable_text(record.get("unavailable", [])) + _skipped_pairs_text(record.get("skipped_pairs", [])))


def _skipped_pairs_text(skipped: list[dict]) -> list[str]:
    """The (scenario config, method config) pairs the methods refused (skipped: no units, no rows)."""
    if not skipped:
        return []
    return ["Pairs skipped because the method cannot run on that scenario config (its own reason); "
            "each of these method configs runs on the sweep's other scenario configs:",
            _table(["scenario config", "method config", "reason"],
                   [[code(p["scenario"]), code(p["method"]), text(p["reason"])] for p in skipped])]


def _unavailable_text(skipped: list) -> list[str]:
    """The optional method configs the sweep names that could not run here, and why."""
    if not skipped:
        return []
    lines = [f"- {code(s['label'])} ({text(s['name'])}): {text(s['reason'])}" for s in skipped]
    return ["**Not run** (marked `optional` in the sweep, unavailable in this environment; their rows are "
            "absent from every table):\n\n" + "\n".join(lines)]


def _section_calibration(cals, summary: pd.DataFrame, task_of: dict) -> str:
    if not cals:
        return ""
    measured = summary.groupby(["scenario", "config"]).pfa.mean()
    several = len({c.scenario for c in cals}) > 1
    rows = []
    for c in cals:
        task = task_of[c.method]
        in_eval = measured.get((c.scenario, c.method), np.nan) if task.evaluation_pfa else np.nan
        rows.append(([code(c.scenario)] if several else []) + [code(c.method), c.mode, f"{c.pfa:g} {task.pfa_unit}",
                     _fmt(c.nominal, 4),
                     f"{_fmt(c.nominal_pfa)} [{_fmt(c.nominal_pfa_low)}, {_fmt(c.nominal_pfa_high)}]",
                     _fmt(c.used, 4), f"{_fmt(c.used_pfa)} [{_fmt(c.used_pfa_low)}, {_fmt(c.used_pfa_high)}]",
                     _fmt(in_eval), f"{_fmt(c.chance_pd)} [{_fmt(c.chance_pd_low)}, {_fmt(c.chance_pd_high)}]",
                     f"{c.null_values:,}"])
    header = (["scenario config"] if several else []) + [
              "config", "mode", "requested Pfa", "nominal threshold", "measured Pfa of nominal [95% CI]",
              "threshold used", "measured Pfa of the threshold used [95% CI]", "Pfa in evaluation",
              "chance Pd [95% CI]", "null values"]
    empty = {"–", "– [–, –]"}
    keep = [j for j in range(len(header)) if any(r[j] not in empty for r in rows)]
    present = _tasks_present({c.method: task_of[c.method] for c in cals})
    return _section("calibration", present, _table([header[j] for j in keep], [[r[j] for j in keep] for r in rows]))


def _section_runtime(runs: pd.DataFrame, units: pd.DataFrame, fig_dir: Path, record: dict) -> str:
    ev = runs[runs.error.isna()]
    if ev.empty:
        return _section("runtime", "", "")
    per = ev.groupby("method").agg(seconds=("seconds", "sum"), n=("n", "sum")).reset_index()
    per["seconds_per_trial"] = per.seconds / per.n
    order = {m["label"]: i for i, m in enumerate(record["methods"])}
    per = per.rename(columns={"method": "config"}).assign(_o=lambda d: d.config.map(order)).sort_values("_o")
    figures.runtime(per, fig_dir / "runtime.png")
    gen = units.generate_seconds.sum() / units.n.sum()
    rows = [[code(r.config), f"{r.seconds_per_trial * 1e3:.3g}", f"{r.n:,}", f"{r.seconds:.3g}"]
            for r in per.itertuples()]
    return _section("runtime", _table(["config", "CPU ms per trial", "trials run", "total CPU seconds"], rows),
                    f"{gen * 1e3:.3g}")


def _section_failures(runs: pd.DataFrame) -> str:
    bad = runs[runs.error.notna()]
    if bad.empty:
        return _section("failures", "", 0)
    rows = [[code(r.method), r.phase, "null" if pd.isna(r.snr_db) else fmt_db(r.snr_db), code(r.unit),
             text(str(r.error)[:300])] for r in bad.head(50).itertuples()]
    return _section("failures", _table(["config", "phase", "SNR (dB)", "unit", "error"], rows), max(0, len(bad) - 50))


def _section_provenance(record: dict, store: Store, prov: dict) -> str:
    rows = [["command", code(record.get('command', ''))], ["sweep file", code(record.get('source', ''))],
            ["plan fingerprint", code(store.meta('fingerprint'))]]
    wall = store.meta("last_wall_seconds")
    if wall:
        rows.append([WALL_TIME_ROW, f"{float(wall):.1f} s"])
    rows += [[text(k), text(v)] for k, v in prov.items()]
    return _section("provenance", "\n\n".join([_table(["", ""], rows), *_identities_text(record, store)]))


def _identities_text(record: dict, store: Store) -> list[str]:
    """The identity of each config (docs/architecture.md, 'Identities'): what its stored
    results were computed by, and the identities the last run replaced (kept in previous/)."""
    import json
    stamps = json.loads(store.meta("identities") or "null")
    if stamps is None:
        return ["Code and data identities: not recorded (stored by an earlier bench)."]
    replaced = json.loads(store.meta("replaced") or '{"scenarios": {}, "methods": {}}')
    rows, versions = [], {}
    for kind, configs in (("scenarios", record["scenarios"]), ("methods", record["methods"])):
        for config in configs:
            label = config["label"]
            identity = stamps[kind].get(label, "")
            d = store.described(identity) or {}
            versions = d.get("versions", versions)
            data = ", ".join(f"{text(Path(p).name)} {code(h)}" for p, h in d.get("data", {}).items()) or "–"
            source = code(d.get("code", "?")) + (f" ({text(d['distribution'])})" if d.get("distribution") else "")
            plugin = text(origin_text(config)) if "module" in config else "not recorded"
            old = ", ".join(code(x) for x in replaced.get(kind, {}).get(label, [])) or "–"
            rows.append([code(label), kind[:-1], plugin, code(identity), source, data, old])
    lines = ", ".join(f"{text(k)} {text(v)}" for k, v in versions.items())
    return [f"Code and data identities ({lines}): a stored result is re-computed when its config's identity "
            "changes; the results the last run replaced are in `previous/` "
            "(`bench compare DIR/previous DIR`).",
            _table(["config", "kind", "module (distribution)", "identity", "code", "data files",
                    "replaced (previous/)"], rows)]


def _section_recording(n: int, out_dir: Path, tasks: list) -> str:
    """What ``recording.rrd`` holds: the harness's part, then each task's
    (``Task.recording_text``)."""
    return _section("recording", n, code(f"bench view {out_dir}"), code(f"rerun {out_dir / 'recording.rrd'}"),
                    [t.recording_text for t in tasks if t.recording_text])


def _preset_name(source: str) -> str:
    """The preset a run came from (its plan's source ``preset NAME``), else ""."""
    return source.split(" ", 1)[1] if source.startswith("preset ") else ""


def preset_notes(source: str) -> str:
    """The packaged notes of a preset (``bench/presets/NAME.md``), if any."""
    import importlib.resources
    if not _preset_name(source):
        return ""
    path = importlib.resources.files("radarbench.bench") / "presets" / f"{_preset_name(source)}.md"
    return path.read_text(encoding="utf-8").strip() if path.is_file() else ""


def _paper_vs_ours(source: str, tables: dict[str, pd.DataFrame], calibration: dict) -> tuple:
    """A preset's *Paper vs ours*: (its claims, ``NAME.claims.toml``, evaluated on the
    tables as written to CSV; the section: the table, then the rendered notes), or
    (None, the notes as they are) for a preset without a claims file; ``calibration``: the
    plan's ``[calibration]`` (:func:`bench.report.quantities.plan_calibration`). Called before
    anything is written: a claim the tables cannot answer stops the report with one
    line, nothing written."""
    file = claims.preset_claims(_preset_name(source)) if _preset_name(source) else None
    if file is None:
        return None, preset_notes(source)
    evaluation = claims.evaluate(file, claims.Tables(**{k: claims.csv_frame(v) for k, v in tables.items()},
                                                     **plan_calibration(calibration)))
    return evaluation, claims.claims_markdown(evaluation, preset_notes(source))


def build_outputs(out_dir: Path, *, recording: bool = True, progress: Progress | None = None,
                  workers: int | None = None, digest: str | None = None) -> Path:
    """(Re)build every output of a run folder from its store; returns report.md's path.

    Every file is written whole (a temporary file renamed into place) and listed in the
    folder's manifest (:mod:`bench.results.runfolder`), and only when its bytes changed; a figure
    drawn before from the same inputs and code is not drawn again (:mod:`bench.results.figure_cache`).
    The caller holds the folder's lock. ``progress`` shows the phases: ``report`` (CSVs,
    figures, report.md, counted in sections, with the figures drawn and reused) and
    ``recording`` (recording.rrd). ``workers``: the most processes that draw the figures
    (None: one per CPU, :func:`bench.report.building.figure_pool`). ``digest``: what the outputs are built from
    (:func:`bench.results.runfolder.outputs_digest`), recorded once they are all written, so an
    unchanged folder is not rebuilt. The build's CPU seconds (this process's and its figure
    processes') are recorded as the store's :data:`REPORT_CPU` (``benchmarks/loop.py`` reads them)."""
    cpu_started = _cpu_seconds()
    progress = progress or Progress(quiet=True)
    out_dir = Path(out_dir)
    db = out_dir / "results.sqlite"
    if not db.exists():
        raise ConfigError("", f"{out_dir} has no results.sqlite (not a bench run folder)")
    store = Store(db)
    try:
        reuse = FigureReuse.of_store(store)
        with runfolder.writing(out_dir), reusing(reuse):
            report = _build(store, out_dir, recording, progress, workers)
            reuse.drop_unmade(out_dir)
        reuse.save(store)
        if digest:
            store.set_meta(runfolder.OUTPUTS_DIGEST, digest)
        store.set_meta(REPORT_CPU, repr(_cpu_seconds() - cpu_started))
        return report
    finally:
        store.close()


#: the store's record of the CPU seconds its last report build took (:func:`build_outputs`)
REPORT_CPU = "report_cpu_seconds"


def _cpu_seconds() -> float:
    """CPU seconds of this process and of its children that have ended (a build's figure processes)."""
    try:
        import resource
    except ImportError:                         # Windows has none: this process's CPU alone
        return time.process_time()
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + children.ru_utime + children.ru_stime


def _task_contexts(present: list, task_of: dict, summary, trials, steps, series, cals, records, store,
                   out_dir: Path, sweep: dict) -> list:
    """(task, its report context) per task present, calibrated tasks first
    (their sections follow the calibration)."""
    out = []
    for task in sorted(present, key=lambda t: not t.calibrated):
        configs = frozenset(label for label, t in task_of.items() if t is task)
        out.append((task, ReportContext(
            summary=summary[summary.config.isin(configs)], trials=trials[trials.config.isin(configs)],
            steps=steps[steps.config.isin(configs)] if not steps.empty else steps,
            series={k: v for k, v in series.items() if k[1] in configs},
            calibrations=[c for c in cals if c.method in configs], records=records, store=store,
            fig_dir=out_dir / "figures", title=sweep["name"], pfa=sweep["calibration"]["pfa"],
            chance_pd=sweep["calibration"].get("chance_pd", EQUAL_CHANCE_PD),
            timeline_snr_db=sweep["record"].get("timeline_snr_db"), configs=configs, task=task)))
    return out


def _without_runtime(summary: pd.DataFrame) -> pd.DataFrame:
    """The summary without the runtime (the runtime section's): the figures of the tasks and of
    the glance are drawn from results alone, so equal results reuse them however long their
    trials took (bench.results.figure_cache)."""
    return summary.loc[:, summary.columns != "seconds_per_trial"]


def _recording_summary(summary: pd.DataFrame, tasks) -> pd.DataFrame:
    """The summary as the recording shows it: configs as methods, the headline columns and
    those the tasks chart."""
    wanted = set(RECORDING_KEYS).union(*(t.headline_columns for t in tasks),
                                       *((column for column, _ in t.recording_charts) for t in tasks))
    summary = summary.assign(method=summary.config)
    return summary[[c for c in summary.columns if c in wanted]]


def _write_tables(out_dir: Path, **tables) -> None:
    """``name.csv`` per table given (None, or an empty ``steps``: not written)."""
    for name, frame in tables.items():
        if frame is not None and not (name == "steps" and frame.empty):
            write_if_changed(out_dir / f"{name}.csv", csv_text(frame).encode("utf-8"))


def _build(store: Store, out_dir: Path, recording: bool, progress: Progress, workers: int | None) -> Path:
    runfolder.folder_for(out_dir / "figures")     # refuses a linked figures/ before anything is written
    with figure_pool(workers) as pool:
        return _build_with(store, out_dir, recording, progress, pool)


def _build_with(store: Store, out_dir: Path, recording: bool, progress: Progress, pool) -> Path:
    record = store.plan()
    require_plugins(record, store.path)
    sweep = record["sweep"]
    runs, units = store.runs(), store.units()
    task_of = _task_of(record)
    present = _tasks_present(task_of)
    sections = Sections(progress, len(present))
    trials, series, cals, summary = store_tables(store, record, runs)
    specs = interactive_specs(summary, task_of)      # drawn by the pool while the driver goes on
    interactive = interactive_job(pool, specs)
    t_of = {key[0]: cols["t_s"][0] for key, cols in series.items() if "t_s" in cols}
    steps = reused(steps_frame, trials, series, record, t_of, key=(trials, series, record["scenarios"], record["methods"], t_of),
                   code=_task_code(*present))
    records = _of_the_plan(store.records(), task_of)   # every read before the first write
    calibration = pd.DataFrame([c.as_row() for c in cals])
    fig_dir = out_dir / "figures"
    title = sweep["name"]
    sections.done("tables")
    with figures.rendering_in(pool):
        # the sections first: their figures draw in the pool while the comparisons are computed
        results = _without_runtime(summary)
        contexts = _task_contexts(present, task_of, results, trials, steps, series, cals, records, store, out_dir, sweep)
        done, total = len(units), int(store.meta("units_total") or len(units))
        chance = {(c.scenario, c.method): c.chance_pd for c in cals}
        task_parts = [s for task, ctx in contexts for s in each_done(task.report_sections(ctx), sections, task.name)]
        trial_parts = [s for task, ctx in contexts
                       for s in each_done(task.trial_sections(ctx), sections, f"{task.name}: single trials")]
        runtime_parts = [_section_runtime(runs, units, fig_dir, record), _section_failures(runs)]
        sections.done("runtime")
        comparisons = comparisons_frame(trials, task_of)
        evaluation, paper_vs_ours = _paper_vs_ours(   # the paper-vs-ours table leads a preset's sections
            record.get("source", ""), {"summary": summary, "comparisons": comparisons, "calibration": calibration},
            sweep["calibration"])
        _write_tables(out_dir, trials=trials, summary=summary, calibration=calibration, steps=steps,
                      comparisons=comparisons, claims=evaluation.frame() if evaluation is not None else None)
        parts = [paper_vs_ours, _section_plan(record, store, present), _section_calibration(cals, summary, task_of),
                 *task_parts, comparisons_markdown(comparisons, task_of), *trial_parts, *runtime_parts]
        entries = glance(trials, task_of, comparisons, chance)
        draw_glance_figures(entries, results, fig_dir)
        at_a_glance = glance_markdown(entries)
        sections.done("comparisons and at a glance")
    sections.done("figures written")
    if recording and records:
        progress.phase("recording")
        shown = _recording_summary(summary, present)
        ids = {"recording_id": f"{title}-{store.meta('fingerprint')}", "application_id": title,
               "recording_name": f"{title} · {str(store.meta('fingerprint'))[:12]}"}
        reused_output(out_dir / "recording.rrd", (records, shown, {k: t.name for k, t in task_of.items()}, ids),
                      lambda path: write_recording(path, records, shown, tasks=task_of, **ids))
        parts.append(_section_recording(sweep["record"]["trials"], out_dir, present))
    # dated by its results, not by the build: an unchanged store gives the same report
    parts.append(_section_provenance(record, store, provenance(units.finished.max() if len(units) else None)))
    page = {"title": text(title), "description": text(sweep.get("description") or "", inline=False),
            "command": code(record.get("command", "")),
            "incomplete": None if done >= total else {"done": done, "total": total},
            "glance": at_a_glance, "parts": [p for p in parts if p]}
    report = out_dir / "report.md"
    _write_text(report, escape_controls(render("report.md.j2", html=False, **page) + "\n"))
    html = markdown_to_html(escape_controls(render("report.md.j2", html=True, **page)), title, out_dir,
                            escape_controls(interactive_html(*interactive, specs)))
    _write_text(out_dir / "report.html", html)      # escaped before the policy hashed its scripts
    return report
