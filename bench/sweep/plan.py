"""The resolved sweep: what a run runs, every default filled in (docs/architecture.md,
'Sweep files and presets').

:class:`Plan` holds the scenario configs (:class:`ScenarioConfig`, each with its SNR levels
and trials), the method configs (:class:`ComponentConfig`) and the calibration
(:class:`CalibrationConfig`); :meth:`Plan.to_dict` writes it back as the sweep file that
reproduces it (plan.toml) and :meth:`Plan.fingerprint` is the identity of its results.
How a config is labelled (:func:`label_value`) and keyed lives here too: both are part of
its identity. A sweep file becomes a plan in :mod:`bench.sweep.config` (reading and checking the
TOML), its grids expand in :mod:`bench.sweep.grid`.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from radarbench.bench.sweep import capabilities
from radarbench.bench import registry
from radarbench.bench.params import params_as_dict, path_fields

#: significant digits of an SNR level in a unit's key (:func:`snr_key`): levels that
#: agree to this many digits are one level, and a sweep listing two of them is refused
SNR_KEY_DIGITS = 9


def snr_key(snr_db: float | None) -> str:
    """The canonical text of an SNR level, as in a unit's key (``"null"`` for the
    null hypothesis): two levels are the same level exactly when their keys are
    equal, which the sweep's duplicate check uses (:func:`bench.sweep.config._parse_snr`) and
    :attr:`bench.run.units.Unit.key` must use too."""
    return "null" if snr_db is None else f"{snr_db:+.{SNR_KEY_DIGITS}g}"


@dataclass(frozen=True)
class ComponentConfig:
    """One expanded config of a method or scenario."""

    name: str
    params: Any                 # the component's Params instance (all defaults filled)
    label: str                  # the config's identity, e.g. "cumulant[window=32]"
    params_text: str            # what distinguishes it, "window=32" (the ``params`` CSV column)

    @property
    def key(self) -> int:
        """The stable integer that keys a scenario config's random streams: from its name and
        the params set away from their defaults, and those its class keys whatever their
        value (:attr:`bench.core.Scenario.stream_params`); a data file by its name, so the
        streams do not depend on the folder the data lives in (docs/architecture.md,
        'Random streams')."""
        from radarbench.bench.sweep.rng import stable_key   # NumPy: not before a sweep's own fields are checked
        cls = registry.find_scenario(self.name)
        always = set(getattr(cls, "stream_params", None) or ())
        defaults = params_as_dict(type(self.params)())
        paths = path_fields(type(self.params))
        values = {k: os.path.basename(v) if k in paths else v
                  for k, v in params_as_dict(self.params).items() if k in always or v != defaults[k]}
        return stable_key([registry.bare_name(self.name), values])   # radarbench:x draws what x draws


@dataclass(frozen=True)
class ScenarioConfig(ComponentConfig):
    """A scenario config with the SNR levels and trials it is run at."""

    snr_db: tuple[float, ...] = ()
    trials: int = 0
    tasks: tuple[str, ...] = ()


@dataclass(frozen=True)
class CalibrationConfig:
    pfa: float = 0.01
    mode: str = "empirical"
    h0_trials: int = 2000
    #: the chance Pd (fraction of null trials whose detection window alarms)
    #: every detector is calibrated to for the equal-chance Pd definition
    chance_pd: float = 0.05


@dataclass(frozen=True)
class Plan:
    """The fully resolved sweep: what runs, with every default filled in."""

    name: str
    description: str
    scenario: str               # the scenario name; "" for a [[scenarios]] list
    scenarios: tuple[ScenarioConfig, ...]
    trials: int
    seed: int
    snr_db: tuple[float, ...]
    chunk: int
    methods: tuple[ComponentConfig, ...]
    calibration: CalibrationConfig
    record_trials: int
    source: str
    method_tasks: tuple[str, ...] = ()   # task of each method config, in order
    timeline_snr_db: float | None = None  # report: the recorded trial shown over time (None: highest SNR)
    unit_timeout_s: float | None = None   # a unit running longer fails (timeout); None: no limit
    #: the single-scenario form: the grid axes of ``scenario_params`` in the order the
    #: sweep wrote them (the order of the labels), which plan.toml keeps
    scenario_axes: tuple[str, ...] = ()
    #: the sweep's ``max_unit_memory_gb`` when it set one (None: the machine's default)
    max_unit_memory_gb: float | None = None
    #: ``[[methods]]`` entries marked ``optional = true`` whose method is unavailable here
    #: (a missing extra): (the entry as written, why), skipped; the report lists them
    skipped_methods: tuple[tuple[dict, str], ...] = ()
    #: (scenario config label, method config label, the method's reason) of the pairs its
    #: ``check_scenario`` refuses while the method config runs on another scenario config
    #: of the sweep: skipped, no units, no rows (:func:`bench.sweep.feasibility.check_pairs`)
    skipped: tuple[tuple[str, str, str], ...] = ()
    #: the absolute folder of the sweep file its data files (``kind="path"`` parameters) were
    #: read from, which a report names them relative to; None: a plan parsed without one
    sweep_folder: str | None = None

    def pairs(self, scenario: ScenarioConfig) -> list[ComponentConfig]:
        """The method configs that run on ``scenario``: those whose task it serves and whose
        capabilities fit (:mod:`bench.sweep.capabilities`), less the skipped pairs."""
        return [m for m in self.candidate_pairs(scenario) if (scenario.label, m.label) not in self._skipped_keys]

    def candidate_pairs(self, scenario: ScenarioConfig) -> list[ComponentConfig]:
        """The method configs whose task and capabilities fit ``scenario`` (before
        their ``check_scenario``)."""
        return [m for m in self.methods if (scenario.label, m.label) in self._fitting]

    @cached_property
    def _fitting(self) -> frozenset[tuple[str, str]]:
        """(scenario config label, method config label) of the pairs whose task and
        capabilities fit (:func:`bench.sweep.capabilities.fits`)."""
        return frozenset((s.label, m.label) for s in self.scenarios for m in self.methods
                         if capabilities.fits(registry.get_method(m.name), registry.get_scenario(s.name), s.params))

    @property
    def _skipped_keys(self) -> frozenset[tuple[str, str]]:
        return frozenset((scenario, method) for scenario, method, _ in self.skipped)

    @property
    def trial_runs(self) -> int:
        return sum(s.trials * len(s.snr_db) * len(self.pairs(s)) for s in self.scenarios)

    def to_dict(self, paths_from: str | os.PathLike | None = None) -> dict[str, Any]:
        """The plan as a sweep file that reproduces it: with ``paths_from``, as a sweep file in
        that folder (plan.toml in the run folder), its data files named relative to it (never
        absolute: a shared plan.toml does not disclose its author's folders); without it, the
        data files as held (absolute: the fingerprint and the store)."""
        head = {"name": self.name, "description": self.description}
        if self.scenario:
            head |= {"scenario": self.scenario, "trials": self.trials, "seed": self.seed,
                     "snr_db": list(self.snr_db), "chunk": self.chunk,
                     "scenario_params": _merge_scenario_grid(self.scenarios, self.scenario_axes, paths_from)}
        else:
            head |= {"trials": self.trials, "seed": self.seed, "snr_db": list(self.snr_db),
                     "chunk": self.chunk,
                     "scenarios": [{"name": s.name, "label": s.label, "params": params_as_dict(s.params, paths_from),
                                    "snr_db": list(s.snr_db), "trials": s.trials} for s in self.scenarios]}
        # written only when set, so plans without it keep their plan.toml
        head |= {} if self.unit_timeout_s is None else {"unit_timeout_s": self.unit_timeout_s}
        return head | {
            "methods": [{"name": m.name, "label": m.label, "params": params_as_dict(m.params, paths_from)}
                        for m in self.methods] + [entry | {"optional": True} for entry, _ in self.skipped_methods],
            "calibration": {"pfa": self.calibration.pfa, "mode": self.calibration.mode,
                            "h0_trials": self.calibration.h0_trials}
                           # written only when set, so plans without it keep their fingerprints
                           | ({} if self.calibration.chance_pd == CalibrationConfig.chance_pd
                              else {"chance_pd": self.calibration.chance_pd}),
            "record": {"trials": self.record_trials}
                      | ({} if self.timeline_snr_db is None else {"timeline_snr_db": self.timeline_snr_db}),
        } | ({} if self.max_unit_memory_gb is None else {"max_unit_memory_gb": self.max_unit_memory_gb})

    def fingerprint(self) -> str:
        """Identity of the results a run of this plan produces (for resume): the
        description and the memory limit do not change results."""
        d = self.to_dict()
        d.pop("description")
        d.pop("unit_timeout_s", None)     # a time limit changes no result: a run may resume under another
        d.pop("max_unit_memory_gb", None)
        from radarbench.bench.sweep.rng import stable_key
        return f"{stable_key(d):016x}"


def format_value(v: Any) -> str:
    """How a label writes a parameter's value: ``true``, ``32`` for 32.0, ``(1,2)`` for a list."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(int(v)) if v.is_integer() and abs(v) < 1e15 else repr(v)
    if isinstance(v, (list, tuple)):
        return "(" + ",".join(format_value(x) for x in v) + ")"
    return str(v)


def label_value(params: Any, key: str) -> str:
    """How a label writes parameter ``key``: a data file by its name alone (its folder
    depends on where the sweep lives; the label must not)."""
    value = getattr(params, key)
    return os.path.basename(value) if key in path_fields(type(params)) else format_value(value)


def _merge_scenario_grid(configs: tuple[ComponentConfig, ...], axes: tuple[str, ...] = (),
                         paths_from: str | os.PathLike | None = None) -> dict[str, Any]:
    """Scenario params of the plan: resolved values, lists where a grid varies.

    Keys in declaration order, except that the grid axes (the keys that vary)
    keep the order ``axes`` gives them (the sweep's): the order of the axes is
    the order of the configs and of the names in their labels, so
    ``bench run plan.toml`` gives the same labels and resumes the same units."""
    dicts = [params_as_dict(c.params, paths_from) for c in configs]
    merged = {}
    for key in dicts[0]:
        values = [d[key] for d in dicts]
        distinct = [v for i, v in enumerate(values) if v not in values[:i]]
        merged[key] = distinct[0] if len(distinct) == 1 else distinct
    varying = [k for k in merged if len(configs) > 1 and any(d[k] != dicts[0][k] for d in dicts)]
    ordered = [k for k in axes if k in varying] + [k for k in varying if k not in axes]
    slots = iter(ordered)                  # the varying keys' places, filled in the sweep's order
    keys = [next(slots) if k in varying else k for k in merged]
    return {k: merged[k] for k in keys}
