"""A run's results as tidy pandas frames: ``radarbench.load_run(path)`` and ``bench export``
(docs/outputs.md, 'Results in pandas'; docs/architecture.md, 'Outputs of a run').

Read from what every run folder and every committed ``reports/NAME`` folder holds: the
CSVs and ``plan.toml`` (no store, no plugin imported, so a run made with plugins that are
not installed here loads too). The wide CSVs stay as they are; this module reshapes them:

* ``summary``: one row per (scenario config, method config, SNR level, metric), the
  metric's ``value`` with its 95% interval (``ci_low``, ``ci_high``) and the cell's
  ``n_trials``. A metric is every summary.csv column that is neither a key of the cell
  (:data:`bench.metrics.CELL_KEYS`, ``n_trials``) nor an interval bound of another
  (:func:`interval_columns`); one that a config has no value for at any SNR (a column
  of another task) is left out.
* ``trials``: trials.csv, one row per trial (absent from committed reports: empty).
* ``calibration``: calibration.csv, one row per calibrated (scenario config, method
  config), its config label in ``config`` and the method's name in ``method`` as in the
  other two frames.

Every frame carries each config's resolved parameters from plan.toml, one typed column
per parameter, ``scenario.NAME`` and ``method.NAME`` (never a metric's name).
"""

from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.grid import params_text_of_label, split_top_level
from radarbench.bench.metrics import CELL_KEYS
from radarbench.bench.sweep.plan import format_value
from radarbench.bench.results.tables import csv_text, read_csv

#: the long summary's key columns, then what it says of each metric
SUMMARY_KEYS = ["scenario", "method", "config", "snr_db", "metric"]
VALUE_COLUMNS = ["value", "ci_low", "ci_high", "n_trials"]
#: the frames of a run, in the order ``bench export`` writes them
FRAMES = ("summary", "trials", "calibration")


@dataclass(frozen=True)
class Run:
    """One run's results (:func:`load_run`): ``summary`` (long), ``trials`` and
    ``calibration``, each with typed parameter columns; ``plan``: plan.toml as parsed."""

    path: Path
    summary: pd.DataFrame
    trials: pd.DataFrame
    calibration: pd.DataFrame
    plan: dict = field(repr=False)

    @property
    def name(self) -> str:
        """The sweep's name."""
        return self.plan.get("name", "")

    def frames(self) -> dict[str, pd.DataFrame]:
        """The frames that have rows, by name (:data:`FRAMES`)."""
        return {name: getattr(self, name) for name in FRAMES if len(getattr(self, name))}


def interval_columns(column: str, columns) -> tuple[str | None, str | None]:
    """The (low, high) bound columns of ``column`` among ``columns``, or None each: ``X_low``
    and ``X_high``, for a mean or a rate ``X_mean`` / ``X_rate`` also ``X_low`` and ``X_high``
    (summary.csv's ``delay_mean`` -> ``delay_low``, ``divergence_rate`` -> ``divergence_low``)."""
    stems = [column, *(column[:-len(s)] for s in ("_mean", "_rate") if column.endswith(s))]
    return tuple(next((f"{s}_{side}" for s in stems if f"{s}_{side}" in columns), None)
                 for side in ("low", "high"))


def metric_columns(columns) -> dict[str, tuple[str | None, str | None]]:
    """The metrics of a wide summary with their bound columns, in the table's order."""
    candidates = [c for c in columns if c not in (*CELL_KEYS, "n_trials")]
    bounds = {c: interval_columns(c, columns) for c in candidates}
    companions = {b for pair in bounds.values() for b in pair if b}
    return {c: pair for c, pair in bounds.items() if c not in companions}


def long_summary(wide: pd.DataFrame) -> pd.DataFrame:
    """summary.csv as one row per (scenario config, method config, SNR, metric)."""
    keys = SUMMARY_KEYS[:-1]
    nan = pd.Series(np.nan, index=wide.index)
    n = wide["n_trials"] if "n_trials" in wide else nan
    parts = [wide[keys].assign(metric=metric, value=pd.to_numeric(wide[metric]),
                               ci_low=wide[low] if low else nan, ci_high=wide[high] if high else nan,
                               n_trials=n, _row=np.arange(len(wide)), _metric=i)
             for i, (metric, (low, high)) in enumerate(metric_columns(wide.columns).items())]
    if not parts:
        return pd.DataFrame(columns=SUMMARY_KEYS + VALUE_COLUMNS)
    long = pd.concat(parts, ignore_index=True).sort_values(["_row", "_metric"], kind="stable")
    found = long[["value", "ci_low", "ci_high"]].notna().any(axis=1)
    applies = found.groupby([long.scenario, long.config, long.metric]).transform("any")
    long = long[applies].drop(columns=["_row", "_metric"]).reset_index(drop=True)
    return long.assign(n_trials=long.n_trials.astype("Int64"))


def _missing(v) -> bool:
    return v is None or isinstance(v, float) and np.isnan(v)


def _frozen(v):
    """A list (of lists) as a tuple (of tuples): hashable, so a list-valued grid axis groups."""
    return tuple(map(_frozen, v)) if isinstance(v, list) else v


def _typed(values: pd.Series) -> pd.Series:
    """One parameter column in one type: bool, int and str as pandas' nullable types, int
    and float together as float, lists as tuples; a parameter name whose types differ
    between configs as text (the label's spelling, :func:`bench.sweep.plan.format_value`)."""
    kinds = {type(v) for v in values if not _missing(v)}
    if kinds == {list}:
        return values.map(lambda v: None if _missing(v) else _frozen(v))
    dtype = {frozenset({bool}): "boolean", frozenset({int}): "Int64", frozenset({str}): "string",
             frozenset({float}): "float64", frozenset({int, float}): "float64"}.get(frozenset(kinds))
    if dtype is None:
        return values.map(lambda v: None if _missing(v) else format_value(v))
    return values.astype(dtype)


def _params_frame(key: str, prefix: str, params: dict[str, dict]) -> pd.DataFrame:
    """One row per config label (in column ``key``), a typed column ``prefix.NAME`` per parameter."""
    rows = pd.DataFrame([{key: label, **{f"{prefix}.{k}": v for k, v in p.items()}} for label, p in params.items()],
                        columns=None if params else [key], dtype=object)
    return rows.assign(**{c: _typed(rows[c]) for c in rows.columns if c != key}).astype({key: str})


def _grid_value(values, text: str):
    """The value of grid axis ``values`` that a scenario label writes as ``text``
    (:func:`bench.sweep.grid.expand`: a data file by its name alone)."""
    if not isinstance(values, list):
        return values
    return next((v for v in values if text in (format_value(v), os.path.basename(str(v)))), text)


def scenario_params(plan: dict, labels) -> dict[str, dict]:
    """Scenario config label -> its parameters. ``[[scenarios]]`` entries carry theirs; the
    single-scenario form keeps one ``scenario_params`` table, a grid axis there as the list
    of its values, and each config's label names its value (``name[axis=value,...]``)."""
    if "scenarios" in plan:
        return {s["label"]: s.get("params", {}) for s in plan["scenarios"]}
    name, params = plan.get("scenario", ""), plan.get("scenario_params", {})
    out = {}
    for label in labels:
        named = dict(p.split("=", 1) for p in split_top_level(params_text_of_label(name, label)) if "=" in p)
        out[label] = {k: _grid_value(v, named[k]) if k in named else v for k, v in params.items()}
    return out


def _with_params(frame: pd.DataFrame, scenarios: pd.DataFrame, methods: pd.DataFrame) -> pd.DataFrame:
    """``frame`` without summary.csv's ``params`` text, with the typed parameter columns."""
    if frame.empty:
        return frame
    frame = frame.drop(columns=["params"], errors="ignore").astype({"scenario": str, "config": str})
    # copy(): one block per dtype again (the typed columns come one by one; a frame of 100+
    # blocks makes every later insert slow, and pandas says so on the user's terminal)
    return frame.merge(scenarios, on="scenario", how="left").merge(methods, on="config", how="left").copy()


def _read(folder: Path, name: str) -> pd.DataFrame:
    path = folder / f"{name}.csv"
    return read_csv(path) if path.is_file() else pd.DataFrame()


def load_run(path: str | os.PathLike) -> Run:
    """The results of a run folder (``runs/NAME``) or a committed report (``reports/NAME``)
    as tidy frames (:class:`Run`); ConfigError (one line) when it holds no summary.csv and
    plan.toml."""
    folder = Path(path)
    missing = [f for f in ("summary.csv", "plan.toml") if not (folder / f).is_file()]
    if missing:
        why = ("no such folder" if not os.path.lexists(folder) else "is not a folder" if not folder.is_dir()
               else f"has no {' and no '.join(missing)}")
        raise ConfigError(str(folder), f"{why} (a run folder after its report, or a reports/NAME folder)")
    try:
        plan = tomllib.loads((folder / "plan.toml").read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(str(folder / "plan.toml"), f"not a plan written by bench: {exc}") from None
    wide, trials = read_csv(folder / "summary.csv"), _read(folder, "trials")
    calibration = _read(folder, "calibration")
    if not calibration.empty:
        names = {m["label"]: m["name"] for m in plan.get("methods", [])}
        calibration = calibration.rename(columns={"method": "config"})
        calibration.insert(1, "method", calibration.config.map(names))
    labels = dict.fromkeys(str(s) for f in (wide, trials, calibration) if "scenario" in f for s in f.scenario)
    scenarios = _params_frame("scenario", "scenario", scenario_params(plan, labels))
    methods = _params_frame("config", "method", {m["label"]: m.get("params", {}) for m in plan.get("methods", [])})
    return Run(folder, _with_params(long_summary(wide), scenarios, methods), _with_params(trials, scenarios, methods),
               _with_params(calibration, scenarios, methods), plan)


def check_format(fmt: str) -> None:
    """ConfigError (one line) unless ``fmt`` can be written here: parquet needs pyarrow (a
    dependency of rerun-sdk), looked up without importing it."""
    import importlib.util
    if fmt == "parquet" and importlib.util.find_spec("pyarrow") is None:
        raise ConfigError("--format", "parquet needs the pyarrow package (pip install pyarrow)")


def export(run: Run, out: Path, fmt: str) -> list[Path]:
    """Write ``run``'s frames into folder ``out`` as ``NAME.csv`` or ``NAME.parquet``, each
    whole (:func:`bench.results.runfolder.atomic_output`); the paths written."""
    from radarbench.bench.results import runfolder
    check_format(fmt)
    runfolder.folder_for(out)
    written = []
    for name, frame in run.frames().items():
        path = out / f"{name}.{fmt}"
        with runfolder.atomic_output(path) as (f, _):
            if fmt == "parquet":
                frame.to_parquet(f, index=False)
            else:
                f.write(csv_text(frame).encode("utf-8"))
        written.append(path)
    return written
