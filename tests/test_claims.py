"""Claims as code (bench/report/claims.py; docs/architecture.md, 'Report').

(a) a claims file is validated at load: one line naming the file and the field;
(b) each quantity kind and verdict rule on small hand-built tables (the rule's every branch
    on synthetic intervals: tests/test_claims_verdicts.py);
(c) every committed report with a claims file and a committed claims.csv gets the same
    claims.csv again from its committed CSVs;
(d) no preset note and no claim reason types a number the run produces.
"""

from __future__ import annotations

import importlib.resources
import math
import re
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.report import claims
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.listing import CLAIMS_SUFFIX, presets
from radarbench.bench.markdown import fmt, fmt_db

ROOT = Path(__file__).resolve().parents[1]
PRESETS_DIR = importlib.resources.files("radarbench.bench") / "presets"
CLAIM_FILES = sorted(p.name[:-len(CLAIMS_SUFFIX)] for p in PRESETS_DIR.iterdir() if p.name.endswith(CLAIMS_SUFFIX))

GOOD = """
paper = "A paper"

[[claim]]
id = "a-beats-b"
claim = "a beats b"
where = "Fig. 3"
quantity = { kind = "paired", a = "b", b = "a", snr_db = "all" }
expect = "positive"
"""


def _parse(text: str) -> claims.ClaimsFile:
    return claims.parse(textwrap.dedent(text), "x.claims.toml")


# ------------------------------------------------------------------ (a) validation

@pytest.mark.parametrize("change, field, words", [
    (("expect = \"positive\"", "expect = \"up\""), "claim[0].expect", "expected one of"),
    (("kind = \"paired\"", "kind = \"pairs\""), "claim[0].quantity.kind", "expected one of"),
    (("where = \"Fig. 3\"\n", ""), "claim[0].where", "missing"),
    (("claim = \"a beats b\"", "claim = \"a beats b\"\nwhen = 3"), "claim[0].when", "unknown key"),
    (("snr_db = \"all\"", "snr_db = \"all\", colour = 1"), "claim[0].quantity.colour", "unknown key"),
    ((", snr_db = \"all\"", ""), "claim[0].quantity.snr_db", "missing"),
    (("snr_db = \"all\"", "snr_db = \"some\""), "claim[0].quantity.snr_db", "finite number"),
    (("id = \"a-beats-b\"", "id = \"A beats\""), "claim[0].id", "kebab-case"),
    (("expect = \"positive\"", "expect = \"value\""), "claim[0].value", "missing"),
    (("expect = \"positive\"", "expect = \"not-comparable\""), "claim[0].reason", "missing"),
    (("expect = \"positive\"", "expect = \"conversion\"\nreason = \" \""), "claim[0].reason", "non-empty"),
    (("paper = \"A paper\"", "paper = \"\""), "paper", "non-empty"),
    (("paper = \"A paper\"", "paper = \"A paper\"\nauthors = 2"), "authors", "unknown key"),
    (("expect = \"positive\"", "expect = \"positive\"\nminimal_effect = -0.1"), "claim[0].minimal_effect", "size >= 0"),
    (("expect = \"positive\"", "expect = \"positive\"\nminimal_effect = \"big\""), "claim[0].minimal_effect",
     "finite number"),
    (("expect = \"positive\"", "expect = \"value\"\nvalue = 1\nminimal_effect = 0.1"), "claim[0].minimal_effect",
     "only for expect = 'positive' or 'negative'"),
    (("expect = \"positive\"", "expect = \"positive\"\ntolerance = 0.1"), "claim[0].tolerance", "only for expect = 'value'"),
    (("expect = \"positive\"", "expect = \"value\"\nvalue = 1\ntolerance = -1"), "claim[0].tolerance", "size >= 0"),
])
def test_a_bad_claims_file_is_one_line_naming_the_file_and_the_field(change, field, words):
    assert GOOD.count(change[0]) == 1
    with pytest.raises(ConfigError) as err:
        _parse(GOOD.replace(*change))
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"x.claims.toml: {field}: ") and words in message


def test_the_sizes_load_into_the_claim():
    c = _parse(GOOD.replace('expect = "positive"', 'expect = "positive"\nminimal_effect = 1.5')).claims[0]
    assert (c.minimal_effect, c.tolerance) == (1.5, 0.0)
    assert _parse(GOOD).claims[0].minimal_effect == 0.0


def test_repeated_ids_names_and_bad_toml_are_refused():
    with pytest.raises(ConfigError, match=r"^x.claims.toml: claim\[1\].id: repeated id 'a-beats-b'$"):
        _parse(GOOD + GOOD.split("\n", 2)[2])
    also = "[claim.also]\nx = { kind = \"calibration\", config = \"a\", column = \"used\" }\n"
    with pytest.raises(ConfigError, match=r"^x.claims.toml: claim\[1\].also.x: repeated name"):
        _parse(GOOD + also + GOOD.split("\n", 2)[2].replace("a-beats-b", "again") + also)
    with pytest.raises(ConfigError, match=r"^x.claims.toml: not valid TOML"):
        _parse("paper = ")


@pytest.mark.parametrize("name", CLAIM_FILES)
def test_every_packaged_claims_file_loads_beside_its_preset(name):
    assert name in presets()                 # a claims file belongs to a preset; it is not one itself
    assert claims.preset_claims(name).claims


def _named(q: dict) -> tuple[set[str], set[str]]:
    """(method configs, scenario configs) a quantity names, inline quantities included."""
    configs, scenarios = set(), set()
    for key, value in q.items():
        if isinstance(value, dict):
            c, s = _named(value)
            configs, scenarios = configs | c, scenarios | s
        elif key in ("config", "a", "b"):
            configs.add(value)
        elif key.startswith("scenario"):
            scenarios.add(value)
    return configs, scenarios


@pytest.mark.parametrize("name", CLAIM_FILES)
def test_every_config_a_claim_names_is_in_its_presets_sweep(name):
    """A misspelt label or level would read as "did not run" (not comparable): only an
    optional method unavailable here may be absent from a run."""
    from tests.conftest import parse_sweep_or_skip
    plan = parse_sweep_or_skip(tomllib.loads(presets()[name].read_text(encoding="utf-8")), f"preset {name}")
    known = {m.label for m in plan.methods}
    optional = [entry.get("label", entry["name"]) for entry, _ in plan.skipped_methods]
    scenarios = {sc.label for sc in plan.scenarios}
    for c in claims.preset_claims(name).claims:
        for q in [c.quantity, *c.also.values()]:
            configs, named_scenarios = _named(q) if q else (set(), set())
            unknown = {x for x in configs - known if not any(x == o or x.startswith(f"{o}[") for o in optional)}
            assert not unknown and named_scenarios <= scenarios, (c.id, unknown, named_scenarios - scenarios)
            absent = {level for level in (_levels(q) if q else set())
                      if not any(np.isclose(level, s) for sc in plan.scenarios for s in sc.snr_db)}
            assert not absent, (c.id, "SNR levels the preset does not run", absent)


def _levels(q: dict) -> set[float]:
    """The SNR levels (dB) a quantity names, inline quantities included ("all" is none)."""
    levels = set()
    for key, value in q.items():
        if isinstance(value, dict):
            levels |= _levels(value)
        elif key == "snr_db" and isinstance(value, (int, float)):
            levels.add(float(value))
    return levels


# ------------------------------------------------------------------ (b) quantities and verdicts

def _summary(config: str, pd_values, snr=None, n=100, **extra) -> pd.DataFrame:
    snr = np.arange(len(pd_values), dtype=float) if snr is None else np.asarray(snr, float)
    pd_values = np.asarray(pd_values, float)
    return pd.DataFrame({"scenario": "s", "method": config.split("[")[0], "config": config, "snr_db": snr,
                         "n_trials": n, "pd": pd_values, "pd_low": pd_values - 0.05, "pd_high": pd_values + 0.05,
                         **extra})


def _tables(summary=None, comparisons=None, calibration=None) -> claims.Tables:
    empty = pd.DataFrame()
    return claims.Tables(summary if summary is not None else empty, comparisons if comparisons is not None else empty,
                         calibration if calibration is not None else empty, 0.05)


def _comparison(a, b, diff, low, high, p=np.nan, snr=np.nan, n=100) -> dict:
    return {"scenario": "s", "task": "maneuver-detection", "metric": "detected", "snr_db": snr, "config_a": a,
            "config_b": b, "n_pairs": n, "difference": diff, "difference_low": low, "difference_high": high,
            "mcnemar_p": p}


def _claim(quantity: dict, **keys) -> claims.Claim:
    return claims.Claim(id="c", claim="c", where="w", quantity=quantity, **{"expect": "positive", **keys})


def _verdict(claim: claims.Claim, tables: claims.Tables) -> claims.Result:
    file = claims.ClaimsFile("x.claims.toml", "P", (claim,))
    return claims.evaluate(file, tables).claims["c"]


PAIRED = {"kind": "paired", "a": "x", "b": "y", "snr_db": "all"}


@pytest.mark.parametrize("row, expect, word, reason", [
    ((0.1, 0.05, 0.15), "positive", "reproduces", ""),
    ((0.1, -0.01, 0.15), "positive", "not resolved",            # n · (0.11 / 0.1)² = 121, rounded up
     "~130 trials per level (this run: 100) would resolve it, as “reproduces” if the estimate holds"),
    ((-0.1, -0.15, -0.05), "positive", "does not reproduce", "the opposite sign"),
    ((-0.1, -0.15, -0.05), "negative", "reproduces", ""),
    ((0.0, 0.0, 0.0), "negative", "does not reproduce", "none in the claimed direction: the interval reaches 0 at most"),
])
def test_sign_rules_read_the_interval(row, expect, word, reason):
    comparisons = pd.DataFrame([_comparison("x", "y", *row, p=0.01)])
    r = _verdict(_claim(PAIRED, expect=expect), _tables(comparisons=comparisons))
    assert (r.verdict, r.reason) == (word, reason)
    assert (r.value, r.low, r.high, r.p) == (*row, 0.01)


def test_a_paired_quantity_is_oriented_as_b_minus_a_whichever_order_the_table_holds():
    comparisons = pd.DataFrame([_comparison("y", "x", 0.1, 0.05, 0.15)])      # the table holds x − y
    r = _verdict(_claim(PAIRED, expect="negative"), _tables(comparisons=comparisons))
    assert (r.value, r.low, r.high, r.verdict) == (-0.1, -0.15, -0.05, "reproduces")


def test_a_paired_quantity_at_one_level():
    comparisons = pd.DataFrame([_comparison("x", "y", 0.1, 0.05, 0.15),
                                _comparison("x", "y", -0.2, -0.3, -0.1, snr=5.0)])
    r = _verdict(_claim({**PAIRED, "snr_db": 5.0}, expect="negative"), _tables(comparisons=comparisons))
    assert (r.value, r.verdict) == (-0.2, "reproduces")


@pytest.mark.parametrize("paper, tolerance, word", [(0.5, 0.0, "not resolved"), (0.5, 0.05, "reproduces"),
                                                   (0.3, 0.0, "does not reproduce"), (0.3, 0.16, "not resolved"),
                                                   (0.3, 0.26, "reproduces"), (0.8, 0.0, "does not reproduce")])
def test_value_rule_needs_the_interval_within_the_tolerance(paper, tolerance, word):
    summary = _summary("x", [0.2, 0.5, 0.9])                 # pd 0.5 [0.45, 0.55] at 1 dB
    claim = _claim({"kind": "summary", "config": "x", "snr_db": 1, "column": "pd"}, expect="value", value=paper,
                   tolerance=tolerance)
    r = _verdict(claim, _tables(summary=summary))
    assert r.verdict == word and (word == "reproduces") == (r.reason == "")


@pytest.mark.parametrize("lo, hi, word", [(0.4, 0.6, "reproduces"), (0.46, 0.6, "not resolved"),
                                          (0.56, 0.9, "does not reproduce")])
def test_between_rule_needs_the_whole_interval_inside(lo, hi, word):
    claim = _claim({"kind": "summary", "config": "x", "snr_db": 1, "column": "pd"}, expect="between", min=lo, max=hi)
    assert _verdict(claim, _tables(summary=_summary("x", [0.2, 0.5, 0.9]))).verdict == word


def test_between_rule_reads_the_value_alone_without_an_interval():
    summary = _summary("x", [0.2, 0.5, 0.9], delay_mean=[np.nan, 4.0, 3.0])   # no delay_low/high columns
    claim = _claim({"kind": "summary", "config": "x", "snr_db": 2, "column": "delay_mean"}, expect="between",
                   min=2.5, max=3.5)
    r = _verdict(claim, _tables(summary=summary))
    assert (r.value, math.isnan(r.low), r.verdict) == (3.0, True, "reproduces")


def test_not_comparable_and_conversion_keep_their_quantity_and_reason():
    summary = _summary("x", [0.2, 0.5, 0.9])
    q = {"kind": "summary", "config": "x", "snr_db": 1, "column": "pd"}
    r = _verdict(_claim(q, expect="not-comparable", reason="the paper gives {{ 'no' }} axis"), _tables(summary))
    assert (r.verdict, r.reason, r.value) == ("not comparable", "the paper gives no axis", 0.5)
    r = _verdict(_claim(q, expect="conversion", reason="ours at {{ text }}"), _tables(summary))
    assert (r.verdict, r.reason) == ("conversion", "ours at 0.5 [0.45, 0.55]")


def test_a_config_that_did_not_run_makes_the_claim_not_comparable():
    r = _verdict(_claim({"kind": "summary", "config": "peer", "snr_db": 1, "column": "pd"}, reason="{{ 1/0 }}"),
                 _tables(summary=_summary("x", [0.2, 0.5, 0.9])))
    assert (r.verdict, r.reason) == ("not comparable", "`peer` did not run")



def test_a_level_that_did_not_run_makes_the_claim_not_comparable():
    """A run narrowed by ``--snr`` (was: exit 2, "no level -5 dB", after every unit had run)."""
    r = _verdict(_claim({"kind": "summary", "config": "x", "snr_db": -5, "column": "pd"}),
                 _tables(summary=_summary("x", [0.2, 0.5, 0.9])))
    assert (r.verdict, r.reason) == ("not comparable", "`x` at -5.0 dB (levels run: 0.0, 1.0, 2.0 dB) did not run")
    comparisons = pd.DataFrame({"scenario": "s", "task": "t", "metric": "pd", "config_a": ["x"], "config_b": ["y"],
                                "snr_db": [0.0], "difference": 0.1, "difference_low": 0.05, "difference_high": 0.15,
                                "mcnemar_p": 0.01, "n_pairs": 100})
    r = _verdict(_claim({**PAIRED, "snr_db": -5, "metric": "pd"}), _tables(comparisons=comparisons))
    assert (r.verdict, r.reason) == ("not comparable", "the level -5.0 dB did not run")


def test_a_reason_reading_a_quantity_that_did_not_run_says_so():
    summary = _summary("x", [0.2, 0.5, 0.9])
    claim = _claim({"kind": "summary", "config": "x", "snr_db": 1, "column": "pd"}, expect="between", min=0.4,
                   max=0.6, reason="low: {{ q.low.value }}",
                   also={"low": {"kind": "summary", "config": "x", "snr_db": -5, "column": "pd"}})
    r = _verdict(claim, _tables(summary=summary))
    assert (r.verdict, r.reason) == ("reproduces", "`x` at -5.0 dB (levels run: 0.0, 1.0, 2.0 dB) did not run")

def test_crossing_is_the_reports_probit_and_a_difference_is_conservative():
    from radarbench.bench.markdown import snr50
    snr = np.arange(-10.0, 11.0, 2.0)
    a = _summary("a", 1 / (1 + np.exp(-(snr + 3))), snr=snr)
    b = _summary("b", 1 / (1 + np.exp(-(snr - 2))), snr=snr)
    summary = pd.concat([a, b], ignore_index=True)
    ca, cb = (snr50(summary[summary.config == c]).crossing.iloc[0] for c in "ab")
    r = _verdict(_claim({"kind": "crossing_difference", "a": "a", "b": "b"}, expect="negative", unit="dB"),
                 _tables(summary=summary))
    assert (r.value, r.low, r.high) == (ca.mid - cb.mid, ca.low - cb.high, ca.high - cb.low)
    assert r.verdict == "reproduces" and r.text.endswith(" dB")
    one = _verdict(_claim({"kind": "crossing", "config": "a", "level": 0.5}, expect="value", value=-3.0,
                          tolerance=1.0, unit="dB"), _tables(summary=summary))
    assert one.value == ca.mid and -4 < ca.low < ca.high < -2 and one.verdict == "reproduces"


def test_each_quantity_carries_the_trials_behind_its_interval():
    """n per level: summary.csv's n_trials, comparisons.csv's per-level n_pairs (over all
    levels too), the plan's h0_trials for a calibration value; a difference the larger of
    its two; per-level and null trials do not mix."""
    summary = pd.concat([_summary("x", [0.2, 0.5, 0.9], n=100), _summary("y", [0.1, 0.4, 0.8], n=250)])
    comparisons = pd.DataFrame([_comparison("x", "y", 0.1, 0.05, 0.15, n=300),
                                _comparison("x", "y", 0.1, 0.05, 0.15, n=100, snr=0.0),
                                _comparison("x", "y", 0.1, 0.05, 0.15, n=200, snr=1.0)])
    calibration = pd.DataFrame({"scenario": ["s"], "method": ["x"], "used_pfa": [0.01], "used_pfa_low": [0.005],
                                "used_pfa_high": [0.02]})
    tables = claims.Tables(summary, comparisons, calibration, 0.05, h0_trials=1000.0)
    pd_at = (lambda c, s: {"kind": "summary", "config": c, "snr_db": s, "column": "pd"})
    cal = {"kind": "calibration", "config": "x", "column": "used_pfa"}
    for q, n, null in [(pd_at("x", 1), 100, False), (PAIRED, 200, False), ({**PAIRED, "snr_db": 0.0}, 100, False),
                       ({"kind": "crossing", "config": "y"}, 250, False), (cal, 1000, True),
                       ({"kind": "difference", "a": pd_at("x", 1), "b": pd_at("y", 1)}, 250, False),
                       ({"kind": "ratio", "a": pd_at("x", 2), "b": pd_at("y", 1), "scale": 100}, 250, False),
                       ({"kind": "difference", "a": cal, "b": cal}, 1000, True)]:
        v = claims.quantity(q, tables)
        assert (v.n, v.null) == (n, null), q
    assert math.isnan(claims.quantity({"kind": "difference", "a": cal, "b": pd_at("x", 1)}, tables).n)
    assert math.isnan(claims.quantity(cal, _tables(calibration=calibration)).n)      # a plan without h0_trials


def test_a_crossing_above_the_swept_range_is_an_open_interval():
    summary = _summary("a", [0.0, 0.01, 0.02], snr=[0.0, 1.0, 2.0])
    r = _verdict(_claim({"kind": "crossing", "config": "a"}, expect="between", min=1.0, max=100.0, unit="dB"),
                 _tables(summary=summary))
    assert math.isnan(r.value) and math.isinf(r.high) and r.text.startswith("> ")
    assert r.verdict == "not resolved" and "more levels" in r.reason      # [2, inf) overlaps [1, 100]


def test_the_crossing_of_pd_has_the_configs_chance_pd_as_floor():
    snr = np.arange(-10.0, 11.0, 2.0)
    summary = _summary("a", 0.3 + 0.7 / (1 + np.exp(-snr)), snr=snr)
    calibration = pd.DataFrame({"scenario": ["s"], "method": ["a"], "chance_pd": [0.3]})
    floored = _verdict(_claim({"kind": "crossing", "config": "a"}), _tables(summary, None, calibration)).value
    bare = _verdict(_claim({"kind": "crossing", "config": "a"}), _tables(summary)).value
    assert floored > bare + 0.5          # without the floor the curve starts nearer 0.5


def test_difference_ratio_and_scale():
    summary = _summary("x", [0.2, 0.5, 0.9])
    pd_at = (lambda s: {"kind": "summary", "config": "x", "snr_db": s, "column": "pd"})
    r = _verdict(_claim({"kind": "difference", "a": pd_at(2), "b": pd_at(1)}), _tables(summary))
    assert np.allclose([r.value, r.low, r.high], [0.4, 0.3, 0.5])
    r = _verdict(_claim({"kind": "ratio", "a": pd_at(2), "b": pd_at(1), "scale": 100}, unit="%", expect="between",
                        min=150, max=250), _tables(summary))
    assert np.allclose([r.value, r.low, r.high], [180, 85 / 0.55, 95 / 0.45]) and r.verdict == "reproduces"
    gain = {"kind": "difference", "a": pd_at(1), "b": pd_at(0)}            # 0.3 [0.2, 0.4]
    loss = {"kind": "difference", "a": pd_at(0), "b": pd_at(1)}            # -0.3 [-0.4, -0.2]
    r = _verdict(_claim({"kind": "ratio", "a": loss, "b": gain}), _tables(summary))
    assert np.allclose([r.value, r.low, r.high], [-1, -0.4 / 0.2, -0.2 / 0.4])   # a negative numerator's ends
    r = _verdict(_claim({"kind": "ratio", "a": gain, "b": loss}), _tables(summary))
    assert r.value == -1 and np.isnan(r.low) and np.isnan(r.high)         # no bound where b may be <= 0


def test_templates_read_every_claim_and_named_quantity():
    text = GOOD + """
    [[claim]]
    id = "second"
    claim = "another"
    where = "eq. 11"
    quantity = { kind = "calibration", config = "x", column = "chance_pd" }
    expect = "between"
    min = 0.0
    max = 0.1
    reason = "first {{ claims['a-beats-b'].verdict }}, chance {{ value | pct }}, ours {{ q.thr.text }}"
    [claim.also]
    thr = { kind = "calibration", config = "x", column = "used" }
    """
    file = claims.parse(textwrap.dedent(text), "x.claims.toml")
    calibration = pd.DataFrame({"scenario": ["s"], "method": ["x"], "chance_pd": [0.0475], "used": [12.3456]})
    comparisons = pd.DataFrame([_comparison("b", "a", 0.1, 0.05, 0.15)])
    evaluation = claims.evaluate(file, _tables(None, comparisons, calibration))
    assert evaluation.claims["second"].reason == "first reproduces, chance 4.75%, ours 12.3"
    notes = "{% if claims['a-beats-b'].tie %}tie{% else %}lead {{ claims['a-beats-b'].value | fmt }}{% endif %}"
    section = claims.claims_markdown(evaluation, notes)
    assert section.startswith("## Paper vs ours (A paper)") and section.endswith("lead 0.1")
    assert "| a beats b | Fig. 3 | 0.1 [0.05, 0.15] | **reproduces** | |" in re.sub(r" +", " ", section)
    with pytest.raises(ConfigError, match=r"^x.claims.toml: claim\[1\].reason: template error"):
        claims.evaluate(claims.parse(textwrap.dedent(text).replace("q.thr", "q.nothing"), "x.claims.toml"),
                        _tables(None, comparisons, calibration))


def test_claims_csv_has_the_schemas_columns():
    comparisons = pd.DataFrame([_comparison("b", "a", 0.1, 0.05, 0.15)])
    frame = claims.evaluate(_parse(GOOD), _tables(comparisons=comparisons)).frame()
    assert list(frame.columns) == claims.CLAIMS_COLUMNS
    assert frame.loc[0, "quantity"] == "paired(a=b, b=a, snr_db=all)" and frame.loc[0, "verdict"] == "reproduces"


def test_bench_report_writes_claims_csv_and_the_table(small_run_copy, monkeypatch):
    """A preset run with a claims file: claims.csv (listed in the manifest) and the table
    where the notes were, the notes rendered after it."""
    from radarbench.bench import report
    from radarbench.bench.results import runfolder
    text = GOOD.replace("A paper", "Small 2026").replace("a-beats-b", "single-step-leads").replace(
        'a = "b", b = "a"', 'a = "innovation[window=1]", b = "innovation[window=5]"')
    monkeypatch.setattr(report, "_preset_name", lambda source: "small")
    monkeypatch.setattr(report.claims, "preset_claims", lambda name: claims.parse(textwrap.dedent(text), "s.toml"))
    monkeypatch.setattr(report, "preset_notes", lambda source: "Notes: {{ claims['single-step-leads'].verdict }}.")
    report.build_outputs(small_run_copy, recording=False)
    written = pd.read_csv(small_run_copy / "claims.csv")
    again = claims.evaluate_folder(small_run_copy, claims.parse(textwrap.dedent(text), "s.toml"))
    assert written.id.tolist() == ["single-step-leads"] and written.verdict[0] == again.verdict[0]
    assert written.value[0] == again.value[0]
    assert "claims.csv" in runfolder.read_manifest(small_run_copy)
    md = (small_run_copy / "report.md").read_text()
    section = md.split("## Paper vs ours (Small 2026)", 1)[1].split("\n## ", 1)[0]
    assert f"Notes: {written.verdict[0]}." in section and "`innovation[window=1]`" not in section


# ------------------------------------------------------------------ (c) committed reports

def _report_folders() -> list[tuple[str, Path]]:
    """(preset, its committed report folder) for every preset with a claims file."""
    out = []
    for plan in sorted((ROOT / "reports").glob("*/plan.toml")):
        name = tomllib.loads(plan.read_text(encoding="utf-8")).get("name", "")
        if name in CLAIM_FILES:
            out.append((name, plan.parent))
    return out


@pytest.mark.parametrize("name, folder", _report_folders(), ids=lambda x: getattr(x, "name", x))
def test_committed_claims_csv_is_regenerated_identical_from_the_committed_csvs(name, folder):
    from radarbench.bench.results.tables import csv_text
    committed = folder / "claims.csv"
    assert committed.exists(), (f"{folder.relative_to(ROOT)} has no committed claims.csv (written when the "
                                f"report is regenerated: bench run --preset {name} --out {folder.relative_to(ROOT)})")
    assert csv_text(claims.evaluate_folder(folder)) == committed.read_text(encoding="utf-8")


def test_the_maneuver_detection_claims_csv_is_committed():
    """At least one committed report is checked by the test above (not all skipped)."""
    assert (ROOT / "reports" / "maneuver-detection" / "claims.csv").exists()


# ------------------------------------------------------------------ (d) no typed numbers

#: a literal number: optional sign (ASCII or Unicode minus), digits, decimals, exponent, percent
_NUMBER = re.compile(r"(?<![\w.])([-−]?\d+(?:\.\d+)?(?:[eE][-−]?\d+)?)(%?)(?![\w])")
#: references into the paper (figures, equations, steps, sections): not results
_REFERENCE = re.compile(r"(?:Figs?\.|eqs?\.|Steps?|§|Table|panels?)\s*[\d–\-, ]*(?:and\s+\d+)?", re.IGNORECASE)


def _prose(template: str) -> str:
    """A template's own text: template fields, code spans and references into the paper removed."""
    text = re.sub(r"\{\{.*?\}\}|\{%.*?%\}|\{#.*?#\}", " ", template, flags=re.S)
    text = re.sub(r"`[^`]*`", " ", text)
    return _REFERENCE.sub(" ", text)


def literals(text: str) -> list[tuple[str, float]]:
    """The literal numbers of a template's prose: (as written, value); "5%" is 0.05.
    Single-digit integers are left out: ordinals and small counts ("χ²(1)", "Step 1"),
    never a measured value at the printed precision."""
    out = []
    for m in _NUMBER.finditer(_prose(text)):
        written = m.group(1).replace("−", "-")
        if re.fullmatch(r"-?\d", written):
            continue
        out.append((m.group(0), float(written) / (100.0 if m.group(2) else 1.0)))
    return out


def _numbers(value) -> list[float]:
    if isinstance(value, dict):
        return [x for v in value.values() for x in _numbers(v)]
    if isinstance(value, list):
        return [x for v in value for x in _numbers(v)]
    return [float(value)] if isinstance(value, (int, float)) and not isinstance(value, bool) else []


def parameters(folder: Path, file: claims.ClaimsFile | None) -> set[str]:
    """Numbers a note may type (as :func:`fmt` prints them): the plan's values (its
    ``[calibration] chance_pd`` default included), the harness's fixed settings (95%
    intervals, the crossing level), and the paper's own printed numbers (the claims'
    ``where``, ``original``, ``english``, ``value``, ``min``, ``max``, ``tolerance``,
    ``minimal_effect``, ``level``)."""
    from radarbench.bench.calibration import EQUAL_CHANCE_PD
    from radarbench.bench.metrics import CONFIDENCE
    plan = tomllib.loads((folder / "plan.toml").read_text(encoding="utf-8"))
    plan.pop("provenance", None)
    values = _numbers(plan) + [plan.get("calibration", {}).get("chance_pd", EQUAL_CHANCE_PD), CONFIDENCE, 0.5]
    for c in (file.claims if file else ()):
        values += [float(w.replace("−", "-")) for w in _NUMBER.findall(f"{c.where} {c.original} {c.english}")
                   for w in [w[0]]]
        values += [x for x in (c.value, c.min, c.max, c.tolerance, c.minimal_effect) if x is not None]
        values += [q["level"] for q in [c.quantity, *c.also.values()] if q and "level" in q]
    return {fmt(v) for v in values}


def run_values(folder: Path, file: claims.ClaimsFile | None) -> tuple[set[str], set[str]]:
    """What the run produced, as the report prints it: (3 significant digits, dB to 0.1).
    Every number of summary/comparisons/calibration.csv (dB columns also to 0.1), every
    claim and named quantity, and every config's SNR at Pd = 0.5 under each Pd column."""
    from radarbench.bench.markdown import crossing_floors, snr50
    tables = claims.read_tables(folder)
    plain, db = set(), set()
    for df in (tables.summary, tables.comparisons, tables.calibration):
        for column in df.select_dtypes("number"):
            values = df[column].dropna().to_numpy(float)
            plain |= {fmt(v) for v in values}
            if column.endswith("_db"):
                db |= {fmt_db(v) for v in values}
    chance = dict(zip(tables.calibration.get("method", []), tables.calibration.get("chance_pd", [])))
    for column in ("pd", "pd_step", "pd_equal_chance"):
        if column in tables.summary and tables.summary[column].notna().any():
            for c in snr50(tables.summary, column, crossing_floors(column, chance, tables.equal_chance)).crossing:
                db |= {fmt_db(x) for x in (c.mid, c.low, c.high) if np.isfinite(x)}
    if file is not None:
        evaluation = claims.evaluate(file, tables)
        for r in [*evaluation.claims.values(), *evaluation.q.values()]:
            for x in (r.value, r.low, r.high):
                if np.isfinite(x):
                    plain.add(fmt(x))
                    db.add(fmt_db(x))
    return plain, db


def typed_run_numbers(text: str, plain: set[str], db: set[str], allowed: set[str]) -> list[str]:
    """The literals of ``text`` equal at the printed precision to a number the run produced."""
    return [written for written, x in literals(text)
            if fmt(x) not in allowed and (fmt(x) in plain or fmt_db(x) in db)]


def test_the_rule_catches_a_typed_crossing_and_lets_parameters_through():
    plain, db = {"0.33", "-7.17", "2.67"}, {"-7.2", "-7.0"}
    allowed = {"15", "0.01", "40"}
    text = ("under any alarm the single-step test leads (−7.0 against −7.2) and fires in 33% of null trials; "
            "at 15 dB, Pfa 1e-2, the 40-step window, Fig. 3, eqs. 8 and 11, `cumulant-paper[M=32]`, "
            "{{ q.delay.text }} steps")
    assert typed_run_numbers(text, plain, db, allowed) == ["−7.0", "−7.2", "33%"]


def _prose_fields(name: str) -> list[tuple[str, str]]:
    """(where, text) of a preset's hand-written prose: its notes and its claims' words."""
    notes = PRESETS_DIR / f"{name}.md"
    out = [(f"{name}.md", notes.read_text(encoding="utf-8"))] if notes.is_file() else []
    file = claims.preset_claims(name)
    for c in (file.claims if file else ()):
        out += [(f"{name}{CLAIMS_SUFFIX}: {c.id}.{k}", getattr(c, k)) for k in ("claim", "scope", "reason")]
    return out


NOTED = sorted(p.name[:-3] for p in PRESETS_DIR.iterdir() if p.name.endswith(".md"))


@pytest.mark.parametrize("name", NOTED)
def test_no_note_or_reason_types_a_number_the_run_produces(name):
    folder = ROOT / "reports" / name
    if name not in CLAIM_FILES:
        pytest.skip(f"preset {name} has no claims file yet: its notes are not templates")
    if not (folder / "summary.csv").exists():
        pytest.skip(f"no committed report of preset {name} to compare its notes with")
    file = claims.preset_claims(name)
    plain, db = run_values(folder, file)
    allowed = parameters(folder, file)
    typed = {where: found for where, text in _prose_fields(name)
             if (found := typed_run_numbers(text, plain, db, allowed))}
    assert not typed, f"numbers the run produces, typed (make them template fields): {typed}"


def test_a_claim_the_tables_cannot_answer_stops_the_report_before_anything_is_written(small_run_copy, monkeypatch):
    from radarbench.bench import report
    text = GOOD.replace('kind = "paired", a = "b", b = "a", snr_db = "all"',
                        'kind = "summary", config = "innovation[window=1]", snr_db = 0, column = "no_such_column"')
    monkeypatch.setattr(report, "_preset_name", lambda source: "small")
    monkeypatch.setattr(report.claims, "preset_claims", lambda name: claims.parse(textwrap.dedent(text), "s.toml"))
    before = {p.name: p.stat().st_mtime_ns for p in small_run_copy.iterdir()}
    with pytest.raises(ConfigError, match=r"^s.toml: claim\[0\].quantity.column: no column 'no_such_column'"):
        report.build_outputs(small_run_copy, recording=False)
    assert {p.name: p.stat().st_mtime_ns for p in small_run_copy.iterdir()} == before
