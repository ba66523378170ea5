"""A registry name two classes claim is refused where a sweep names it, and a qualified
name (``qualifier:name``) picks one (docs/architecture.md, 'Plugins').

Two outside distributions installed through entry points, as in tests/test_task_plugin.py:
``benchdemo`` (the peak-finding task, its ``bumps`` scenario and ``argmax`` method) and
``mylab``, whose ``glr`` takes a built-in's name and whose ``argmax`` takes benchdemo's.
"""

from __future__ import annotations

import tomllib

import pandas as pd
import pytest
import tomli_w

from tests.test_task_plugin import ENTRY_POINTS, METHOD, SCENARIO, TASK, _bench, env_with, install

#: mylab's peak finders: benchdemo's argmax naming the smallest sample instead (numbers no other class gives)
GLR, ARGMIN = (METHOD.replace("class ArgMax", f"class {cls}").replace('name = "argmax"', f'name = "{name}"')
               .replace("largest", "smallest").replace("np.argmax", "np.argmin")
               for cls, name in (("Glr", "glr"), ("ArgMin", "argmax")))

MYLAB_ENTRY_POINTS = """
[bench.methods]
glr = mylab.glr:Glr
argmax = mylab.argmax:ArgMin
"""

#: what every sweep here shares
COMMON = {"trials": 8, "chunk": 8, "seed": 1, "snr_db": [12], "calibration": {"h0_trials": 40}}


def _sweep(scenario: str, method: str) -> str:
    """One method on a scenario of its task (without the check, each name would run one of its classes)."""
    return tomli_w.dumps({"name": "collide", "scenario": scenario, "methods": [{"name": method}], **COMMON})


#: every qualified name, on the scenarios each one's task runs on (the built-in glr: a small
#: CV-turn-CV instance; the peak finders: the bumps)
QUALIFIED_SWEEP = tomli_w.dumps({
    "name": "qualified", "scenarios": [{"name": "benchdemo:bumps"}, {"name": "cv-turn-cv"}],
    "methods": [{"name": "radarbench:glr", "params": {"window": 5}}, {"name": "mylab:glr"},
                {"name": "benchdemo:argmax"}, {"name": "mylab:argmax"}], **COMMON})


@pytest.fixture
def rivals(tmp_path):
    """Environment with benchdemo and mylab installed."""
    site = tmp_path / "site"
    install(site, "benchdemo", {"task": TASK, "scenario": SCENARIO, "method": METHOD}, ENTRY_POINTS)
    install(site, "mylab", {"glr": GLR, "argmax": ARGMIN}, MYLAB_ENTRY_POINTS)
    return env_with(site)


@pytest.mark.parametrize("name, scenario, modules, choices", [
    ("glr", "cv-turn-cv", ("radarbench.methods.maneuver.glr (radar-maneuver-bench", "mylab.glr (mylab 0.1)"),
     "name 'radarbench:glr' or 'mylab:glr'"),
    ("argmax", "bumps", ("benchdemo.method (benchdemo 0.1)", "mylab.argmax (mylab 0.1)"),
     "name 'benchdemo:argmax' or 'mylab:argmax'")])
def test_a_name_registered_twice_is_refused_naming_both_modules(rivals, tmp_path, name, scenario, modules, choices):
    sweep, out = tmp_path / "s.toml", tmp_path / "out"
    sweep.write_text(_sweep(scenario, name))
    run = _bench(rivals, "run", sweep, "--out", out)
    assert run.returncode == 2, run.stderr
    [line] = run.stderr.strip().splitlines()
    assert line.startswith(f"error: {sweep}: methods[0].name: method {name!r} is registered twice (")
    assert all(module in line for module in modules) and line.endswith(choices), line
    assert not out.exists()


def test_bench_list_shows_each_name_registered_twice_with_both_modules(rivals):
    listed = _bench(rivals, "list")
    assert listed.returncode == 0, listed.stderr
    methods = listed.stdout.split("methods:")[1].split("names registered twice")[0]
    for name in ("radarbench:glr", "mylab:glr", "benchdemo:argmax", "mylab:argmax"):
        assert f"\n  {name} " in methods
    assert "\n  glr " not in methods and "\n  argmax " not in methods
    twice = listed.stdout.split("names registered twice")[1].split("unavailable:")[0]
    assert "method 'glr' is registered twice (radarbench.methods.maneuver.glr" in twice
    assert "method 'argmax' is registered twice (benchdemo.method (benchdemo 0.1), mylab.argmax" in twice


def test_a_qualifier_that_registered_no_such_name_is_refused(rivals, tmp_path):
    sweep = tmp_path / "s.toml"
    sweep.write_text(_sweep("bumps", "benchdemo:glr"))
    run = _bench(rivals, "run", sweep, "--out", tmp_path / "out")
    assert run.returncode == 2
    assert run.stderr.strip() == (f"error: {sweep}: methods[0].name: method 'benchdemo:glr': no method 'glr' registered by "
                                  "'benchdemo' (it is registered by radarbench.methods.maneuver.glr, mylab.glr: "
                                  "name 'radarbench:glr' or 'mylab:glr')")


@pytest.mark.slow
def test_qualified_names_run_their_own_classes_and_the_report_names_module_and_distribution(rivals, tmp_path):
    sweep, out = tmp_path / "q.toml", tmp_path / "out"
    sweep.write_text(QUALIFIED_SWEEP)
    run = _bench(rivals, "run", sweep, "--out", out, "--quiet", "--no-record")
    assert run.returncode == 0, run.stderr
    trials = pd.read_csv(out / "trials.csv")
    ran_on = trials.groupby("config").scenario.unique().map(list).to_dict()
    # the built-in glr detects maneuvers, mylab's finds peaks: each ran where its task runs
    assert ran_on == {"radarbench:glr[window=5]": ["cv-turn-cv"], "mylab:glr": ["benchdemo:bumps"],
                      "benchdemo:argmax": ["benchdemo:bumps"], "mylab:argmax": ["benchdemo:bumps"]}
    # argmin and argmax name different steps: mylab's class ran under its name, benchdemo's under its own
    hits = trials[trials.scenario == "benchdemo:bumps"].groupby("config").correct.mean()
    assert hits["benchdemo:argmax"] > 0.8 and hits["mylab:argmax"] < 0.2 and hits["mylab:glr"] < 0.2

    plan = tomllib.loads((out / "plan.toml").read_text())
    plugins = plan["provenance"]["plugins"]["methods"]
    assert plugins["mylab:glr"] == "mylab.glr (mylab 0.1)"
    assert plugins["benchdemo:argmax"] == "benchdemo.method (benchdemo 0.1)"
    assert plugins["radarbench:glr[window=5]"].startswith("radarbench.methods.maneuver.glr (radar-maneuver-bench")
    identities = _rows((out / "report.md").read_text().split("## Provenance")[1])
    assert identities["`mylab:argmax`"][:2] == ["method", "mylab.argmax (mylab 0.1)"]
    assert identities["`benchdemo:bumps`"][:2] == ["scenario", "benchdemo.scenario (benchdemo 0.1)"]
    assert identities["`radarbench:glr[window=5]`"][1].startswith(
        "radarbench.methods.maneuver.glr (radar-maneuver-bench")

    again = _bench(rivals, "run", out / "plan.toml", "--out", out)       # the labels round-trip
    assert again.returncode == 0, again.stderr
    assert pd.read_csv(out / "trials.csv").equals(trials)


def _rows(markdown: str) -> dict[str, list[str]]:
    """First cell -> the other cells of each row of the markdown tables in ``markdown``."""
    cells = [[c.strip() for c in line.strip().strip("|").split("|")] for line in markdown.splitlines()
             if line.startswith("|")]
    return {row[0]: row[1:] for row in cells}


def test_a_qualified_name_draws_the_streams_of_its_bare_name_and_names_no_path():
    from radarbench.bench.sweep.config import parse_sweep
    from radarbench.bench.recording.paths import entity_name

    bare, qualified = (parse_sweep({"name": "q", "scenario": scenario, "snr_db": [0],
                                    "methods": [{"name": "radarbench:cusum"}]})
                       for scenario in ("cv-turn-cv", "radarbench:cv-turn-cv"))
    assert qualified.scenarios[0].label == "radarbench:cv-turn-cv" and qualified.methods[0].label == "radarbench:cusum"
    assert qualified.scenarios[0].key == bare.scenarios[0].key         # the qualifier changes no number
    assert entity_name("mylab:glr[window=5]") == "mylab-glr_window-5"   # recordings and figure files


def test_an_optional_entry_whose_distribution_is_not_installed_is_skipped_with_the_reason():
    from radarbench.bench.sweep.config import parse_sweep

    plan = parse_sweep({"name": "q", "scenario": "cv-turn-cv", "snr_db": [0],
                        "methods": [{"name": "cusum"}, {"name": "mylab:glr", "optional": True}]})
    [(entry, reason)] = plan.skipped_methods
    assert entry == {"name": "mylab:glr"} and [m.label for m in plan.methods] == ["cusum"]
    assert reason.startswith("method 'mylab:glr': no method 'glr' registered by 'mylab'")
