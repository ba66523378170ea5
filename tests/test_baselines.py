"""The strongest baseline of a claim, chosen by the run (bench/report/baselines.py; docs/architecture.md,
'Report').

(a) the chosen config is the candidate ranked first by the task's ranking metric, averaged over the
    SNR levels as the glance averages (on the outcome at equal chance Pd where the run has it),
    higher or lower being better as the task says;
(b) ties go to the earlier candidate (file order; a ``METHOD[*]``'s configs in the run's order), whatever
    order the table lists them in;
(c) a candidate that did not run is left out; none ran: the claim is not comparable;
(d) a claim names the choice in its reason (``baseline``), notes in ``baselines.NAME``, and
    claims.csv's quantity says ``baseline:NAME``;
(e) a bad ``[baseline]`` table or reference is one line naming the field; every packaged
    selection names configs or methods of its preset's sweep.
"""

from __future__ import annotations

import itertools
import re
import textwrap
import tomllib

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.report import baselines, claims
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.listing import presets

DETECTION, TRACKING = "maneuver-detection", "multi-target"     # Pd (higher is better), GOSPA (lower)


def _comparisons(means: dict[str, list[float]], task: str, metric: str, scenario: str = "s") -> list[dict]:
    """comparisons.csv's rows of every pair of configs: per level (means[config][level]) and over all."""
    levels = len(next(iter(means.values())))
    rows = []
    for a, b in itertools.combinations(means, 2):
        for level in [np.nan, *range(levels)]:
            ma, mb = ((np.mean(means[c]) if np.isnan(level) else means[c][level]) for c in (a, b))
            rows.append({"scenario": scenario, "task": task, "metric": metric, "snr_db": float(level),
                         "config_a": a, "config_b": b, "mean_a": ma, "mean_b": mb, "difference": mb - ma,
                         "difference_low": mb - ma - 0.01, "difference_high": mb - ma + 0.01, "mcnemar_p": np.nan})
    return rows


def _summary(configs, levels: int, scenario: str = "s") -> pd.DataFrame:
    return pd.DataFrame([{"scenario": scenario, "method": c.split("[")[0], "config": c, "snr_db": float(level),
                          "pd": 0.5} for c in configs for level in range(levels)])


def _tables(*blocks: list[dict]) -> claims.Tables:
    comparisons = pd.DataFrame([row for block in blocks for row in block])
    configs = list(dict.fromkeys([*comparisons.config_a, *comparisons.config_b]))
    levels = int(comparisons.snr_db.nunique())
    return claims.Tables(_summary(configs, levels), comparisons, pd.DataFrame(), 0.05)


def _choose(t, *best_of, by="ranking"):
    return baselines.choose(baselines.Selection("x", tuple(best_of), by), t)


# ------------------------------------------------------------------ (a) the best-ranked candidate

def test_the_chosen_baseline_is_the_best_ranked_on_the_equal_chance_outcome_where_the_run_has_it():
    """Any-alarm Pd favours `glr`, Pd at equal chance Pd favours `cusum` (as the glance ranks)."""
    t = _tables(_comparisons({"glr": [0.7, 0.9], "cusum": [0.6, 0.8], "innovation": [0.5, 0.6]}, DETECTION, "detected"),
                _comparisons({"glr": [0.5, 0.7], "cusum": [0.6, 0.8], "innovation": [0.4, 0.5]}, DETECTION,
                             "detected_equal_chance"))
    chosen = _choose(t, "innovation", "glr", "cusum")
    assert (chosen.config, chosen.metric) == ("cusum", "detected_equal_chance")
    assert chosen.mean == pytest.approx(0.7) and [c for c, _ in chosen.ranking] == ["cusum", "glr", "innovation"]
    assert _choose(t, "innovation", "glr", "cusum", by="ranking_metric").config == "glr"
    assert str(chosen) == "cusum"


def test_lower_is_better_where_the_task_says_so():
    t = _tables(_comparisons({"peer-a": [4000.0], "peer-b": [3900.0], "ours": [3000.0]}, TRACKING, "gospa_m"))
    assert _choose(t, "peer-a", "peer-b").config == "peer-b"


def test_every_level_weighs_the_same_as_in_the_glance():
    """Mean over levels of the per-level means: a is better on average over the levels
    (0.55 against 0.5) though b wins two levels of three, and the pooled means of the rows over
    all levels (as with 100, 300 and 300 trials at the three levels) would rank b first."""
    rows = _comparisons({"a": [0.95, 0.35, 0.35], "b": [0.5, 0.5, 0.5]}, DETECTION, "detected")
    for row in rows:
        if np.isnan(row["snr_db"]):
            row["mean_a"] = (0.95 * 100 + 0.35 * 600) / 700
    t = _tables(rows)
    assert _choose(t, "a", "b").config == "a"
    assert dict(_choose(t, "a", "b").ranking) == pytest.approx({"a": 0.55, "b": 0.5})


# ------------------------------------------------------------------ (b) ties

def test_a_tie_goes_to_the_earlier_candidate_whatever_the_tables_order():
    means = {"y": [0.6, 0.8], "x": [0.8, 0.6], "z": [0.1, 0.2]}            # x and y tie at 0.7
    for order in (["y", "x", "z"], ["z", "x", "y"]):
        t = _tables(_comparisons({c: means[c] for c in order}, DETECTION, "detected"))
        assert _choose(t, "x", "y", "z").config == "x"
        assert _choose(t, "y", "x", "z").config == "y"
        assert _choose(t, "z", "y", "x").config == "y"


def test_a_tie_within_the_numerical_resolution_is_a_tie():
    t = _tables(_comparisons({"x": [0.7], "y": [0.7 * (1 + 1e-12)]}, DETECTION, "detected"))
    assert _choose(t, "x", "y").config == "x"
    assert _choose(t, "y", "x").config == "y"


def test_method_star_stands_for_its_configs_in_the_runs_order_and_a_label_for_itself():
    t = _tables(_comparisons({"glr[window=20]": [0.7], "cusum": [0.6], "glr[window=40]": [0.7], "glr": [0.9]},
                             DETECTION, "detected"))
    assert baselines.candidates(baselines.Selection("x", ("cusum", "glr[*]")), t, "s") == \
        ["cusum", "glr[window=20]", "glr[window=40]", "glr"]
    assert baselines.candidates(baselines.Selection("x", ("glr[window=40]", "glr")), t, "s") == \
        ["glr[window=40]", "glr"]
    assert _choose(t, "cusum", "glr[window=20]", "glr[*]").config == "glr"
    assert _choose(t, "glr[window=40]", "glr[window=20]").config == "glr[window=40]"


# ------------------------------------------------------------------ (c) candidates that did not run

def test_a_candidate_that_did_not_run_is_left_out_and_none_is_missing():
    t = _tables(_comparisons({"a": [0.4], "b": [0.6]}, DETECTION, "detected"))
    assert _choose(t, "a", "not-installed").config == "a"
    with pytest.raises(claims.Missing, match="every candidate of baseline 'x'"):
        _choose(t, "not-installed", "nor-this")


def test_candidates_of_two_tasks_are_refused():
    t = _tables(_comparisons({"a": [0.4], "b": [0.6]}, DETECTION, "detected"),
                _comparisons({"c": [10.0], "d": [20.0]}, TRACKING, "gospa_m"))
    with pytest.raises(ConfigError, match=r"baseline.x.best_of: the candidates belong to 2 tasks"):
        _choose(t, "a", "c")


# ------------------------------------------------------------------ (d) in the claims

FILE = """
paper = "A paper"

[baseline.strongest]
best_of = ["glr[*]", "cusum[*]"]

[[claim]]
id = "ours-beats-the-strongest"
claim = "ours beats the conventional detectors"
where = "Fig. 3"
quantity = { kind = "paired", a = { baseline = "strongest" }, b = "ours", snr_db = "all" }
expect = "positive"
reason = "against `{{ baseline }}` ({{ baseline.mean | fmt }}), ranked first of {{ baseline.ranking | length }}"
[claim.also]
strongest_pd = { kind = "summary", config = { baseline = "strongest" }, snr_db = 0, column = "pd" }
"""


def _parse(text: str) -> claims.ClaimsFile:
    return claims.parse(textwrap.dedent(text), "x.claims.toml")


def test_a_claim_reads_the_chosen_baseline_and_names_it_in_its_reason():
    t = _tables(_comparisons({"glr": [0.6, 0.7], "cusum": [0.7, 0.8], "ours": [0.8, 0.9]}, DETECTION, "detected"))
    evaluation = claims.evaluate(_parse(FILE), t)
    result = evaluation.claims["ours-beats-the-strongest"]
    assert result.value == pytest.approx(0.1)                           # ours minus cusum, not minus glr
    assert result.reason == "against `cusum` (0.75), ranked first of 2"
    assert evaluation.q["strongest_pd"].value == 0.5
    assert evaluation.render("the strongest: `{{ baselines.strongest }}`", "notes") == "the strongest: `cusum`"
    assert evaluation.frame().quantity[0] == "paired(a=baseline:strongest, b=ours, snr_db=all)"


def test_a_selection_none_of_whose_candidates_ran_makes_its_claim_not_comparable():
    t = _tables(_comparisons({"wavelet": [0.6], "ours": [0.8]}, DETECTION, "detected"))
    evaluation = claims.evaluate(_parse(FILE), t)
    result = evaluation.claims["ours-beats-the-strongest"]
    assert result.verdict == claims.NOT_COMPARABLE
    assert result.reason.startswith("every candidate of baseline 'strongest' (glr[*], cusum[*]) on `s` did not run")
    assert str(evaluation.baselines["strongest"]) == "–"


# ------------------------------------------------------------------ (e) validation

@pytest.mark.parametrize("change, field, words", [
    (('best_of = ["glr[*]", "cusum[*]"]', 'best_of = []'), "baseline.strongest.best_of", "non-empty list"),
    (('best_of = ["glr[*]", "cusum[*]"]', 'best_of = ["glr"]\nby = "pd"'), "baseline.strongest.by", "expected one of"),
    (('best_of = ["glr[*]", "cusum[*]"]', 'best_of = ["glr"]\nfrom = 1'), "baseline.strongest.from", "unknown key"),
    (('a = { baseline = "strongest" }', 'a = { baseline = "strong" }'), "claim[0].quantity.a.baseline",
     "no [baseline.strong]"),
    (('config = { baseline = "strongest" }', 'config = { baseline = "strongest", x = 1 }'),
     "claim[0].also.strongest_pd.config", "expected { baseline"),
])
def test_a_bad_baseline_is_one_line_naming_the_field(change, field, words):
    bad = FILE.replace(*change)
    assert bad != FILE
    with pytest.raises(ConfigError, match=rf"^x\.claims\.toml: {re.escape(field)}: [^\n]*{re.escape(words)}[^\n]*$"):
        _parse(bad)


CLAIM_FILES = sorted(name for name in presets() if claims.preset_claims(name) is not None)


@pytest.mark.parametrize("name", CLAIM_FILES)
def test_every_packaged_selection_names_configs_or_methods_of_its_presets_sweep(name):
    """A misspelt candidate would silently drop out of the choice: only an optional method
    unavailable here may be absent from a run (a label, or METHOD[*] of a method the sweep runs)."""
    from tests.conftest import parse_sweep_or_skip
    plan = parse_sweep_or_skip(tomllib.loads(presets()[name].read_text(encoding="utf-8")), f"preset {name}")
    known = {m.label for m in plan.methods} | {f"{m.name}[*]" for m in plan.methods}
    known |= {entry.get("label", entry["name"]) for entry, _ in plan.skipped_methods}
    known |= {f"{entry['name']}[*]" for entry, _ in plan.skipped_methods}
    scenarios = {sc.label for sc in plan.scenarios}
    for selection in claims.preset_claims(name).baselines.values():
        assert set(selection.best_of) <= known, (selection.name, set(selection.best_of) - known)
        assert not selection.scenario or selection.scenario in scenarios
