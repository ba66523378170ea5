"""The strongest baseline of a claim, chosen by the run (docs/architecture.md, 'Report').

A claims file may declare named selections of baselines instead of naming one config by hand::

    [baseline.strongest]
    best_of = ["method-a[*]", "method-b[window=8]"]   # config labels; METHOD[*]: all its configs
    by = "ranking"            # the order of *Results at a glance* (the default)
    scenario = "scene-label"  # optional: else the scenario config of the quantity that names it

and a quantity names one wherever it names a config (``config``, ``a``, ``b``):
``b = { baseline = "strongest" }``. The selection is the candidate ranked first, read from
the run's comparisons.csv alone (so a committed report's claims regenerate from its CSVs): for
each candidate the mean of the task's ranking metric at each SNR level, averaged over the levels
(each level weighing the same, as the glance averages), ``by = "ranking"`` on the outcome at
equal chance Pd where the run has it (the glance's metric), ``by = "ranking_metric"`` on the
task's ranking metric itself. Candidates are the entries of ``best_of`` in file order: a config's
label, or ``METHOD[*]`` for every config of that method in the run's order; one that did not run
is left out (an optional method unavailable here), and if none ran the claim is *not comparable*.
Means equal within :data:`bench.metrics.RELATIVE_RESOLUTION` are a tie, which goes to the earlier
candidate.
Templates read the chosen config as ``baseline`` (a claim's reason: the one its quantity names)
and ``baselines.NAME`` (every template), both :class:`Chosen`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np
import pandas as pd

from radarbench.bench.errors import ConfigError
from radarbench.bench.metrics import RELATIVE_RESOLUTION
from radarbench.bench.report.quantities import INLINE, Missing, Tables

#: ``by`` -> whether the outcome at equal chance Pd ranks where the run has it (as the glance)
BY = {"ranking": True, "ranking_metric": False}
#: the keys of a quantity that name a config, which a baseline reference may take
CONFIG_KEYS = ("config", "a", "b")
#: ``METHOD[*]`` in ``best_of``: every config of the method
EVERY = "[*]"


@dataclass(frozen=True)
class Selection:
    """One ``[baseline.NAME]`` of a claims file, validated."""

    name: str
    best_of: tuple[str, ...]
    by: str = "ranking"
    scenario: str = ""


@dataclass(frozen=True)
class Chosen:
    """The config a selection chose on one scenario config: ``config`` (also its ``str``), the
    ``metric`` it was ranked on, its ``mean`` over the levels, and the whole ``ranking``
    ((config, mean), best first); ``missing`` says why nothing was chosen."""

    selection: str
    config: str = "–"
    scenario: str = ""
    metric: str = ""
    mean: float = math.nan
    ranking: tuple[tuple[str, float], ...] = ()
    missing: str = ""

    def __str__(self) -> str:
        return self.config


# ------------------------------------------------------------------ the file

def parse_selections(raw: Any, field: str) -> dict[str, Selection]:
    """The ``[baseline]`` table of a claims file: name -> :class:`Selection`."""
    if not isinstance(raw, dict):
        raise ConfigError(field, f"expected a table of named selections, got {raw!r}"[:200])
    return {name: _selection(name, table, f"{field}.{name}") for name, table in raw.items()}


def _selection(name: str, table: Any, field: str) -> Selection:
    if not isinstance(table, dict):
        raise ConfigError(field, f"expected a table with best_of, got {table!r}"[:200])
    for key in table:
        if key not in ("best_of", "by", "scenario"):
            raise ConfigError(f"{field}.{key}", "unknown key (allowed: best_of, by, scenario)")
    best_of = table.get("best_of")
    if not isinstance(best_of, list) or not best_of or not all(isinstance(x, str) and x.strip() for x in best_of):
        raise ConfigError(f"{field}.best_of", f"expected a non-empty list of config labels or METHOD{EVERY}, "
                                              f"got {best_of!r}"[:200])
    by = table.get("by", "ranking")
    if by not in BY:
        raise ConfigError(f"{field}.by", f"expected one of {', '.join(BY)}, got {by!r}")
    scenario = table.get("scenario", "")
    if not isinstance(scenario, str) or ("scenario" in table and not scenario.strip()):
        raise ConfigError(f"{field}.scenario", f"expected a scenario config's label, got {scenario!r}"[:200])
    return Selection(name, tuple(best_of), by, scenario)


def is_reference(value: Any) -> bool:
    """Whether a quantity's config slot names a selection (``{ baseline = "NAME" }``)."""
    return isinstance(value, dict) and "baseline" in value


def check_reference(value: Any, field: str, names=None) -> dict:
    """A config slot's ``{ baseline = "NAME" }``, checked against the file's selections
    ``names`` (None: its shape alone)."""
    if set(value) != {"baseline"} or not isinstance(value["baseline"], str):
        raise ConfigError(field, f"expected {{ baseline = \"NAME\" }}, got {value!r}"[:200])
    if names is not None and value["baseline"] not in names:
        known = ", ".join(sorted(names)) or "none declared"
        raise ConfigError(f"{field}.baseline", f"no [baseline.{value['baseline']}] (selections: {known})")
    return dict(value)


# ------------------------------------------------------------------ the choice

def _only_scenario(t: Tables) -> str:
    scenarios = list(dict.fromkeys(t.summary.scenario)) if not t.summary.empty else []
    if len(scenarios) != 1:
        raise ConfigError("scenario", f"the run has {len(scenarios)} scenario configs: name one")
    return scenarios[0]


def candidates(selection: Selection, t: Tables, scenario: str) -> list[str]:
    """The configs of ``best_of`` that ran on ``scenario``, in file order, a ``METHOD[*]``'s in the run's order."""
    rows = t.summary[t.summary.scenario == scenario] if not t.summary.empty else t.summary
    configs = list(dict.fromkeys(rows.config)) if not rows.empty else []
    method_of = dict(zip(rows.config, rows.method)) if not rows.empty else {}
    out: list[str] = []
    for entry in selection.best_of:
        method = entry[:-len(EVERY)] if entry.endswith(EVERY) else None
        out += [c for c in configs if (method_of[c] == method if method else c == entry) and c not in out]
    return out


def _ranked_on(selection: Selection, rows: pd.DataFrame) -> tuple[str, bool]:
    """(metric, higher is better) the candidates' rows of comparisons.csv are ranked on."""
    from radarbench.bench import registry
    tasks = list(dict.fromkeys(rows.task))
    if len(tasks) != 1:
        raise ConfigError(f"baseline.{selection.name}.best_of",
                          f"the candidates belong to {len(tasks)} tasks ({', '.join(tasks)}): rank one task's")
    task = registry.get_task(tasks[0])
    fair = task.equal_chance_metric if BY[selection.by] else ""
    metric = fair if fair and fair in set(rows.metric) else task.ranking_metric
    return metric, bool(task.ranking_higher_is_better)


def level_means(rows: pd.DataFrame, configs: list[str]) -> dict[str, float]:
    """config -> the mean over SNR levels of its per-level mean (comparisons.csv's ``mean_a`` /
    ``mean_b`` of the per-level rows; each level weighing the same, as the glance averages)."""
    per_level = rows[rows.snr_db.notna()]
    sides = pd.concat([per_level[["snr_db", "config_a", "mean_a"]].set_axis(["snr_db", "config", "mean"], axis=1),
                       per_level[["snr_db", "config_b", "mean_b"]].set_axis(["snr_db", "config", "mean"], axis=1)])
    first = sides.groupby(["config", "snr_db"], sort=False)["mean"].first()
    return {c: float(first[c].mean()) if c in first.index.get_level_values(0) else math.nan for c in configs}


def best_first(means: Mapping[str, float], higher_is_better: bool) -> list[tuple[str, float]]:
    """(config, mean) best first, configs without a mean left out; the first is the earliest of
    the configs within :data:`RELATIVE_RESOLUTION` of the best mean (a tie, in ``means``' order)."""
    sign = -1.0 if higher_is_better else 1.0
    ranked = sorted(((c, m) for c, m in means.items() if np.isfinite(m)), key=lambda cm: sign * cm[1])
    if not ranked:
        return []
    best = ranked[0][1]
    tied = next(c for c, m in means.items() if np.isfinite(m) and abs(m - best) <= RELATIVE_RESOLUTION * abs(best))
    return [(tied, means[tied])] + [(c, m) for c, m in ranked if c != tied]


def choose(selection: Selection, t: Tables, scenario: str = "") -> Chosen:
    """The candidate of ``selection`` ranked first on its scenario config (its own, else
    ``scenario``, else the run's only one); raises :class:`Missing` when none ran."""
    scenario = selection.scenario or scenario or _only_scenario(t)
    configs = candidates(selection, t, scenario)
    if not configs:
        listed = ", ".join(selection.best_of)
        raise Missing(f"every candidate of baseline {selection.name!r} ({listed}) on `{scenario}`")
    df = t.comparisons
    rows = df[(df.scenario == scenario) & (df.config_a.isin(configs) | df.config_b.isin(configs))] \
        if not df.empty else df
    if rows.empty:
        if len(configs) == 1:              # a lone candidate: nothing to compare it with
            return Chosen(selection.name, configs[0], scenario, ranking=((configs[0], math.nan),))
        raise ConfigError(f"baseline.{selection.name}", f"comparisons.csv ranks none of {', '.join(configs)}")
    metric, higher = _ranked_on(selection, rows)
    ranking = best_first(level_means(rows[rows.metric == metric], configs), higher)
    if not ranking:
        raise Missing(f"a ranked config of baseline {selection.name!r} on `{scenario}`")
    return Chosen(selection.name, ranking[0][0], scenario, metric, ranking[0][1], tuple(ranking))


def resolve(q: dict, selections: Mapping[str, Selection], t: Tables) -> tuple[dict, list[Chosen]]:
    """Quantity ``q`` with each baseline reference replaced by the config it chooses (on the
    scenario config the slot's quantity reads), and the choices in order."""
    chosen: list[Chosen] = []
    out = dict(q)
    for key in CONFIG_KEYS:
        value = q.get(key)
        if q["kind"] in INLINE and isinstance(value, dict):
            out[key], inner = resolve(value, selections, t)
            chosen += inner
        elif is_reference(value):
            pick = choose(selections[value["baseline"]], t, q.get(f"scenario_{key}", q.get("scenario", "")))
            out[key] = pick.config
            chosen.append(pick)
    return out, chosen


def template_values(selections: Mapping[str, Selection], t: Tables) -> dict[str, Chosen]:
    """name -> :class:`Chosen` on the selection's scenario config (or the run's only one), for
    ``baselines.NAME`` in the notes and reasons; a choice the run cannot make reads "–" with why."""
    out = {}
    for name, selection in selections.items():
        try:
            out[name] = choose(selection, t)
        except (Missing, ConfigError) as why:
            out[name] = Chosen(name, missing=str(why))
    return out
