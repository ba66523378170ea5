"""Claims as code: a paper's claims checked against the run's own tables.

A paper preset declares its paper's claims beside its sweep, in
``bench/presets/NAME.claims.toml`` (data, never code; the schema is in
docs/architecture.md, 'Report'). Each claim names the quantity that tests it
as a query over the run's summary, calibration and comparison tables (exactly
as written to summary.csv, calibration.csv and comparisons.csv, so a committed
report's claims are evaluated again from its committed CSVs alone), the
direction or value the paper claims, and how large an effect counts as the
paper's (``minimal_effect``, ``tolerance``): the verdict (:func:`verdict`) reads
"reproduces" or "does not reproduce" only where the interval settles it, else "not
resolved" with the trials that would resolve it. The report prints
the "Paper vs ours" table from the results and renders the preset's notes
(``NAME.md``) and each claim's ``reason`` as Jinja2 templates filled from them:
no number the run produces is ever typed.

Quantities (:mod:`bench.report.quantities`) give (value, low, high): a 95% interval where the
table has one.
Crossings are the SNR at which a Pd column reaches a level, computed as the
report's SNR-at-Pd tables compute them (:func:`bench.markdown.snr50`); a
difference of two quantities has the conservative interval
[a.low − b.high, a.high − b.low] (the Minkowski difference of the two 95%
intervals). A quantity whose config or scenario config did not run (an
optional method unavailable here) makes its claim *not comparable*. Nothing
here names a method, a scenario or a task: they are the claims file's data.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping

import pandas as pd

from radarbench.bench.report.baselines import Chosen, Selection, check_reference, is_reference, parse_selections, resolve
from radarbench.bench.report.baselines import template_values as baseline_values
from radarbench.bench.errors import ConfigError
from radarbench.bench.sweep.listing import CLAIMS_SUFFIX
from radarbench.bench.markdown import fmt, fmt_db, table
from radarbench.bench.report.quantities import (ALL_LEVELS, INLINE, Missing, Tables, Value, csv_frame,  # noqa: F401 - importable from here
                              describe, quantity, read_tables)
from radarbench.bench.results.tables import write_csv

#: the columns of claims.csv, in order
CLAIMS_COLUMNS = ["id", "claim", "where", "original", "english", "quantity", "value", "low", "high", "unit",
                  "verdict", "scope", "reason"]
REPRODUCES, DOES_NOT, NOT_COMPARABLE, CONVERSION = "reproduces", "does not reproduce", "not comparable", "conversion"
NOT_RESOLVED = "not resolved"

_ID = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")
_CLAIM_KEYS = {"id", "claim", "where", "original", "english", "quantity", "unit", "expect", "value", "tolerance",
               "minimal_effect", "min", "max", "reason", "scope", "also"}
_REQUIRED = ("id", "claim", "where", "expect")
#: expect -> the keys it needs besides the required ones
_EXPECT_NEEDS = {"negative": ("quantity",), "positive": ("quantity",), "value": ("quantity", "value"),
                 "between": ("quantity", "min", "max"), "not-comparable": ("reason",), "conversion": ("reason",)}
#: the size keys (non-negative, in the claim's unit) -> the expects they belong to
_SIZES = {"minimal_effect": ("positive", "negative"), "tolerance": ("value",)}
#: kind -> (required keys, optional keys); every kind may carry ``scale`` (a multiplier applied to the result)
_KINDS = {
    "summary": ({"config", "snr_db", "column"}, {"scenario"}),
    "calibration": ({"config", "column"}, {"scenario"}),
    "paired": ({"a", "b", "snr_db"}, {"scenario", "metric"}),
    "crossing": ({"config"}, {"scenario", "column", "level"}),
    "crossing_difference": ({"a", "b"}, {"scenario", "scenario_a", "scenario_b", "column", "level"}),
    "difference": ({"a", "b"}, set()),
    "ratio": ({"a", "b"}, set()),
}


# ------------------------------------------------------------------ the file

@dataclass(frozen=True)
class Claim:
    """One ``[[claim]]`` of a claims file, validated."""

    id: str
    claim: str
    where: str
    expect: str
    quantity: dict | None = None
    original: str = ""
    english: str = ""
    unit: str = ""
    value: float | None = None
    tolerance: float = 0.0          # value ± tolerance is the paper's value
    minimal_effect: float = 0.0     # the smallest size of a directional effect that is the paper's
    min: float | None = None
    max: float | None = None
    reason: str = ""
    scope: str = ""
    also: dict = field(default_factory=dict)


@dataclass(frozen=True)
class ClaimsFile:
    """A preset's claims: ``paper`` (how the report names it) and its claims, in file order."""

    name: str          # the file's name, for error messages
    paper: str
    claims: tuple[Claim, ...]
    baselines: dict[str, Selection] = field(default_factory=dict)   # [baseline.NAME]: bench.report.baselines


def _text(value: Any, field: str, *, empty: bool = False) -> str:
    if not isinstance(value, str) or (not empty and not value.strip()):
        raise ConfigError(field, f"expected a non-empty string, got {value!r}"[:200])
    return value


def _number(value: Any, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(field, f"expected a finite number, got {value!r}"[:200])
    return float(value)


def _unknown(table: Mapping, allowed: set, field: str) -> None:
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{field}.{key}", f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _quantity(q: Any, field: str) -> dict:
    """An inline quantity, checked: its kind, its keys, its values' types."""
    if not isinstance(q, dict):
        raise ConfigError(field, f"expected an inline table with a kind, got {q!r}"[:200])
    kind = q.get("kind")
    if kind not in _KINDS:
        raise ConfigError(f"{field}.kind", f"expected one of {', '.join(_KINDS)}, got {kind!r}")
    required, optional = _KINDS[kind]
    _unknown(q, required | optional | {"kind", "scale"}, field)
    for key in sorted(required - set(q)):
        raise ConfigError(f"{field}.{key}", f"missing (a {kind} quantity needs {', '.join(sorted(required))})")
    out = dict(q)
    for key in ("scale", "level"):
        if key in q:
            out[key] = _number(q[key], f"{field}.{key}")
    if "snr_db" in q and not (kind == "paired" and q["snr_db"] == ALL_LEVELS):
        out["snr_db"] = _number(q["snr_db"], f"{field}.snr_db")
    if kind == "crossing_difference" and "scenario" in q and ({"scenario_a", "scenario_b"} & set(q)):
        raise ConfigError(f"{field}.scenario", "give scenario, or scenario_a and scenario_b, not both")
    for key in ("a", "b"):
        if key in q:
            out[key] = _quantity(q[key], f"{field}.{key}") if kind in INLINE else _config(q[key], f"{field}.{key}")
    if "config" in q:
        out["config"] = _config(q["config"], f"{field}.config")
    for key in ("column", "scenario", "scenario_a", "scenario_b", "metric"):
        if key in q:
            _text(q[key], f"{field}.{key}")
    return out


def _config(value: Any, field: str) -> str | dict:
    """A quantity's config: a label, or ``{ baseline = "NAME" }`` (checked against the file's
    selections once they are all read, :func:`_check_references`)."""
    return check_reference(value, field) if isinstance(value, dict) else _text(value, field)


def _check_references(claims: tuple[Claim, ...], selections: dict[str, Selection]) -> None:
    """Every ``{ baseline = "NAME" }`` of the claims names a ``[baseline.NAME]``."""
    def walk(q: dict, field: str):
        for key, value in q.items():
            if is_reference(value):
                check_reference(value, f"{field}.{key}", selections)
            elif isinstance(value, dict):
                walk(value, f"{field}.{key}")
    for i, c in enumerate(claims):
        for name, q in [("quantity", c.quantity), *((f"also.{k}", v) for k, v in c.also.items())]:
            if q:
                walk(q, f"claim[{i}].{name}")


def _claim(raw: Any, field: str) -> Claim:
    if not isinstance(raw, dict):
        raise ConfigError(field, f"expected a table, got {raw!r}"[:200])
    _unknown(raw, _CLAIM_KEYS, field)
    for key in _REQUIRED:
        if key not in raw:
            raise ConfigError(f"{field}.{key}", "missing")
    expect = raw["expect"]
    if expect not in _EXPECT_NEEDS:
        raise ConfigError(f"{field}.expect", f"expected one of {', '.join(_EXPECT_NEEDS)}, got {expect!r}")
    for key in _EXPECT_NEEDS[expect]:
        if key not in raw:
            raise ConfigError(f"{field}.{key}", f"missing (expect = {expect!r} needs it)")
    if not _ID.match(_text(raw["id"], f"{field}.id")):
        raise ConfigError(f"{field}.id", f"expected kebab-case (a-z, 0-9, -), got {raw['id']!r}")
    also = raw.get("also", {})
    if not isinstance(also, dict):
        raise ConfigError(f"{field}.also", f"expected a table of named quantities, got {also!r}"[:200])
    for name in also:
        if not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", name):
            raise ConfigError(f"{field}.also.{name}", "expected a template name (letters, digits, _)")
    numbers = {k: _number(raw[k], f"{field}.{k}") for k in ("value", "tolerance", "minimal_effect", "min", "max")
               if k in raw}
    for key, expects in _SIZES.items():
        if key in numbers and expect not in expects:
            raise ConfigError(f"{field}.{key}", f"only for expect = {' or '.join(map(repr, expects))}, not {expect!r}")
        if numbers.get(key, 0.0) < 0:
            raise ConfigError(f"{field}.{key}", f"expected a size >= 0 (in the claim's unit), got {numbers[key]:g}")
    if "min" in numbers and "max" in numbers and numbers["min"] > numbers["max"]:
        raise ConfigError(f"{field}.max", f"expected >= min ({numbers['min']:g}), got {numbers['max']:g}")
    needed = {"claim", "where", *_EXPECT_NEEDS[expect]}          # not-comparable and conversion need a reason
    texts = {k: _text(raw[k], f"{field}.{k}", empty=k not in needed)
             for k in ("claim", "where", "original", "english", "unit", "reason", "scope") if k in raw}
    return Claim(id=raw["id"], expect=expect, **texts, **numbers,
                 quantity=_quantity(raw["quantity"], f"{field}.quantity") if "quantity" in raw else None,
                 also={name: _quantity(q, f"{field}.also.{name}") for name, q in also.items()})


def parse(text: str, name: str) -> ClaimsFile:
    """A claims file's text, validated: unknown keys, missing fields or a bad kind
    raise :class:`ConfigError` naming the file and the field, e.g.
    ``maneuver-detection.claims.toml: claim[2].quantity.kind: expected one of ...``."""
    try:
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError("", f"not valid TOML: {exc}") from None
        _unknown(data, {"paper", "claim", "baseline"}, "")
        paper = _text(data.get("paper"), "paper")
        raws = data.get("claim")
        if not isinstance(raws, list) or not raws:
            raise ConfigError("claim", "missing: give at least one [[claim]]")
        claims = tuple(_claim(raw, f"claim[{i}]") for i, raw in enumerate(raws))
        selections = parse_selections(data.get("baseline", {}), "baseline")
        _check_references(claims, selections)
        seen, named = set(), set()
        for i, c in enumerate(claims):
            if c.id in seen:
                raise ConfigError(f"claim[{i}].id", f"repeated id {c.id!r}")
            seen.add(c.id)
            for also in c.also:          # one namespace ``q`` for the whole file
                if also in named:
                    raise ConfigError(f"claim[{i}].also.{also}", "repeated name (an earlier claim has it)")
                named.add(also)
    except ConfigError as err:
        raise ConfigError(f"{name}: {err.field.lstrip('.')}" if err.field else name, err.problem) from None
    return ClaimsFile(name, paper, claims, selections)


def load(path: str | Path) -> ClaimsFile:
    path = Path(path)
    return parse(path.read_text(encoding="utf-8"), path.name)


def preset_claims(preset: str) -> ClaimsFile | None:
    """The packaged claims of preset ``preset`` (``bench/presets/NAME.claims.toml``), if any."""
    import importlib.resources
    path = importlib.resources.files("radarbench.bench") / "presets" / f"{preset}{CLAIMS_SUFFIX}"
    return parse(path.read_text(encoding="utf-8"), path.name) if path.is_file() else None


# ------------------------------------------------------------------ verdicts and results

def _number_text(x: float, unit: str) -> str:
    if math.isinf(x):
        return "−∞" if x < 0 else "+∞"
    return fmt_db(x) if unit == "dB" else fmt(x)


def value_text(v: Value, unit: str = "") -> str:
    """``value [low, high] unit`` as the table prints it: dB to 0.1, else 3 significant
    digits; an interval alone (a crossing the levels do not resolve, or outside the
    swept range) as "between a and b", "< b" or "> a"."""
    f = (lambda x: _number_text(x, unit))
    has = (lambda x: not math.isnan(x))
    if has(v.value):
        text = f(v.value) + (f" [{f(v.low)}, {f(v.high)}]" if has(v.low) or has(v.high) else "")
    elif has(v.low) and has(v.high):
        text = (f"< {f(v.high)}" if math.isinf(v.low) else f"> {f(v.low)}" if math.isinf(v.high)
                else f"between {f(v.low)} and {f(v.high)}")
    else:
        return "–"
    return f"{text} {unit}" if unit else text


def _bounds(v: Value) -> tuple[float, float]:
    """The interval a verdict reads: the quantity's, else the value alone."""
    if math.isnan(v.low) and math.isnan(v.high):
        return v.value, v.value
    return v.low, v.high


def claimed_range(c: Claim) -> tuple[float, float]:
    """(lo, hi): the effects claim ``c`` counts as the paper's. A directional claim's is
    open at its threshold, the minimal effect (0 unless stated): (m, +∞) or (−∞, −m); a
    value's is value ± tolerance and a between's [min, max], both closed."""
    if c.expect == "positive":
        return c.minimal_effect, math.inf
    if c.expect == "negative":
        return -math.inf, -c.minimal_effect
    if c.expect == "value":
        return c.value - c.tolerance, c.value + c.tolerance
    return c.min, c.max


def settled(c: Claim, low: float, high: float) -> str:
    """The verdict an interval [low, high] settles: REPRODUCES when it lies within the
    claimed range (:func:`claimed_range`), DOES_NOT when it lies entirely outside it
    (it excludes the paper's effect), else NOT_RESOLVED."""
    lo, hi = claimed_range(c)
    if c.expect in ("positive", "negative"):   # open at the threshold: beyond it to reproduce, at or short of it to exclude
        inside = (lo == -math.inf or low > lo) and (hi == math.inf or high < hi)
        outside = high <= lo or low >= hi
    else:
        inside, outside = lo <= low and high <= hi, high < lo or low > hi
    return REPRODUCES if inside else DOES_NOT if outside else NOT_RESOLVED


def trials_needed(c: Claim, v: Value) -> float:
    """The trials (per level, or null trials for a calibration value; as ``v.n`` counts
    them) that would resolve a claim not resolved by ``v``, if the estimate holds.

    A 95% interval's half-width scales as 1/sqrt(n), so with n' trials the interval
    around the estimate x is x − w_lo·sqrt(n/n') .. x + w_hi·sqrt(n/n'), where
    w_lo = x − low and w_hi = high − x. It settles when the half-width facing a
    threshold of the claimed range is smaller than the estimate's distance d to it:

        n_needed ≈ n · (w / d)²

    with w and d the half-width and distance on the threshold's side (for a directional
    claim the threshold is 0 or the minimal effect). An estimate outside the claimed
    range settles "does not reproduce" at its near threshold; one inside it settles
    "reproduces" once both sides are inside: the larger of the two. NaN where no number
    of trials settles it (the estimate on a threshold) or ``v`` gives no estimate, no
    finite interval or no trial count."""
    x, lo, hi = v.value, *claimed_range(c)
    if not all(math.isfinite(y) for y in (x, v.low, v.high, v.n)) or x in (lo, hi):
        return math.nan
    w_lo, w_hi = x - v.low, v.high - x
    if x > hi:
        ratios = [w_lo / (x - hi)]
    elif x < lo:
        ratios = [w_hi / (lo - x)]
    else:
        ratios = [w / d for w, d in ((w_lo, x - lo), (w_hi, hi - x)) if math.isfinite(d)]
    return v.n * max(ratios) ** 2


def _rounded_up(n: float) -> int:
    """n rounded up to two significant digits: an estimate, not a count."""
    step = 10 ** max(0, math.floor(math.log10(n)) - 1)
    return int(math.ceil(n / step - 1e-9) * step)      # 1e-9: not up for a float's last bit


def _unresolved_reason(c: Claim, v: Value) -> str:
    if math.isnan(v.value) or not (math.isfinite(v.low) and math.isfinite(v.high)):
        return "the SNR levels bound its interval (a crossing between or beyond them): more levels would resolve it"
    if not v.n > 0:
        return "the trials behind its interval are not known"
    n = trials_needed(c, v)
    if math.isnan(n):
        if c.expect == "value" and not c.tolerance:
            return "the estimate is the claimed value and the claim states no tolerance: no number of trials would resolve it"
        return "the estimate sits on the claim's threshold: no number of trials would resolve it"
    per = "null trials" if v.null else "trials per level"
    towards = REPRODUCES if claimed_range(c)[0] <= v.value <= claimed_range(c)[1] else DOES_NOT
    return f"~{_rounded_up(n):,} {per} (this run: {v.n:,.0f}) would resolve it, as “{towards}” if the estimate holds"


def verdict(c: Claim, v: Value | None) -> tuple[str, str]:
    """(verdict, generated reason) of claim ``c`` whose quantity is ``v`` (None: no quantity):
    :func:`settled` on v's interval (v's value alone where it has none); a claim not
    resolved gets the trials that would resolve it (:func:`trials_needed`)."""
    if c.expect == "not-comparable":
        return NOT_COMPARABLE, ""
    if c.expect == "conversion":
        return CONVERSION, ""
    low, high = _bounds(v)
    if math.isnan(low) or math.isnan(high):
        return NOT_COMPARABLE, "the run gives no value for it"
    word = settled(c, low, high)
    if word == NOT_RESOLVED:
        return word, _unresolved_reason(c, v)
    if word == REPRODUCES:
        return word, ""
    unit = (lambda x: _number_text(x, c.unit))
    if c.expect in ("positive", "negative"):
        sign = 1.0 if c.expect == "positive" else -1.0
        if sign * high < 0 and sign * low < 0:
            return word, "the opposite sign"
        if c.minimal_effect:
            return word, f"smaller than the minimal effect {unit(c.minimal_effect)}"
        return word, "none in the claimed direction: the interval reaches 0 at most"
    if c.expect == "value":
        side = "below" if c.value < low - c.tolerance else "above"
        return word, (f"the claimed {unit(c.value)} lies {side} our interval"
                      + (f" widened by its tolerance {unit(c.tolerance)}" if c.tolerance else ""))
    return word, f"outside [{unit(c.min)}, {unit(c.max)}]"


@dataclass(frozen=True)
class Result:
    """A claim's or a named quantity's outcome, as templates see it: ``value``, ``low``,
    ``high``, ``p``, ``n`` (the trials behind the interval; ``null``: null trials),
    ``text``, ``verdict``, ``reason`` (and ``tie``: the interval covers 0)."""

    value: float = math.nan
    low: float = math.nan
    high: float = math.nan
    p: float = math.nan
    n: float = math.nan
    null: bool = False
    text: str = "–"
    verdict: str = ""
    reason: str = ""
    missing: str = ""              # what did not run, if anything

    @property
    def tie(self) -> bool:
        low, high = _bounds(Value(self.value, self.low, self.high))
        return not (low > 0 or high < 0)

    def __str__(self) -> str:
        return self.text


def default_unit(q: dict) -> str:
    """The unit a quantity has by its kind: dB for a crossing and a difference of two dB
    quantities; none otherwise (a claim's ``unit`` overrides it)."""
    if q["kind"] in ("crossing", "crossing_difference"):
        return "dB"
    if q["kind"] == "difference" and default_unit(q["a"]) == default_unit(q["b"]) == "dB":
        return "dB"
    return ""


def _result(q: dict | None, t: Tables, unit: str = "", selections: dict | None = None) -> Result:
    if q is None:
        return Result()
    unit = unit or default_unit(q)
    try:
        v = quantity(resolve(q, selections or {}, t)[0], t)
    except Missing as m:
        return Result(missing=str(m.args[0]))
    return Result(v.value, v.low, v.high, v.p, v.n, v.null, value_text(v, unit))


def _environment():
    from radarbench.bench.report.render import environment
    return environment()


def render_template(template: str, field: str, **values) -> str:
    """``template`` rendered by Jinja2 with ``values`` (``claims``, ``q``, ...; filters
    ``fmt``, ``db``, ``pct``); an error names ``field``."""
    import jinja2
    try:
        return _environment().from_string(template).render(**values).strip()
    except jinja2.TemplateError as exc:
        raise ConfigError(field, f"template error: {exc}") from None


@dataclass(frozen=True)
class Evaluation:
    """A claims file evaluated on a run: every claim's result and every named quantity's."""

    file: ClaimsFile
    claims: dict[str, Result]
    q: dict[str, Result]
    baselines: dict[str, Chosen] = field(default_factory=dict)    # baselines.NAME: bench.report.baselines

    def frame(self) -> pd.DataFrame:
        """claims.csv: one row per claim (:data:`CLAIMS_COLUMNS`)."""
        rows = [{"id": c.id, "claim": c.claim, "where": c.where, "original": c.original, "english": c.english,
                 "quantity": describe(c.quantity), "value": r.value, "low": r.low, "high": r.high, "unit": c.unit,
                 "verdict": r.verdict, "scope": c.scope, "reason": r.reason}
                for c, r in ((c, self.claims[c.id]) for c in self.file.claims)]
        return pd.DataFrame(rows, columns=CLAIMS_COLUMNS)

    def render(self, text: str, field: str) -> str:
        return render_template(text, field, claims=self.claims, q=self.q, baselines=self.baselines)


def evaluate(file: ClaimsFile, tables: Tables) -> Evaluation:
    """Every claim of ``file`` on ``tables``: quantities, verdicts, then the reasons
    rendered in file order (a reason may read the claims before it)."""
    def named(field: str, fn):
        try:
            return fn()
        except ConfigError as err:
            raise ConfigError(f"{file.name}: {field}.{err.field}" if err.field else f"{file.name}: {field}",
                              err.problem) from None

    q = {name: named(f"claim[{i}].also.{name}", lambda: _result(quantity_, tables, selections=file.baselines))
         for i, c in enumerate(file.claims) for name, quantity_ in c.also.items()}
    results = {}
    for i, c in enumerate(file.claims):
        r = named(f"claim[{i}].quantity", lambda: _result(c.quantity, tables, c.unit, file.baselines))
        if r.missing:
            results[c.id] = replace(r, verdict=NOT_COMPARABLE, reason=f"{r.missing} did not run")
            continue
        word, generated = verdict(c, Value(r.value, r.low, r.high, n=r.n, null=r.null)) if c.quantity \
            else verdict(c, None)
        results[c.id] = replace(r, verdict=word, reason=generated)
    evaluation = Evaluation(file, results, q, baseline_values(file.baselines, tables))
    for i, c in enumerate(file.claims):
        r = results[c.id]
        absent = [q[name].missing for name in c.also if q[name].missing]
        if c.reason and absent and not r.missing:     # its reason would read them: say why instead
            results[c.id] = replace(r, reason="; ".join(s for s in (r.reason, *(f"{a} did not run" for a in absent))
                                                        if s))
        elif c.reason and not r.missing:
            own = render_template(c.reason, f"{file.name}: claim[{i}].reason", claims=results, q=q,
                                  baselines=evaluation.baselines, baseline=_claims_baseline(c, file, tables),
                                  value=r.value, low=r.low, high=r.high, text=r.text, verdict=r.verdict)
            results[c.id] = replace(r, reason="; ".join(s for s in (r.reason, own) if s))
    return evaluation


def _claims_baseline(c: Claim, file: ClaimsFile, tables: Tables) -> Chosen | None:
    """The baseline the claim's own quantity chose (its first), for ``baseline`` in its reason."""
    chosen = resolve(c.quantity, file.baselines, tables)[1] if c.quantity else []
    return chosen[0] if chosen else None


# ------------------------------------------------------------------ the report's section

def _paper_cell(c: Claim) -> str:
    words = f"“{c.original}”" if c.original else ""
    if c.english:
        words += f" ({c.english})" if words else c.english
    # the value a claim is tested against: the paper's number, or our reading of its words
    # (e.g. an ideal detector's Pd); "claimed", since the paper need not print it
    paper = f" (claimed: {_number_text(c.value, c.unit)}{' ' + c.unit if c.unit else ''})" \
        if c.expect == "value" else ""
    return f"{c.where}: {words}{paper}" if words else f"{c.where}{paper}"


def claims_markdown(evaluation: Evaluation, notes: str = "") -> str:
    """The report's *Paper vs ours* section: the table from the evaluated claims,
    then the preset's notes rendered with ``claims`` and ``q``."""
    f = evaluation.file
    rows = []
    for c in f.claims:
        r = evaluation.claims[c.id]
        word = f"**{r.verdict}**" + (f" {c.scope}" if c.scope else "")
        rows.append([c.claim, _paper_cell(c), r.text, word, r.reason])
    rows = [[str(x).replace("|", "\\|").replace("\n", " ") for x in row] for row in rows]
    parts = [f"## Paper vs ours ({f.paper})",
             table(["claim", "paper (where: words)", "ours [95% CI]", "verdict", "reason"], rows)]
    if notes.strip():
        parts.append(evaluation.render(notes, f"{f.name[:-len(CLAIMS_SUFFIX)]}.md"))
    return "\n\n".join(parts)


def write_folder(folder: str | Path) -> Path:
    """Write claims.csv of a report folder from its committed tables (listed in its
    manifest, as ``bench report`` writes it): ``python -m radarbench.bench.report.claims FOLDER...``."""
    from radarbench.bench.results import runfolder
    folder = Path(folder)
    frame = evaluate_folder(folder)
    with runfolder.writing(folder):
        write_csv(frame, folder / "claims.csv")
    return folder / "claims.csv"


def evaluate_folder(folder: str | Path, file: ClaimsFile | None = None) -> pd.DataFrame:
    """claims.csv of a report folder, from its committed CSVs and plan.toml alone:
    the claims of its preset (plan.toml's ``name``) unless ``file`` is given."""
    folder = Path(folder)
    if file is None:
        name = tomllib.loads((folder / "plan.toml").read_text(encoding="utf-8"))["name"]
        file = preset_claims(name)
        if file is None:
            raise ConfigError(str(folder), f"preset {name!r} has no claims file ({name}{CLAIMS_SUFFIX})")
    return evaluate(file, read_tables(folder)).frame()


def main(argv: list[str] | None = None) -> int:
    """``python -m radarbench.bench.report.claims FOLDER...``: claims.csv of each report folder from its CSVs."""
    import sys
    for folder in (sys.argv[1:] if argv is None else argv):
        try:
            print(write_folder(folder))
        except ConfigError as err:
            print(f"error: {err}", file=sys.stderr)
            return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
