"""Every label of a plan reads back: a parameter value a config label cannot hold is
refused when the sweep is read (one line naming the parameter) or, for a plugin's
declared choice, when the plugin registers; never after the compute, where plan.toml's
reader (``bench report``, ``bench run plan.toml``) would refuse the finished run forever
(docs/architecture.md, 'Sweep files and presets')."""

from __future__ import annotations

import contextlib
import re
from dataclasses import dataclass

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from radarbench.bench import registry
from radarbench.bench.sweep.config import parse_sweep
from radarbench.bench.core import MANEUVER_DETECTION, Method
from radarbench.bench.errors import ConfigError
from radarbench.bench.params import declaration_problem, param
from radarbench.bench.report import build_outputs
from radarbench.bench.run.runner import plan_record, run_sweep
from radarbench.methods.maneuver.innovation import Innovation
from tests.property.test_hostile_markup import FRAGMENTS, SMALL

#: choice-like strings: markup, the label's own punctuation, blanks, words of every length
choice_text = st.one_of(
    st.lists(st.one_of(st.sampled_from(FRAGMENTS + [",", "=", "(", ")", "[", "]", " ", "/", "$x$", "a" * 70]),
                       st.text(max_size=4)), min_size=1, max_size=4).map("".join),
    st.from_regex(r"[A-Za-z0-9_.+\- ]{1,70}", fullmatch=True))


def chooser(choices: tuple[str, ...]) -> type[Method]:
    """The innovation detector with a string parameter ``how`` declaring ``choices``."""

    class Chooser(Method):
        """The innovation detector with a declared choice that changes nothing."""

        name = "chooser"
        task = MANEUVER_DETECTION

        @dataclass(frozen=True)
        class Params:
            how: str = param(choices[0], "a declared choice", choices=choices)

        def run(self, batch, params):
            return Innovation().run(batch, Innovation.Params(window=1))

        def nominal_threshold(self, params, pfa, batch):
            return Innovation().nominal_threshold(Innovation.Params(window=1), pfa, batch)

    return Chooser


def sweep(params: dict, label: str | None = None) -> dict:
    method = {"name": "chooser", "params": params} | ({"label": label} if label else {})
    return {"name": "choices", "trials": 2, "seed": 3, "chunk": 2, "snr_db": [6], "scenario": "cv-turn-cv",
            "scenario_params": SMALL, "methods": [method],
            "calibration": {"pfa": 0.1, "mode": "empirical", "h0_trials": 10}, "record": {"trials": 1}}


@contextlib.contextmanager
def registered(cls: type[Method]):
    """``cls`` registered (a refused plugin raises PluginError) for the block's duration."""
    registry.register_method(cls)
    try:
        yield
    finally:
        registry._METHODS.pop("chooser", None)


@settings(max_examples=150, deadline=None)
@given(choice=choice_text)
def test_a_declared_choice_is_refused_at_registration_or_its_plan_reads_back(choice):
    """Was: any string accepted as a choice; a config choosing markup ran, then plan.toml's
    label was refused by every later read."""
    cls = chooser(("plain", choice))
    problem = declaration_problem(cls.Params)
    if problem is not None:
        assert re.match(r"parameter 'how': choice .* a config label could not name it$", problem), problem
        with pytest.raises(registry.PluginError), registered(cls):
            pass
        return
    with registered(cls):
        plan = parse_sweep(sweep({"how": choice}), "s.toml")
        again = parse_sweep(plan.to_dict(), "plan.toml")              # what bench report reads back
    assert [m.label for m in again.methods] == [m.label for m in plan.methods] == [f"chooser[how={choice}]"]
    assert again.fingerprint() == plan.fingerprint()


@settings(max_examples=150, deadline=None)
@given(value=choice_text)
def test_a_free_string_a_label_cannot_hold_is_refused_when_the_sweep_is_read(value):
    """A plugin's free string (no choices) in a generated label: refused in one line naming
    the parameter, or a plan that reads back; with a label of the user's, always read back."""
    with registered(free_text()):
        try:
            plan = parse_sweep(sweep({"note": value}), "s.toml")
        except ConfigError as err:
            assert err.field == "methods[0].params.note" and "name this config with a 'label'" in err.problem
            plan = parse_sweep(sweep({"note": value}, label="noted"), "s.toml")
        again = parse_sweep(plan.to_dict(), "plan.toml")
    assert again.fingerprint() == plan.fingerprint() and [m.label for m in again.methods] == \
        [m.label for m in plan.methods]


def free_text() -> type[Method]:
    base = chooser(("plain",))

    @dataclass(frozen=True)
    class Params:
        note: str = param("", "any text")

    return type("FreeText", (base,), {"Params": Params, "__doc__": "The innovation detector with a free note."})


def test_a_declared_choice_of_every_kind_the_alphabet_allows_makes_a_reportable_run(tmp_path):
    """End to end: a choice with blanks, '+', '.', '-' and '_' runs, and the finished run's
    report is built (bench report reads plan.toml back)."""
    choice = "x+1 y.z-w_2"
    out = tmp_path / "run"
    with registered(chooser(("plain", choice))):
        plan = parse_sweep(sweep({"how": choice}), "s.toml")
        store = run_sweep(plan, out, plan_record=plan_record(plan, "bench run s.toml"), workers=1, quiet=True,
                          executor="serial")
        store.close()
        report = build_outputs(out, recording=False)
    assert f"`chooser[how={choice}]`" in report.read_text()


def test_a_markup_choice_is_refused_when_its_plugin_registers():
    with pytest.raises(registry.PluginError, match=r"choice '<svg onload=alert\(1\)>' is not letters"), \
            registered(chooser(("plain", "<svg onload=alert(1)>"))):
        pass


def test_bench_run_refuses_a_value_its_label_cannot_hold_in_one_line_writing_nothing():
    """Was: the run computed every unit, then exited 2 on its own plan.toml's label, and
    ``bench report`` failed the same way forever."""
    from tests.test_reliability_validation import refused, toml
    with registered(free_text()):
        line = refused(toml(sweep({"note": "<svg onload=alert(1)>"})))
    assert "methods[0].params.note: its label 'chooser[note=<svg onload=alert(1)>]' is not letters" in line
    assert line.endswith("name this config with a 'label' (one config per entry)")
