"""The quantities a paper's claims name, read from a run's own tables (docs/architecture.md,
'Report'): a config's summary value at an SNR, a calibration value, a paired difference, the
SNR at which a Pd column crosses a level, and differences and ratios of those.

Each gives (value, low, high): a 95% interval where the table has one, and the trials
behind it (``n``: per SNR level, or the calibration's null trials) from which a verdict
estimates how many trials would resolve a claim (:func:`bench.report.claims.trials_needed`). Crossings are
computed as the report's SNR-at-Pd tables compute them (:func:`bench.markdown.snr50`); a
difference of two quantities has the conservative interval [a.low − b.high, a.high − b.low]
(the Minkowski difference of the two 95% intervals). A quantity whose config or scenario
config did not run raises :class:`Missing`. The claims file that names them, and the
verdicts: :mod:`bench.report.claims`.
"""

from __future__ import annotations

import io
import math
import tomllib
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Mapping

import numpy as np
import pandas as pd

from radarbench.bench.errors import ConfigError
from radarbench.bench.markdown import crossing_floors, fmt_db, snr50
from radarbench.bench.results.tables import csv_text, read_csv

#: ``snr_db`` of a paired quantity over every level (comparisons.csv's blank ``snr_db``)
ALL_LEVELS = "all"
#: kinds whose a and b are quantities themselves
INLINE = ("difference", "ratio")


# ------------------------------------------------------------------ the run's tables

@dataclass(frozen=True)
class Tables:
    """The run's tables as written to CSV (and read back: :func:`read_tables`),
    the chance Pd every detector is calibrated to for equal-chance Pd
    (the sweep's ``[calibration] chance_pd``: the floor of that Pd column) and the
    null trials of each calibration (``[calibration] h0_trials``; NaN: unknown)."""

    summary: pd.DataFrame
    comparisons: pd.DataFrame
    calibration: pd.DataFrame
    equal_chance: float
    h0_trials: float = math.nan


def plan_calibration(calibration: Mapping) -> dict:
    """The :class:`Tables` fields read from a resolved plan's ``[calibration]`` table."""
    from radarbench.bench.calibration import EQUAL_CHANCE_PD
    return {"equal_chance": float(calibration.get("chance_pd", EQUAL_CHANCE_PD)),
            "h0_trials": float(calibration.get("h0_trials", math.nan))}


def csv_frame(df: pd.DataFrame) -> pd.DataFrame:
    """``df`` exactly as its CSV reads back, so claims evaluated at report time and
    from the committed CSVs are the same numbers."""
    return read_csv(io.StringIO(csv_text(df)))


def read_tables(folder: str | Path) -> Tables:
    """A report folder's committed tables: summary.csv, comparisons.csv,
    calibration.csv and plan.toml's ``[calibration]`` (:func:`plan_calibration`)."""
    folder = Path(folder)
    frames = [read_csv(folder / f"{name}.csv") if (folder / f"{name}.csv").exists() else pd.DataFrame()
              for name in ("summary", "comparisons", "calibration")]
    plan = tomllib.loads((folder / "plan.toml").read_text(encoding="utf-8")) if (folder / "plan.toml").exists() else {}
    return Tables(*frames, **plan_calibration(plan.get("calibration", {})))


# ------------------------------------------------------------------ quantities

class Missing(Exception):
    """A config or scenario config the claim names did not run."""


@dataclass(frozen=True)
class Value:
    value: float
    low: float = math.nan
    high: float = math.nan
    p: float = math.nan
    n: float = math.nan        # the trials behind the interval: per SNR level, or null trials (``null``)
    null: bool = False         # n counts the calibration's null trials

    def scaled(self, k: float) -> Value:
        low, high = self.low * k, self.high * k
        return replace(self, value=self.value * k, low=high if k < 0 else low, high=low if k < 0 else high)

    def combined(self, other: Value, value: float, low: float, high: float) -> Value:
        """A value computed from this one and ``other`` (a difference, a ratio). Its n is
        the larger of the two: n trials at every level give each part at least its own
        count. NaN where one is unknown or they count different trials (per level, null)."""
        n = max(self.n, other.n) if self.null == other.null and not math.isnan(self.n + other.n) else math.nan
        return Value(value, low, high, n=n, null=self.null)


def _scenario(df: pd.DataFrame, q: dict) -> str:
    """The scenario config a quantity names, or the run's only one."""
    if "scenario" in q:
        if q["scenario"] not in set(df.scenario):
            raise Missing(f"scenario config `{q['scenario']}`")
        return q["scenario"]
    scenarios = list(dict.fromkeys(df.scenario))
    if len(scenarios) != 1:
        raise ConfigError("scenario", f"the run has {len(scenarios)} scenario configs ({', '.join(scenarios)}): "
                                      "name one")
    return scenarios[0]


def _rows(df: pd.DataFrame, q: dict, config_column: str, config: str) -> pd.DataFrame:
    """The rows of ``config`` (in ``config_column``) on the quantity's scenario config."""
    if df.empty or config not in set(df[config_column]):
        raise Missing(f"`{config}`")
    scenario = _scenario(df, q)
    rows = df[(df.scenario == scenario) & (df[config_column] == config)]
    if rows.empty:
        raise Missing(f"`{config}` on `{scenario}`")
    return rows


def _column(columns, column: str) -> str:
    if column not in columns:
        raise ConfigError("column", f"no column {column!r} in the table")
    return column


def _interval_of(row: pd.Series, column: str, n: float) -> Value:
    """``column`` of one row, with ``column_low`` / ``column_high`` where the table has
    them (for a mean ``X_mean``, ``X_low`` / ``X_high``: summary.csv's ``delay_mean``),
    from ``n`` trials."""
    stem = column[:-len("_mean")] if column.endswith("_mean") else column

    def bound(side: str) -> float:
        name = next((c for c in (f"{column}_{side}", f"{stem}_{side}") if c in row.index), None)
        return float(row[name]) if name else math.nan
    return Value(float(row[_column(row.index, column)]), bound("low"), bound("high"), n=n)


def _summary(q: dict, t: Tables) -> Value:
    rows = _rows(t.summary, q, "config", q["config"])
    at = rows[np.isclose(rows.snr_db.astype(float), q["snr_db"])]
    if at.empty:        # a run narrowed by --snr, say; a level missing from the preset is a test's to find
        raise Missing(f"`{q['config']}` at {fmt_db(q['snr_db'])} dB (levels run: "
                      f"{', '.join(fmt_db(s) for s in rows.snr_db)} dB)")
    return _interval_of(at.iloc[0], q["column"], _trials(at))


def _calibration(q: dict, t: Tables) -> Value:
    return replace(_interval_of(_rows(t.calibration, q, "method", q["config"]).iloc[0], q["column"], t.h0_trials),
                   null=True)


def _trials(rows: pd.DataFrame, column: str = "n_trials") -> float:
    """The most trials any of ``rows`` ran (NaN where the table does not say)."""
    return float(rows[column].max()) if column in rows and len(rows) else math.nan


def _paired(q: dict, t: Tables) -> Value:
    """comparisons.csv's row for (a, b), oriented so that value = mean(b) − mean(a)."""
    df = t.comparisons
    for config in (q["a"], q["b"]):
        if df.empty or config not in set(df.config_a) | set(df.config_b):
            raise Missing(f"`{config}`")
    df = df[df.scenario == _scenario(df, q)]
    metric = q.get("metric") or _task_metric(df, q)
    snr = df.snr_db.isna() if q["snr_db"] == ALL_LEVELS else np.isclose(df.snr_db, q["snr_db"])
    rows = df[snr & (df.metric == metric)]
    if rows.empty and q["snr_db"] != ALL_LEVELS:
        raise Missing(f"the level {fmt_db(q['snr_db'])} dB")
    same = rows[(rows.config_a == q["a"]) & (rows.config_b == q["b"])]
    swapped = rows[(rows.config_a == q["b"]) & (rows.config_b == q["a"])]
    if same.empty and swapped.empty:
        raise ConfigError("snr_db", f"no comparison of `{q['a']}` and `{q['b']}` on {metric} at {q['snr_db']}")
    r = (same if len(same) else swapped).iloc[0]
    # over all levels, n_pairs counts every level's pairs: the trials per level are the levels' own rows'
    pair = df[(df.metric == metric) & (df.config_a == r.config_a) & (df.config_b == r.config_b) & df.snr_db.notna()]
    n = _trials(pair, "n_pairs") if q["snr_db"] == ALL_LEVELS and len(pair) else float(r.get("n_pairs", math.nan))
    v = Value(float(r.difference), float(r.difference_low), float(r.difference_high), float(r.mcnemar_p), n=n)
    return v if len(same) else v.scaled(-1.0)


def _task_metric(df: pd.DataFrame, q: dict) -> str:
    """The ranking metric of the task the pair belongs to (``Task.ranking_metric``)."""
    from radarbench.bench import registry
    tasks = set(df[(df.config_a.isin([q["a"], q["b"]])) | (df.config_b.isin([q["a"], q["b"]]))].task)
    if len(tasks) != 1:
        raise ConfigError("metric", f"the pair belongs to {len(tasks)} tasks: name the metric")
    return registry.get_task(tasks.pop()).ranking_metric


def _crossing_value(crossing, n: float) -> Value:
    """A :class:`bench.metrics.Crossing` as (value, low, high): NaN value unless fitted;
    outside the swept range an open bound (±inf) on the far side."""
    value = crossing.mid if crossing.kind == "fit" else math.nan
    low = -math.inf if crossing.kind == "below" else crossing.low
    high = math.inf if crossing.kind == "above" else crossing.high
    return Value(value, low, high, n=n)


def _crossing(q: dict, t: Tables) -> Value:
    config, column = q["config"], q.get("column", "pd")
    rows = _rows(t.summary, q, "config", config)
    _column(rows.columns, column)
    cal = t.calibration
    chance = {config: float(r.chance_pd) for r in _rows(cal, q, "method", config).itertuples()} \
        if not cal.empty and "chance_pd" in cal and config in set(cal.method) else {}
    found = snr50(rows, column, crossing_floors(column, chance, t.equal_chance), q.get("level", 0.5))
    return _crossing_value(found.crossing.iloc[0], _trials(rows))


def _minus(a: Value, b: Value) -> Value:
    """a − b with the conservative interval [a.low − b.high, a.high − b.low]."""
    return a.combined(b, a.value - b.value, a.low - b.high, a.high - b.low)


def _crossing_difference(q: dict, t: Tables) -> Value:
    side = (lambda s: {**q, "config": q[s], "scenario": q.get(f"scenario_{s}", q.get("scenario"))})
    a, b = ({k: v for k, v in side(s).items() if v is not None} for s in ("a", "b"))
    return _minus(_crossing(a, t), _crossing(b, t))


def _ratio(a: Value, b: Value) -> Value:
    """a / b for a positive denominator (b.low > 0), with the conservative interval: the
    extremes of a's ends over b's ends (a may be of either sign); NaN ends where b's
    interval reaches 0, where the ratio is unbounded."""
    if not b.low > 0:
        return a.combined(b, a.value / b.value, np.nan, np.nan)
    ends = [a.low / b.low, a.low / b.high, a.high / b.low, a.high / b.high]
    return a.combined(b, a.value / b.value, min(ends), max(ends))


def quantity(q: dict, t: Tables) -> Value:
    """The value of quantity ``q`` (validated by :func:`parse`) on the tables ``t``."""
    kind = q["kind"]
    if kind in INLINE:
        a, b = quantity(q["a"], t), quantity(q["b"], t)
        with np.errstate(all="ignore"):
            v = _minus(a, b) if kind == "difference" else _ratio(a, b)
    else:
        v = {"summary": _summary, "calibration": _calibration, "paired": _paired, "crossing": _crossing,
             "crossing_difference": _crossing_difference}[kind](q, t)
    return v.scaled(q["scale"]) if "scale" in q else v


def describe(q: dict | None) -> str:
    """A quantity as one line: ``crossing(config=..., column=pd_step)``."""
    if q is None:
        return ""
    if "baseline" in q:                  # a config chosen by the run (bench.report.baselines)
        return f"baseline:{q['baseline']}"
    show = (lambda v: describe(v) if isinstance(v, dict) else f"{v:g}" if isinstance(v, float) else str(v))
    return f"{q['kind']}({', '.join(f'{k}={show(v)}' for k, v in q.items() if k != 'kind')})"
