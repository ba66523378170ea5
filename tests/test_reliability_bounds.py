"""The documented bounds of every parameter are the enforced ones, and
validation is bounded in time and memory (a huge map is refused before any layout search).

Every refusal is met as in ``tests/test_reliability_validation.py``: exit code 2, one
line naming the field, nothing written. Impossible outputs and parameters that cannot
work: ``tests/test_reliability_outputs.py``.
"""

from __future__ import annotations

import dataclasses
import math
import re

import numpy as np
import pytest

from radarbench.bench import registry
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.listing import plugin_listing
from radarbench.bench.params import build_params

registry.discover()


# ------------------------------------------------------------------ documented bounds == enforced ones

#: ``bench list -v`` prints each bound as ``[>= 2 and <= 12: why]`` after the doc.
_BOUNDS = re.compile(r"\[((?:[<>]=? -?[\d.e+-]+)(?: and [<>]=? -?[\d.e+-]+)*)[:\]]")
_PARAM_LINE = re.compile(r"^      (\w+) \(([^,]+), default .*?\): (.*)$")


def listed_bounds() -> list[tuple[str, str, str, str, str, float]]:
    """(kind, plugin, field, type, operator, value) of every bound ``bench list -v`` prints."""
    rows, kind, plugin = [], None, None
    for line in plugin_listing(verbose=True).splitlines():
        if line in ("scenarios:", "methods:", "unavailable:", "tasks:"):
            kind = line[:-1]
            continue
        if kind in ("scenarios", "methods") and (m := re.match(r"^  (\S+)\s", line)):
            plugin = m.group(1)
        elif kind in ("scenarios", "methods") and (m := _PARAM_LINE.match(line)):
            found = _BOUNDS.findall(m.group(3))
            for part in (found[-1].split(" and ") if found else []):
                op, value = part.split(" ")
                rows.append((kind, plugin, m.group(1), m.group(2), op, value))
    return rows


#: The other values under which a bound holds where another field constrains it (a
#: cross-field check: the bound itself is reached, with these companions). Keyed by
#: (plugin, field, bound as printed).
COMPANIONS = {
    ("cv-turn-cv", "steps", "2"): {"onset_step": 1, "turn_steps": 1, "warmup_steps": 0, "detect_window_steps": 1},
    ("cv-turn-cv", "onset_step", "1"): {"warmup_steps": 0},
    ("cv-turn-cv", "onset_step", "9999"): {"steps": 10000, "turn_steps": 1, "detect_window_steps": 1},
    ("cv-turn-cv", "warmup_steps", "9998"): {"steps": 10000, "onset_step": 9999, "turn_steps": 1,
                                             "detect_window_steps": 1},
    **{("cv-turn-cv", f, v): {"steps": 10000, "onset_step": 1, "turn_steps": 1, "warmup_steps": 0,
                              "detect_window_steps": 1}
       for f, v in (("turn_steps", "9999"), ("detect_window_steps", "9999"), ("onset_jitter_steps", "9998"))},
    ("recorded-tracks", "steps", "5"): {"onset_step": 1, "warmup_steps": 0, "detect_window_steps": 1},
    ("recorded-tracks", "onset_step", "1"): {"warmup_steps": 0},
    ("recorded-tracks", "onset_step", "9999"): {"steps": 10000, "detect_window_steps": 1},
    ("recorded-tracks", "detect_window_steps", "9999"): {"steps": 10000, "onset_step": 1, "warmup_steps": 0},
    ("recorded-tracks", "warmup_steps", "9998"): {"steps": 10000, "onset_step": 9999, "detect_window_steps": 1},
    ("glint", "initial_range_m", "10.0"): {"initial_range_std_m": 1.0},
    ("glint", "initial_range_std_m", "100000.0"): {"initial_range_m": 1e6},
    ("glint", "process_noise_los_m_s2", "0.0"): {"process_noise_los_m_s2": (0.0, 0.0, 0.0)},
    ("glint", "process_noise_los_m_s2", "100.0"): {"process_noise_los_m_s2": (100.0, 100.0, 100.0)},
    ("glint", "initial_angle_std_rad", "1e-06"): {"initial_angle_std_rad": (1e-6, 1e-6)},
    ("glint", "initial_angle_std_rad", "0.1"): {"initial_angle_std_rad": (0.1, 0.1)},
    ("hfswr-targets", "targets", "1"): {"crossing": False},
    ("hfswr-targets", "crossing_targets", "100"): {"targets": 100},
    ("maneuvering-1d", "steps", "2"): {"dt_s": 100.0},
    ("maneuvering-1d", "dt_s", "0.001"): {"maneuver_start_s": 0.0},
    ("maneuvering-1d", "maneuver_start_s", "1000000.0"): {"profile": "singer"},
    **{("cusum", "window", v): {"score": "glr"} for v in ("1", "1000")},      # the GLR score's window
    ("recorded-tracks", "min_steps", "10000"): {"steps": 10000},             # at most steps
    ("ar-adaptive", "order_low", "5"): {"order_high": 6, "state_dim": 7},
    ("ar-adaptive", "order_high", "1"): {"order_low": 0},
    ("ar-adaptive", "order_high", "6"): {"state_dim": 7},
    ("current-statistical", "accel_std_floor_m_s2", "1000.0"): {"a_max_m_s2": 1000.0},
    **{(m, f, v): c for m in ("imm-cv-ca", "imm-cv-ct") for f, v, c in (
        ("transition", "0.0", {"transition": (0.0, 1.0, 0.5, 0.5)}),
        ("transition", "1.0", {"transition": (0.0, 1.0, 0.5, 0.5)}),
        ("initial_probabilities", "0.0", {"initial_probabilities": (0.0, 1.0)}),
        ("initial_probabilities", "1.0", {"initial_probabilities": (1.0, 0.0)}))},
    ("innovation", "delta", "0.999"): {"window": 1},
    **{(m, f, v): c for m in ("gnn-ekf", "jpda-ukf", "stonesoup-jpda", "stonesoup-mfa") for f, v, c in (
        ("confirm_m", "20", {"confirm_n": 20}), ("confirm_n", "1", {"confirm_m": 1}),
        ("terminate_m", "60", {"terminate_n": 60}), ("terminate_n", "1", {"terminate_m": 1}))},
    **{(m, f, v): c for m in ("os-cfar", "region-adaptive") for f, v, c in (
        ("reference_range", "1", {"k_range": 1}), ("reference_doppler", "1", {"k_doppler": 1}),
        ("k_range", "512", {"reference_range": 256}), ("k_doppler", "512", {"reference_doppler": 256}))},
    ("wavelet", "levels", "1"): {"coarsest": 1},
    ("wavelet", "coarsest", "8"): {"levels": 8},
    ("tbd-grid", "cells", "8"): {"frames": 4, "cell_m": 1e5},
    ("tbd-grid", "frames", "2"): {"noise": "white"},
    ("tbd-grid", "frames", "1000"): {"cell_m": 1e5},
    ("tbd-grid", "frame_period_s", "100.0"): {"cell_m": 1e5},
    ("tbd-grid", "cell_m", "1.0"): {"frame_period_s": 1e-3},
    ("rd-map", "range_cells", "16"): {"interference_range_start": 0, "edge_range_cell": 8, "margin_cells": 0},
    ("rd-map", "doppler_cells", "16"): {"bragg_offset_bins": 4, "margin_cells": 0},
    ("rd-map", "bragg_offset_bins", "8191"): {"doppler_cells": 16384},
    ("rd-map", "interference_range_start", "4095"): {"range_cells": 4096, "interference_range_cells": 1},
    ("rd-map", "interference_range_cells", "4096"): {"range_cells": 4096, "interference_range_start": 0},
    ("rd-map", "edge_range_cell", "4095"): {"range_cells": 4096},
    ("rd-map", "margin_cells", "2047"): {"range_cells": 4096, "doppler_cells": 16384},
    ("hfswr-rd-scans", "targets", "1"): {"crossing": False},
    ("hfswr-rd-scans", "range_cells", "16"): {"interference_range_start": 0, "edge_range_cell": 8},
    ("hfswr-rd-scans", "interference_range_start", "1023"): {"range_cells": 1024, "interference_range_cells": 1},
    ("hfswr-rd-scans", "interference_range_cells", "1024"): {"range_cells": 1024, "interference_range_start": 0},
    ("hfswr-rd-scans", "edge_range_cell", "1023"): {"range_cells": 1024},
    ("hfswr-rd-scans", "crossing_targets", "50"): {"targets": 50},
}


def _plugin(kind: str, name: str):
    return (registry.get_scenario if kind == "scenarios" else registry.get_method)(name)


def _number(tp: str, text: str):
    return int(text) if "int" in tp else float(text)


def _beyond(op: str, value, is_int: bool):
    """The nearest value on the wrong side of ``op value`` (``>``/``<``: the bound itself)."""
    if op in (">", "<"):
        return value
    if is_int:
        return value - 1 if op == ">=" else value + 1
    return math.nextafter(value, -math.inf if op == ">=" else math.inf)


def _with(cls, field: str, value, lower: bool, companions: dict):
    """``{field: value}`` with the companions; in a tuple field the value replaces the
    default's first element for a lower bound, its last for an upper one ([min, max] pairs)."""
    default = getattr(cls.Params(), field)
    if isinstance(default, tuple):
        value = (value,) if not default else (value, *default[1:]) if lower else (*default[:-1], value)
    return {field: value} | companions


@pytest.mark.parametrize("kind, plugin, field, tp, op, text", listed_bounds(),
                         ids=lambda x: str(x) if not isinstance(x, str) or len(x) < 30 else x[:30])
def test_every_listed_bound_is_the_enforced_one(kind, plugin, field, tp, op, text):
    """``bench list -v`` prints each bound; at it the value is accepted (with the
    companions a cross-field check needs, :data:`COMPANIONS`), just beyond it refused
    naming the field. state_dim = 2 of ar-adaptive was listed as allowed and refused."""
    cls = _plugin(kind, plugin)
    is_int = "int" in tp
    value = _number(tp, text)
    companions = COMPANIONS.get((plugin, field, text), {})
    if op in (">=", "<="):
        values = _with(cls, field, value, op == ">=", companions)
        try:
            build_params(cls.Params, values)
        except ConfigError as err:
            pytest.fail(f"{plugin}.{field} = {values[field]!r} (listed {op} {text}) refused: {err}")
    beyond = _beyond(op, value, is_int)
    values = _with(cls, field, beyond, op[0] == ">", {k: v for k, v in companions.items() if k != field})
    with pytest.raises(ConfigError) as err:
        build_params(cls.Params, values)
    assert err.value.field.split("[")[0] == field and "expected" in err.value.problem, err.value


def test_the_listing_holds_every_numeric_bound():
    """The parse above misses nothing: every declared ge/gt/le/lt appears in the listing."""
    listed = {(p, f, op) for _, p, f, _, op, _ in listed_bounds()}
    declared = set()
    for table in (registry.scenarios(), registry.methods()):
        for name, cls in table.items():
            for f in dataclasses.fields(cls.Params):
                for key, op in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")):
                    if f.metadata.get(key) is not None:
                        declared.add((name, f.name, op))
    assert declared == listed


def _old_place_targets(labels, names, *, per_region, pairs, pair_offset, spacing, margin, seed):
    """The straightforward layout search (a Python loop over every candidate, a distance
    test against every placed target): the oracle of :func:`models.rd_map.place_targets`."""
    def far_enough(cell, placed):
        return not placed or int(np.abs(np.asarray(placed) - cell).max(axis=1).min()) >= spacing
    R, D = labels.shape
    rng = np.random.default_rng(seed)
    inside = np.zeros(labels.shape, bool)
    inside[margin:R - margin, margin:D - margin] = True
    placed, paired, missing = [], [], []
    present = [k for k in range(len(names)) if np.any(labels == k)]
    for k in sorted(present, key=lambda k: int(np.count_nonzero(labels == k))):
        candidates = np.argwhere((labels == k) & inside)
        got = 0
        for cell in candidates[rng.permutation(len(candidates))]:
            if got == per_region:
                break
            if far_enough(cell, placed):
                placed.append(cell)
                paired.append(False)
                got += 1
        if got < per_region:
            missing.append(f"{per_region - got} of {per_region} targets in region {names[k]!r}")
    home, offset = names.index("homogeneous"), np.asarray(pair_offset, np.int64)
    candidates = np.argwhere((labels == home) & inside)
    got = 0
    for cell in candidates[rng.permutation(len(candidates))]:
        if got == pairs:
            break
        mate = cell + offset
        if not (margin <= mate[0] < R - margin and margin <= mate[1] < D - margin) or labels[tuple(mate)] != home:
            continue
        if far_enough(cell, placed) and far_enough(mate, placed):
            placed += [cell, mate]
            paired += [True, True]
            got += 1
    if got < pairs:
        missing.append(f"{pairs - got} of {pairs} pairs in region 'homogeneous'")
    return np.asarray(placed, np.int64).reshape(-1, 2), np.asarray(paired, bool), "; ".join(missing)


@pytest.mark.parametrize("chunks", [(4096, 1 << 20), (2, 8)], ids=["as-run", "tiny-chunks"])
def test_the_vectorised_layout_search_places_every_target_where_the_loop_did(chunks, monkeypatch):
    """The same cells, flags and shortfall as the loop it replaces, on random label maps
    (tiny chunks: the growth and the early stop on maps this small)."""
    import radarbench.models.rd_map as rd
    monkeypatch.setattr(rd, "_SCAN_CHUNK", chunks[0])
    monkeypatch.setattr(rd, "_SCAN_CHUNK_MAX", chunks[1])
    names = ("homogeneous", "bragg", "interference", "clutter-edge")
    rng = np.random.default_rng(0)
    for case in range(150):
        R, D = (int(x) for x in rng.integers(16, 64, 2))
        labels = rng.integers(0, 4, (R, D)).astype(np.int8)
        if case % 3 == 0:
            labels[:] = 0
            labels[:R // 3] = 1
        offset = (int(rng.integers(-3, 4)), int(rng.integers(1, 4)))
        kw = dict(per_region=int(rng.integers(0, 6)), pairs=int(rng.integers(0, 5)), pair_offset=offset,
                  spacing=int(rng.integers(1, 40)), margin=int(rng.integers(0, 6)), seed=int(rng.integers(0, 100)))
        new, old = rd.place_targets(labels, names, **kw), _old_place_targets(labels, names, **kw)
        assert np.array_equal(new[0], old[0]) and np.array_equal(new[1], old[1]) and new[2] == old[2], (case, kw)


HUGE_MAP = {"range_cells": 4096, "doppler_cells": 16384, "targets_per_region": 64, "pairs": 32,
            "target_spacing_cells": 4096}


def test_a_huge_map_above_the_memory_limit_is_refused_before_any_layout_search(monkeypatch):
    """The issue's case ran > 420 s and reached 4.4 GB before the memory check: now the
    memory check comes first and the layout is never built."""
    import radarbench.models.rd_map as rd
    from tests.test_reliability_validation import refused, sweep, toml

    def no_layout(*args, **kwargs):
        raise AssertionError("the layout was searched before the memory check")
    monkeypatch.setattr(rd, "background_power", no_layout)
    monkeypatch.setattr(rd, "place_targets", no_layout)
    import radarbench.scenarios.rd_map as scenario
    monkeypatch.setattr(scenario, "background_power", no_layout)
    monkeypatch.setattr(scenario, "place_targets", no_layout)
    scenario.scene_layout.cache_clear()
    data = sweep(scenarios=[{"name": "rd-map", "params": HUGE_MAP}], methods=[{"name": "ca-cfar"}],
                 max_unit_memory_gb=2.0, chunk=1)
    del data["scenario"], data["scenario_params"]
    refused(toml(data), "scenarios[0].params: a unit of 1 trials of 'rd-map'", "max_unit_memory_gb = 2")


def test_a_large_map_without_room_is_refused_in_one_pass(tmp_path):
    """8 M cells whose targets cannot fit: the loop examined every candidate against every
    placed target (minutes); the refusal now comes from one pass. A hang guard, not a
    timing: 60 s is ten times what the pass takes on a loaded machine."""
    import signal

    from conftest import scaled
    from tests.test_reliability_validation import refused, sweep, toml
    bound = round(scaled(60))

    def hung(*_):
        raise TimeoutError(f"the layout search still runs after {bound} s")
    previous = signal.signal(signal.SIGALRM, hung)
    signal.alarm(bound)
    try:
        data = sweep(scenarios=[{"name": "rd-map", "params": HUGE_MAP | {"range_cells": 512}}],
                     methods=[{"name": "ca-cfar"}], chunk=1, trials=1)
        del data["scenario"], data["scenario_params"]
        refused(toml(data), "scenarios[0].params.targets_per_region: no room for every target: ",
                "32 of 32 pairs in region 'homogeneous'")
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def test_the_memory_estimate_of_a_map_counts_its_layout():
    from radarbench.models.rd_map import LAYOUT_BYTES_PER_CELL
    S = registry.get_scenario("rd-map")
    p = build_params(S.Params, HUGE_MAP)
    assert S().unit_memory_bytes(p, 2) == (48 + LAYOUT_BYTES_PER_CELL) * 4096 * 16384


# ======================================================================= 5: undefined and degenerate numbers
