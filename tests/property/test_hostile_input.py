"""Hostile and broken sweep files.

Hypothesis generates malformed or adversarial sweep files — wrong types, NaN
and infinities, huge grids, negative counts, unknown keys, deep nesting,
non-UTF-8 bytes, invalid TOML, path-like names, huge strings — and drives the
CLI's ``main(argv)`` in-process with each (a subprocess per example would cost
seconds each; a handful of subprocess checks of the real console script
follow). Every one must end with exit code 2 and exactly one line on stderr,
``error: ...``, no traceback, and nothing written at all: no run folder, no
``results.sqlite``, no report, nothing outside ``--out`` either.

Every generated file is invalid by construction: it is a valid base sweep
(checked below) with one to three mutations applied, each of which makes any
sweep invalid on its own.

Every number a method or scenario declares, at its bounds and beyond:
``tests/property/test_param_bounds.py``.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import re
import subprocess
import sys
import tempfile
import tracemalloc
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.cli import main
from radarbench.bench.sweep.config import (
    LARGE_SWEEP_TRIAL_RUNS,
    MAX_CONFIGS,
    MAX_SNR_LEVELS,
    MAX_SWEEP_BYTES,
    NAME_PATTERN,
    TOP_KEYS,
    parse_sweep_text,
)
from conftest import scaled

registry.discover()

BASE = {
    "name": "fuzz",
    "scenario": "cv-turn-cv",
    "trials": 4,
    "seed": 1,
    "snr_db": [0, 5],
    "chunk": 2,
    "scenario_params": {"steps": 120, "onset_step": 60},
    "methods": [{"name": "innovation", "params": {"window": 5}},
                {"name": "cumulant", "params": {"window": 16}, "label": "cumulant-16"}],
    "calibration": {"pfa": 0.05, "mode": "empirical", "h0_trials": 20},
    "record": {"trials": 0},
}


# ------------------------------------------------------------------ a TOML writer for any value

def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else _string(k)


def _string(s: str) -> str:
    # JSON escapes are TOML basic-string escapes; DEL is escaped too (raw it is invalid TOML)
    return json.dumps(s, ensure_ascii=False).replace("\x7f", "\\u007f")


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v > 0 else "-inf") if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return _string(v)
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def toml_text(data: dict) -> str:
    return "".join(f"{_key(k)} = {toml_value(v)}\n" for k, v in data.items())


def copy(data):
    return json.loads(json.dumps(data))


# ------------------------------------------------------------------ mutations, each one invalid on its own

NAN, INF = float("nan"), float("inf")
HUGE = "x" * 100_000
PATH_LIKE = ["../../x", "../x", "..", ".", "/etc/passwd", "a/b", "a\\b", "~", "~root", "C:\\x", "x/..", "./x",
             "\\\\server\\share", "x\x00y", "reports/../../x"]
NOT_INT = ["10", 1.5, NAN, INF, -INF, True, False, [10], {"n": 10}, 1e300]

# top-level fields: values that are always wrong for them
BAD_FIELD_VALUES = {
    "name": [1, 1.5, True, [], {}, "", " x", "x ", "-x", "x\n", "x" * 65, HUGE, "é", "x;rm -rf ~", *PATH_LIKE],
    "description": [1, NAN, True, ["a"], {"a": 1}],
    "scenario": ["nowhere", "", "CV-TURN-CV", "scenarios.cv_turn_cv", "cv_turn_cv.py", "__import__('os')",
                 HUGE, 1, [], {}, True, *PATH_LIKE],
    "trials": [0, -1, -10**9, 10_000_001, 2**63, -2**63, *NOT_INT],
    "seed": [-1, 2**63, 2**64, -2**70, "1", 1.0, NAN, INF, True, [1]],
    "chunk": [0, -5, 1_000_001, 2.5, "x", NAN, True, []],
    "snr_db": [[], "5", True, NAN, INF, [NAN], [INF], [-INF, 0], [0, "5"], [0, 0], [0, [1]], [[0]], {},
               {"start": 0, "stop": 10}, {"start": 0, "step": 1}, {"stop": 10, "step": 1},
               {"start": 0, "stop": 10, "step": 0}, {"start": 0, "stop": 10, "step": -1},
               {"start": 10, "stop": 0, "step": 1}, {"start": 0, "stop": 10, "step": NAN},
               {"start": 0, "stop": INF, "step": 1}, {"start": -INF, "stop": 0, "step": 1},
               {"start": 0, "stop": 10, "step": 1e-9}, {"start": 0, "stop": 1, "step": 5e-324},
               {"start": -1e308, "stop": 1e308, "step": 1}, {"start": -1e308, "stop": 1e308, "step": 1e300},
               {"start": 0, "stop": 10, "step": 1, "extra": 1}, {"start": "0", "stop": 10, "step": 1},
               list(range(MAX_SNR_LEVELS + 1)), [1e6], [-1e300, 0], [0, 1e308]],
    "scenario_params": [1, "x", [], [{}], {"nope": 1}, {"steps": 1.5}, {"steps": "120"}, {"steps": -1},
                        {"steps": 0}, {"steps": NAN}, {"turn_rate_deg_s": NAN}, {"turn_rate_deg_s": INF},
                        {"turn_rate_deg_s": 0.0}, {"dt_s": -1.0}, {"dt_s": 0}, {"onset_step": 10**9},
                        {"steps": []}, {"steps": [[120]]}, {"process_noise": "yes"},
                        {"steps": list(range(100, 100 + MAX_CONFIGS + 1))},
                        {"dt_s": [0.5, 1.0, 2.0] * 11, "speed_m_s": [float(v) for v in range(100, 140)]},
                        {"turn_rate_deg_s": [1.0, 2.0], "turn_rate_deg_s\x00": 1}],
    "methods": [[], {}, "innovation", 1, [[]], [{}], [1], [{"name": 1}], [{"name": ""}], [{"name": "nope"}],
                [{"name": "innovation", "params": 5}], [{"name": "innovation", "color": "red"}],
                [{"name": "innovation"}, {"name": "innovation"}],
                [{"name": n} for n in ("innovation", "innovation ")],
                [{"name": "innovation"}] * (MAX_CONFIGS + 1)],
    "calibration": [1, "x", [], {"pfa": 0}, {"pfa": 0.5}, {"pfa": -0.1}, {"pfa": NAN}, {"pfa": INF},
                    {"pfa": "0.01"}, {"pfa": True}, {"mode": "bogus"}, {"mode": 1}, {"mode": "gumbel"},
                    {"mode": "../x"}, {"h0_trials": 0}, {"h0_trials": 9}, {"h0_trials": -1},
                    {"h0_trials": 10_000_001}, {"h0_trials": 2.5}, {"extra": 1}],
    "record": [1, "x", [], {"trials": -1}, {"trials": 1001}, {"trials": "1"}, {"trials": NAN},
               {"trials": 1.0}, {"extra": 1}],
}

# method entries whose params/labels are wrong (set as methods[0])
BAD_METHOD_ENTRIES = [
    {"name": "innovation", "params": {"window": -2}},
    {"name": "innovation", "params": {"window": 0}},
    {"name": "innovation", "params": {"window": NAN}},
    {"name": "innovation", "params": {"window": INF}},
    {"name": "innovation", "params": {"window": 2.5}},
    {"name": "innovation", "params": {"window": "5"}},
    {"name": "innovation", "params": {"window": True}},
    {"name": "innovation", "params": {"window": []}},
    {"name": "innovation", "params": {"window": [[5]]}},
    {"name": "innovation", "params": {"window": {"a": 5}}},
    {"name": "innovation", "params": {"window": list(range(1, MAX_CONFIGS + 2))}},
    {"name": "innovation", "params": {"windw": 3}},
    {"name": "innovation", "params": {"": 3}},
    {"name": "innovation", "params": {"window\n": 3}},
    {"name": "innovation", "params": {HUGE: 3}},
    {"name": "innovation", "params": {"delta": NAN}},
    {"name": "innovation", "params": {"window": [5, 6]}, "label": "two-configs"},
    {"name": "cumulant", "params": {"normalisation": "../x"}},
    {"name": "cumulant", "params": {"window": [16, 32], "moment": ["centred", "raw"],
                                    "combine": ["sum", "max"] * 200}},
    {"name": "wavelet", "params": {"wavelet": "__import__('os').system('true')"}},
]
BAD_LABELS = ["", " ", "x\n", "\t", "../../x", "a/b", "a\\b", "/abs", "..", "x" * 201, HUGE, "$\\frac{$",
              "a|b", "\x1b[31mred", "-x", "_hidden", 1, True, [], {}]


def _set(data, key, value):
    data[key] = copy(value)
    return data


def tolerant(apply):
    """A mutation that needs a part an earlier mutation replaced is skipped (the earlier one
    already makes the file invalid)."""
    def run(d):
        try:
            return apply(d)
        except (TypeError, KeyError, IndexError, AttributeError):
            return d
    return run


def _bad_field(draw):
    key = draw(st.sampled_from(sorted(BAD_FIELD_VALUES)))
    value = draw(st.sampled_from(BAD_FIELD_VALUES[key]))
    return lambda d: _set(d, key, value), f"{key}={str(value)[:40]!r}"


def _missing_key(draw):
    key = draw(st.sampled_from(["name", "scenario", "snr_db", "methods"]))
    return lambda d: (d.pop(key, None), d)[1], f"missing {key}"


def _unknown_key(draw):
    where = draw(st.sampled_from(["top", "method", "calibration", "record", "snr", "scenario_params"]))
    key = draw(st.one_of(st.sampled_from(["colour", "name ", "Name", "__class__", "../x", "", "\n", "\x00",
                                          "\x1b[2J", HUGE, "methods.name", "import", "eval"]),
                         st.text(min_size=1, max_size=30)))
    value = draw(st.sampled_from([1, "x", True, [1], {"a": 1}]))
    allowed = {"top": TOP_KEYS, "method": {"name", "params", "label"}, "calibration": {"pfa", "mode", "h0_trials"},
               "record": {"trials"}, "snr": {"start", "stop", "step"}, "scenario_params": set()}[where]
    if key in allowed:
        key = key + "~"

    def apply(d):
        if where == "top":
            d[key] = value
        elif where == "method":
            d["methods"][0][key] = value
        elif where == "snr":
            d["snr_db"] = {"start": 0, "stop": 5, "step": 5, key: value}
        elif where == "scenario_params":
            d["scenario_params"]["zz" + key] = value
        else:
            d[where][key] = value
        return d
    return apply, f"unknown key {key[:20]!r} in {where}"


def _bad_method(draw):
    entry = draw(st.sampled_from(BAD_METHOD_ENTRIES))
    return lambda d: _set(d, "methods", [entry]), f"method {entry}"[:80]


def _bad_label(draw):
    label = draw(st.one_of(st.sampled_from(BAD_LABELS),
                           st.text(min_size=1, max_size=20).map(lambda t: t + "/" + t)))

    def apply(d):
        d["methods"][1]["label"] = label
        return d
    return apply, f"label {str(label)[:30]!r}"


def _bad_method_name(draw):
    name = draw(st.one_of(st.sampled_from(PATH_LIKE + ["methods.maneuver.innovation", "innovation.py", "Innovation", HUGE,
                                                        "os.system", "__import__('os')"]),
                          st.text(max_size=30).filter(lambda t: t not in ("innovation", "cumulant", "wavelet"))))

    def apply(d):
        d["methods"][0]["name"] = name
        return d
    return apply, f"method name {name[:30]!r}"


# the [[scenarios]] form (replacing scenario + scenario_params): lists that are always wrong
CV = {"name": "cv-turn-cv", "params": {"steps": 120, "onset_step": 60}}
BAD_SCENARIO_LISTS = [
    [], {}, "cv-turn-cv", [1], [{}], [{"name": 1}], [{"name": "nowhere"}], [{"name": "../cv-turn-cv"}],
    [CV | {"label": "../../x"}], [CV | {"label": "a/b"}], [CV | {"label": "x\n"}], [CV | {"label": ""}],
    [CV | {"label": HUGE}], [CV | {"label": 5}], [CV | {"snr_db": [1e6]}], [CV | {"snr_db": []}],
    [CV | {"snr_db": {"start": 0, "stop": 1, "step": 5e-324}}], [CV | {"trials": 0}], [CV | {"trials": NAN}],
    [CV | {"trials": 10**8}], [CV | {"extra": 1}], [CV | {"params": 5}], [CV | {"params": {"steps": -1}}],
    [CV | {"params": {"steps": [100, 120]}, "label": "one-label"}],
    [CV, CV],                                                   # two configs with the same name
    [CV | {"label": "same"}, CV | {"params": {"steps": 130}, "label": "same"}],
    [CV, {"name": "tbd-grid"}],                                 # no method of the sweep runs on tbd-grid
    [CV, {"name": "tbd-grid", "params": {"ar_coefficients": [-2.0, 1.7, 0.64]}}],   # explosive AR
    [CV, {"name": "glint", "params": {"epsilon": 1.5}}],
    [CV] * (MAX_CONFIGS + 1),
]


def _bad_scenarios(draw):
    entries = draw(st.sampled_from(BAD_SCENARIO_LISTS))

    def apply(d):
        d.pop("scenario", None)
        d.pop("scenario_params", None)
        d["scenarios"] = copy(entries)
        return d
    return apply, f"scenarios {str(entries)[:60]}"


def _both_scenario_forms(draw):
    def apply(d):
        d.setdefault("scenario", "cv-turn-cv")
        d.setdefault("scenarios", [CV])
        return d
    return apply, "scenario and [[scenarios]]"


STRING_PARAMS = [("cumulant", "moment"), ("cumulant", "combine"), ("cumulant", "normalisation"),
                 ("wavelet", "wavelet"), ("wavelet", "coefficients"), ("wavelet", "mode")]


def _bad_string_param(draw):
    """Free text where a method expects one of a few words (a wavelet name, a choice)."""
    method, key = draw(st.sampled_from(STRING_PARAMS))
    text = draw(st.one_of(st.text(max_size=40), st.sampled_from(["db999999", "sym0", "bior1.1", "cmor1.5-1.0",
                                                                  "gaus1", "haar\x00", "HAAR", "../haar"])))
    valid = re.fullmatch(r"|haar|(db|sym|coif)\d+|centred|raw|sum|max|consistent|paper|approximation|detail|both"
                         r"|decimated|sliding", text)
    text = "zz" + text if valid else text
    return lambda d: _set(d, "methods", [{"name": method, "params": {key: text}}]), f"{method}.{key}={text!r}"


def _bad_name(draw):
    name = draw(st.text(max_size=80).filter(lambda t: not re.fullmatch(NAME_PATTERN.pattern.rstrip("$"), t)))
    return lambda d: _set(d, "name", name), f"name {name[:30]!r}"


def _deep(draw):
    depth = draw(st.sampled_from([2, 50, 200, 400, 2_000, 20_000]))
    where = draw(st.sampled_from(["window", "snr_db", "scenario_params", "unknown"]))
    nested: object = 5
    for _ in range(min(depth, 400)):            # deeper ones are spliced in as text below
        nested = [nested]

    def apply(d):
        if where == "window":
            d["methods"][0]["params"]["window"] = nested
        elif where == "snr_db":
            d["snr_db"] = [0, nested]
        elif where == "scenario_params":
            d["scenario_params"]["steps"] = nested
        else:
            d["deep"] = nested
        return d
    return apply, f"nested {depth} in {where}", depth


def _large_sweep(draw):
    """Above LARGE_SWEEP_TRIAL_RUNS: refused without --yes (which the fuzzer never gives)."""
    trials = draw(st.sampled_from([10_000_000, 5_000_000]))
    levels = draw(st.integers(min_value=LARGE_SWEEP_TRIAL_RUNS // trials + 1, max_value=MAX_SNR_LEVELS))

    def apply(d):
        d["trials"] = trials
        d["snr_db"] = {"start": 0, "stop": levels - 1, "step": 1}
        d["methods"] = d["methods"][:1]
        return d
    return apply, f"large sweep {trials} x {levels}"


@st.composite
def hostile_sweep(draw) -> tuple[bytes, str]:
    """(file bytes, what was done)."""
    data = copy(BASE)
    notes = []
    deep_text = None
    for _ in range(draw(st.integers(min_value=1, max_value=3))):
        kind = draw(st.sampled_from([_bad_field, _bad_field, _missing_key, _unknown_key, _bad_method, _bad_label,
                                     _bad_method_name, _bad_name, _bad_string_param, _deep, _large_sweep,
                                     _bad_scenarios, _both_scenario_forms]))
        made = kind(draw)
        if kind is _deep and made[2] > 400:     # too deep for a Python-built value: write it as text
            deep_text = "deep = " + "[" * made[2] + "5" + "]" * made[2] + "\n"
            notes.append(made[1])
            continue
        data = tolerant(made[0])(data)
        notes.append(made[1])
    text = toml_text(data) + (deep_text or "")
    raw = text.encode("utf-8", "surrogatepass")
    if draw(st.integers(min_value=0, max_value=5)) == 0:       # sometimes, break the bytes too
        raw, note = draw(_byte_damage(raw))
        notes.append(note)
    return raw, "; ".join(notes)


BAD_UTF8 = [b"\xff", b"\xfe\xff", b"\xc3\x28", b"\xe2\x82", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80",
            b"\xc0\xaf", b"\x80"]


@st.composite
def _byte_damage(draw, raw: bytes) -> tuple[bytes, str]:
    kind = draw(st.sampled_from(["utf8", "toml", "toml", "nul"]))
    if kind == "utf8":
        at = draw(st.integers(min_value=0, max_value=len(raw)))
        bad = draw(st.sampled_from(BAD_UTF8))
        return raw[:at] + bad + raw[at:], f"bytes {bad!r} at {at}"
    if kind == "nul":
        at = draw(st.integers(min_value=0, max_value=len(raw)))
        return raw[:at] + b"\x00" + raw[at:], f"NUL at {at}"
    tail = draw(st.sampled_from([b"x = [", b'x = "open', b"= 1", b"[[methods]\n", b"name = 'dup'\n",
                                 b"[calibration]\n", b"x = 1 2\n", b"x = {a = 1,}\n", b"methods = 1\n",
                                 b"[x]\n[x]\n", b"\x7f = 1\n", b"x = 0x\n", b"x = 1979-13-45\n"]))
    return raw + b"\n" + tail, f"TOML tail {tail!r}"


# ------------------------------------------------------------------ the checks

def _tree(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def run_in_process(raw: bytes, *, default_out: bool = False, extra=()) -> tuple[int, str, str, set[str]]:
    """main(["run", ...]) in a fresh folder; (exit code, stdout, stderr, files there afterwards but the sweep)."""
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        sweep = root / "sweep.toml"
        sweep.write_bytes(raw)
        argv = ["run", str(sweep), "--quiet", "--workers", "1", "--no-record", *extra]
        if not default_out:
            argv += ["--out", str(root / "out")]
        out, err = io.StringIO(), io.StringIO()
        with contextlib.chdir(root), contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(argv)
            except SystemExit as exc:          # argparse --help and the like; never expected here
                code = exc.code
        return code, out.getvalue(), err.getvalue(), _tree(root) - {"sweep.toml"}


def assert_rejected(code, out, err, written, what=""):
    lines = err.splitlines()
    assert code == 2, (what, code, err[-2000:])
    assert len(lines) == 1 and lines[0].startswith("error: "), (what, err[:2000])
    assert "Traceback" not in err, what
    assert len(lines[0]) <= 600, (what, len(lines[0]))
    assert out == "", (what, out[:500])
    assert not written, (what, sorted(written)[:10])     # no run folder, no results.sqlite, no report


def test_the_base_sweep_is_valid():
    """The mutations are what makes the generated files invalid."""
    plan = parse_sweep_text(toml_text(BASE).encode(), "base.toml")
    assert [m.label for m in plan.methods] == ["innovation[window=5]", "cumulant-16"]


@pytest.mark.slow                     # fuzzing: 300 generated files
@settings(max_examples=300, derandomize=True, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.large_base_example])
@given(case=hostile_sweep(), default_out=st.booleans())
def test_hostile_sweeps_are_rejected_with_one_line_and_write_nothing(case, default_out):
    raw, what = case
    assert_rejected(*run_in_process(raw, default_out=default_out), what=what)


@pytest.mark.parametrize("raw, field", [
    (b"", "name: missing"),
    (b"\xef\xbb\xbf", "name: missing"),                   # a byte-order mark alone: an empty file
    (b"\xef\xbb\xbf\xef\xbb\xbf", "invalid TOML"),
    (b"\x00" * 100, "invalid TOML"),
    (b"x = " + b"[" * 100_000 + b"]" * 100_000, "invalid TOML"),
    (b"x = " + b"{a = " * 5_000 + b"1" + b"}" * 5_000, "invalid TOML"),
    (b"a" + b".a" * 2_000 + b" = 1", "unknown key"),    # dotted keys nest tables without recursion
    (b'name = "' + b"x" * 2_000_000 + b'"', "bytes; a sweep file is at most"),
], ids=["empty", "bom", "two-boms", "nul", "deep-array", "deep-table", "deep-dotted-key", "2MB"])
def test_degenerate_files(raw, field):
    code, out, err, written = run_in_process(raw)
    assert_rejected(code, out, err, written, field)
    assert field in err, err


def test_a_huge_grid_axis_is_rejected_quickly_without_allocating_it():
    """A 10^7-element list would take seconds and gigabytes to parse; the file size alone stops it."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "huge.toml"
        with path.open("wb") as f:
            f.write(toml_text({k: v for k, v in BASE.items() if k != "methods"}).encode())
            f.write(b'methods = [{name = "innovation", params = {window = [')
            for _ in range(100):
                f.write(b"5," * 100_000)
            f.write(b"5]}}]\n")
        assert path.stat().st_size > 10 * MAX_SWEEP_BYTES
        err = io.StringIO()
        tracemalloc.start()
        try:
            with contextlib.redirect_stderr(err):
                code = main(["run", str(path), "--out", str(Path(tmp) / "out"), "--quiet"])
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert code == 2 and "at most" in err.getvalue(), err.getvalue()
        assert peak < 4 * MAX_SWEEP_BYTES + 20e6, peak          # never the 20 MB file, let alone its parse
        assert not (Path(tmp) / "out").exists()


@pytest.mark.parametrize("snr", [
    {"start": 0, "stop": 1e6, "step": 1e-6},                  # 10^12 levels
    {"start": -1e308, "stop": 1e308, "step": 5e-324},          # the level count overflows a float
    {"start": 0, "stop": 1, "step": 5e-324},
])
def test_huge_snr_ranges_are_counted_not_built(snr):
    data = copy(BASE) | {"snr_db": snr}
    code, out, err, written = run_in_process(toml_text(data).encode())
    assert_rejected(code, out, err, written)
    assert "snr_db" in err


def test_a_sweep_above_the_bound_needs_yes():
    data = copy(BASE) | {"trials": 10_000_000, "snr_db": {"start": 0, "stop": 9, "step": 1}}
    data["methods"] = data["methods"][:1]
    raw = toml_text(data).encode()
    code, out, err, written = run_in_process(raw)
    assert_rejected(code, out, err, written)
    assert "--yes" in err
    plan = parse_sweep_text(raw, "big.toml", allow_large=True)      # with --yes it would run
    assert plan.trial_runs == 10 * 10_000_000


def test_calibration_trials_count_towards_the_bound():
    data = copy(BASE) | {"calibration": {"h0_trials": 10_000_000},
                         "methods": [{"name": "innovation", "params": {"window": list(range(1, 11))}}]}
    code, out, err, written = run_in_process(toml_text(data).encode())
    assert_rejected(code, out, err, written)
    assert "--yes" in err


def test_sweep_files_never_execute_code():
    """TOML only: no eval/exec, no pickle, no YAML anywhere in the harness; hostile strings stay data."""
    from radarbench import bench
    forbidden = re.compile(r"\b(eval|exec)\s*\(|^\s*(import|from)\s+(pickle|cloudpickle|dill|marshal|shelve|yaml)\b"
                           r"|allow_pickle\s*=\s*True|pd\.read_pickle|__import__\s*\(", re.MULTILINE)
    for path in Path(bench.__file__).parent.glob("*.py"):
        source = path.read_text(encoding="utf-8")
        hits = forbidden.findall(source)
        if path.name == "figures.py":
            # the report's figure pool: a Figure pickled in the driver, in its own thread (the
            # pool's feeder thread would pickle it while the driver closes it), and unpickled
            # by the pool's process; never a file, nothing a sweep file can reach
            assert re.findall(r"pickle\.\w+\(\w*\)", source) == ["pickle.loads(data)", "pickle.dumps(fig)"], source
            hits.remove(("", "import", "pickle"))
        if path.name == "numba_cache.py":
            # numba's on-disk cache is pickles by numba's design (its own loader unpickles the
            # same files from the same folder); this module only adds checksums around them
            assert {m for m in re.findall(r"pickle\.(\w+)\(", source)} == {"load", "loads", "dumps"}, source
            hits.remove(("", "import", "pickle"))
        assert not hits, (path.name, hits)
    with tempfile.TemporaryDirectory() as tmp:
        marker = Path(tmp) / "pwned"
        payload = f"__import__('os').system('touch {marker}')"
        for field, value in [("name", payload), ("scenario", payload), ("description", 1)]:
            data = copy(BASE) | {field: value}
            assert_rejected(*run_in_process(toml_text(data).encode()), what=field)
        data = copy(BASE)
        data["methods"][0] = {"name": payload}
        assert_rejected(*run_in_process(toml_text(data).encode()))
        assert not marker.exists()


# ------------------------------------------------------------------ the real console script

CONSOLE_CASES = [
    (b"\xff\xfename = 1", "not UTF-8"),
    (b"x = " + b"[" * 50_000, "invalid TOML"),
    (toml_text(copy(BASE) | {"name": "../../x"}).encode(), "name"),
    (toml_text(copy(BASE) | {"methods": [{"name": "innovation", "params": {"window": list(range(1, 2002))}}]}
               ).encode(), "methods[0].params"),
    (toml_text(copy(BASE) | {"snr_db": {"start": 0, "stop": 1, "step": 5e-324}}).encode(), "snr_db"),
]


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
def test_the_console_script_rejects_hostile_files_the_same_way(tmp_path):
    """The installed ``bench`` script (all at once: each start costs seconds)."""
    exe = Path(sys.executable).with_name("bench")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-m", "radarbench.bench"]
    procs = []
    for i, (raw, field) in enumerate(CONSOLE_CASES):
        root = tmp_path / str(i)
        root.mkdir()
        (root / "sweep.toml").write_bytes(raw)
        procs.append((root, field, subprocess.Popen([*cmd, "run", "sweep.toml", "--quiet"], cwd=root, text=True,
                                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE)))
    for root, field, proc in procs:
        out, err = proc.communicate(timeout=scaled())
        lines = err.splitlines()
        assert proc.returncode == 2, (field, err[-2000:])
        assert len(lines) == 1 and lines[0].startswith("error: sweep.toml: ") and field in lines[0], err
        assert out == "" and _tree(root) == {"sweep.toml"}, _tree(root)
