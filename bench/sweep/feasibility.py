"""Whether a valid sweep can run: the checks that need the plugins and the machine.

After a sweep is parsed and its grids expanded (:mod:`bench.sweep.config`), every
scenario config's SNR levels are checked by the scenario
(:meth:`~bench.core.Scenario.check_snr`), every (method config, scenario
config) pair by the method (:meth:`~bench.core.Method.check_scenario`) and by
its task (:meth:`~bench.tasks.base.Task.check_pair`: whether the config can be
scored there; a pair either refuses is skipped, a method config refused
everywhere is an error), every unit's memory is estimated from the plugins' declared array sizes
(``unit_memory_bytes``) against ``max_unit_memory_gb``, and only then are the
checks that cost work in proportion to a config's size run (the scenario's
``check_config``) — so a sweep that would fail, hang or swap on every unit is
refused in one line, in seconds, before anything is written (docs/architecture.md,
'Run folders and faults').
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from radarbench.bench import registry
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.plan import Plan, ScenarioConfig

#: the default ``max_unit_memory_gb`` is this fraction of the machine's memory
#: (:func:`machine_memory_bytes`); N workers hold up to N units at once
UNIT_MEMORY_FRACTION = 0.5
GIB = 2 ** 30


def machine_memory_bytes() -> int:
    """Physical memory of the machine (or the container's cgroup limit, if lower);
    8 GiB when neither can be read."""
    total = None
    try:
        total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, OSError, ValueError):
        pass
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text(encoding="ascii").strip()
        except (OSError, UnicodeDecodeError):
            continue
        if text.isdigit() and 0 < int(text) < (total or math.inf):
            total = int(text)
    return int(total) if total and total > 0 else 8 * GIB


def default_unit_memory_gb() -> float:
    """The default ``max_unit_memory_gb``: :data:`UNIT_MEMORY_FRACTION` of the machine's memory."""
    return UNIT_MEMORY_FRACTION * machine_memory_bytes() / GIB


def check_snr_levels(plan: Plan, scenario_fields: tuple[str, ...]) -> None:
    """Every SNR level of every scenario config, by the scenario's
    :meth:`~bench.core.Scenario.check_snr` (e.g. noise scaled below what its
    trackers resolve in float64)."""
    for s, field in zip(plan.scenarios, scenario_fields):
        scenario = registry.get_scenario(s.name)()
        where = field.replace(".params", ".snr_db") if field != "scenario_params" else "snr_db"
        for snr in s.snr_db:
            problem = scenario.check_snr(s.params, snr)
            if problem:
                raise ConfigError(where, f"{snr:g} dB on scenario config {s.label!r}: {problem}"[:400])


def check_pairs(plan: Plan, method_fields: tuple[str, ...]) -> tuple[tuple[str, str, str], ...]:
    """Every (method config, scenario config) pair the sweep names, checked by the
    method's :meth:`~bench.core.Method.check_scenario` and its task's
    :meth:`~bench.tasks.base.Task.check_pair` after grid expansion (:func:`pair_problem`).
    A pair refused (a window longer than the scene, a tracker of another kind of
    scene, a statistic formed only after the onset) is skipped when the method config runs on some other scenario config
    of the sweep; returns the skipped pairs as (scenario label, method label,
    reason). A method config that runs on none is refused, in one line naming it
    and its first refused scenario config, rather than failing on every unit."""
    skipped = []
    for m, field in zip(plan.methods, method_fields):
        method = registry.get_method(m.name)()
        candidates = [s for s in plan.scenarios if any(p is m for p in plan.candidate_pairs(s))]
        refused = [(s, problem) for s in candidates if (problem := pair_problem(method, m.params, s))]
        if refused and len(refused) == len(candidates):
            s, problem = refused[0]
            raise ConfigError(f"{field}.params", f"{m.label!r} cannot run on scenario config "
                                                 f"{s.label!r}: {problem}"[:400])
        skipped += [(s.label, m.label, problem) for s, problem in refused]
    return tuple(skipped)


def pair_problem(method, method_params, scenario: ScenarioConfig) -> str | None:
    """Why a method config cannot run on ``scenario`` (the method's own
    :meth:`~bench.core.Method.check_scenario`), or cannot be scored there (its task's
    :meth:`~bench.tasks.base.Task.check_pair`, from what the method and the scenario
    declare); None: it can."""
    return method.check_scenario(method_params, scenario.params) or registry.get_task(method.task).check_pair(
        method, method_params, registry.get_scenario(scenario.name)(), scenario.params)


def unit_memory_bytes(plan: Plan, scenario: ScenarioConfig, n: int, calibration: bool) -> tuple[int, str]:
    """Estimated peak bytes of a unit of ``n`` trials of ``scenario`` (its batch, plus the
    largest working memory of the method configs that run on it, which run one after
    the other), and the label of that method config ("" if none declares any)."""
    batch = registry.get_scenario(scenario.name)().unit_memory_bytes(scenario.params, n) or 0
    worst, label = 0, ""
    for m in plan.pairs(scenario):
        if calibration and not registry.get_task(registry.get_method(m.name).task).calibrated:
            continue
        need = registry.get_method(m.name)().unit_memory_bytes(m.params, scenario.params, n) or 0
        if need > worst:
            worst, label = need, m.label
    return int(batch) + int(worst), label


def check_scenario_configs(plan: Plan, scenario_fields: tuple[str, ...]) -> None:
    """Every scenario config by its scenario's :meth:`~bench.core.Scenario.check_config`:
    the checks whose cost grows with the config, run after :func:`check_unit_memory`."""
    for s, field in zip(plan.scenarios, scenario_fields):
        try:
            registry.get_scenario(s.name)().check_config(s.params)
        except ConfigError as err:
            raise err.within(field) from None


def check_unit_memory(plan: Plan, scenario_fields: tuple[str, ...]) -> None:
    """Refuse a sweep whose units would need more memory than ``max_unit_memory_gb``
    (default: :func:`default_unit_memory_gb`), estimated from the array sizes
    before anything is allocated."""
    limit_gb = plan.max_unit_memory_gb if plan.max_unit_memory_gb is not None else default_unit_memory_gb()
    limit = limit_gb * GIB
    for s, field in zip(plan.scenarios, scenario_fields):
        calibrated = any(registry.get_task(registry.get_method(m.name).task).calibrated for m in plan.pairs(s))
        units = [(min(plan.chunk, s.trials), False)] + \
            ([(min(plan.chunk, plan.calibration.h0_trials), True)] if calibrated else [])
        for n, calibration in units:
            need, method = unit_memory_bytes(plan, s, n, calibration)
            if need > limit:
                one, _ = unit_memory_bytes(plan, s, 1, calibration)
                with_method = f" with {method!r}" if method else ""
                set_by = "the sweep's" if plan.max_unit_memory_gb is not None else \
                    f"the default ({UNIT_MEMORY_FRACTION:g} of this machine's memory)"
                raise ConfigError(field, f"a unit of {n} trials of {s.label!r}{with_method} needs about "
                                         f"{need / GIB:.3g} GB ({one / GIB:.3g} GB per trial), above "
                                         f"max_unit_memory_gb = {limit_gb:.3g}, {set_by}; make the scene "
                                         f"smaller, lower 'chunk', or raise max_unit_memory_gb"[:400])
