"""Command-line changes to a sweep (``bench run --methods/--scenarios/--snr/--trials/--seed/
--set``; docs/running.md): applied to the sweep's data, checked by the sweep's own code, kept
in plan.toml; and a sweep's own mistakes answered before any plugin or NumPy is imported."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import tomllib

import pytest

from radarbench.bench.cli import main
from radarbench.bench.sweep.config import Overrides, apply_overrides, parse_sweep
from radarbench.bench.errors import ConfigError

SWEEP = {"name": "o", "scenario": "maneuvering-1d", "scenario_params": {"steps": 60}, "trials": 20, "seed": 1,
         "snr_db": [0, 6, 12], "methods": [{"name": "cv-kf"}, {"name": "imm-cv-ca"},
                                           {"name": "ca-kf", "label": "ca"}]}


def test_methods_keep_the_named_entries_in_order_and_add_unknown_ones_at_their_defaults():
    out = apply_overrides(SWEEP, Overrides(methods=("ca", "cv-kf", "singer")))
    assert out["methods"] == [{"name": "ca-kf", "label": "ca"}, {"name": "cv-kf"}, {"name": "singer"}]
    assert SWEEP["methods"][0] == {"name": "cv-kf"} and len(SWEEP["methods"]) == 3     # the input is not changed


def test_scenarios_turn_the_single_form_into_a_list_keeping_its_params():
    out = apply_overrides(SWEEP, Overrides(scenarios=("maneuvering-1d", "cv-turn-cv")))
    assert "scenario" not in out and "scenario_params" not in out
    assert out["scenarios"] == [{"name": "maneuvering-1d", "params": {"steps": 60}}, {"name": "cv-turn-cv"}]
    listed = apply_overrides({**out, "scenarios": [{"name": "glint", "snr_db": [3], "trials": 5}, *out["scenarios"]]},
                             Overrides(scenarios=("glint",), snr_db=(1.0, 2.0), trials=7))
    assert listed["scenarios"] == [{"name": "glint"}] and listed["snr_db"] == [1.0, 2.0] and listed["trials"] == 7


@pytest.mark.parametrize("assignment, path, value", [
    ("calibration.h0_trials=500", ("calibration", "h0_trials"), 500),
    ("scenario_params.steps=80", ("scenario_params", "steps"), 80),
    ("methods.1.params.tracking_index=[0.5, 1.0]", ("methods", 1, "params", "tracking_index"), [0.5, 1.0]),
    ("description=a quick look", ("description",), "a quick look"),
    ('name="renamed"', ("name",), "renamed"),
])
def test_set_writes_a_toml_value_at_a_dotted_key(assignment, path, value):
    node = apply_overrides(SWEEP, Overrides(sets=(assignment,)))
    for part in path:
        node = node[part]
    assert node == value


@pytest.mark.parametrize("assignment, says", [
    ("methods.7.params.x=1", "methods.7: expected an index below 3"),
    ("name.first=1", "name is not a table"),
    ("=3", "expected KEY=VALUE"),
    ("trials", "expected KEY=VALUE"),
])
def test_a_bad_set_is_refused_naming_it(assignment, says):
    with pytest.raises(ConfigError, match=says) as err:
        apply_overrides(SWEEP, Overrides(sets=(assignment,)))
    assert err.value.field.startswith("--set")


def test_the_changed_sweep_resolves_like_a_sweep_file():
    plan = parse_sweep(apply_overrides(SWEEP, Overrides(methods=("cv-kf",), snr_db=(3.0,), trials=8, seed=5,
                                                        sets=("scenario_params.steps=50",))))
    assert [m.label for m in plan.methods] == ["cv-kf"] and plan.snr_db == (3.0,) and plan.trials == 8
    assert plan.seed == 5 and plan.scenarios[0].params.steps == 50


def test_methods_alone_leave_out_the_scenarios_none_of_them_runs_on():
    sweep = {**SWEEP, "scenario": None, "scenario_params": None}
    del sweep["scenario"], sweep["scenario_params"]
    sweep["scenarios"] = [{"name": "maneuvering-1d", "params": {"steps": 60}}, {"name": "glint", "params": {"steps": 60}}]
    with pytest.raises(ConfigError, match="no method of the sweep runs on scenario config 'glint'"):
        parse_sweep(sweep)
    plan = parse_sweep(sweep, drop_idle_scenarios=True)
    assert [s.name for s in plan.scenarios] == ["maneuvering-1d"]


@pytest.mark.parametrize("argv, says", [
    (["--snr", "500"], "error: --snr: snr_db[0]: expected an SNR in [-200, 200] dB, got 500"),
    (["--trials", "0"], "error: --trials: expected int in [1, 10000000], got 0"),
    (["--seed", "-1"], "error: --seed: expected int in [0, "),
    (["--set", "calibration.pfa=2"], "error: --set calibration.pfa: expected a number in [1e-300, 0.5)"),
    (["--methods", "nosuch"], "error: --methods: methods[0].name: unknown method 'nosuch'"),
])
def test_a_bad_change_is_one_line_naming_its_option_and_nothing_is_written(tmp_path, capsys, argv, says):
    out = tmp_path / "run"
    assert main(["run", "--preset", "quick", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(says) and err.count("\n") == 1, err
    assert not out.exists()


def test_a_word_that_is_no_sweep_file_is_named(tmp_path, capsys):
    assert main(["run", "--preset", "quick", "cv-kf", "--out", str(tmp_path / "r")]) == 2
    assert "'cv-kf' and --preset quick: give a sweep file or --preset NAME, not both" in capsys.readouterr().err
    sweep = tmp_path / "s.toml"
    sweep.write_text("name = 'x'\n")
    assert main(["run", "--methods", "cv-kf", str(sweep)]) == 2
    assert "was read as a name of --methods/--scenarios: put the sweep file first" in capsys.readouterr().err


def test_a_sweeps_own_mistake_is_answered_before_any_plugin_or_numpy(tmp_path):
    """The sweep's own fields are checked before the plugins are imported (a second, not a minute, under load)."""
    sweep = tmp_path / "s.toml"
    sweep.write_text('name = "x"\nscenario = "cv-turn-cv"\nsnr_db = [0]\ntrials = -1\n[[methods]]\nname = "cv-kf"\n')
    script = textwrap.dedent(f"""
        import sys
        from radarbench.bench.cli import main
        code = main(["run", {str(sweep)!r}, "--out", {str(tmp_path / "run")!r}])
        print(code, "numpy" in sys.modules, "radarbench.methods" in sys.modules)
    """)
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert run.stdout.split() == ["2", "False", "False"], run.stdout + run.stderr
    assert run.stderr.strip() == f"error: {sweep}: trials: expected int in [1, 10000000], got -1"


@pytest.mark.slow
def test_the_preset_runs_exactly_what_the_command_line_chose(tmp_path):
    out = tmp_path / "run"
    assert main(["run", "--preset", "quick", "--methods", "cv-kf", "imm-cv-ca", "--snr", "0", "10",
                 "--out", str(out), "--quiet", "--no-record", "--workers", "1"]) == 0
    plan = tomllib.loads((out / "plan.toml").read_text())
    assert [m["name"] for m in plan["methods"]] == ["cv-kf", "imm-cv-ca"]
    assert {s["name"] for s in plan["scenarios"]} == {"maneuvering-1d"}
    assert all(s["snr_db"] == [0.0, 10.0] for s in plan["scenarios"])
    assert "--methods cv-kf imm-cv-ca --snr 0 10" in plan["provenance"]["command"]
    # the plan reproduces the run: nothing left to compute
    assert main(["run", str(out / "plan.toml"), "--out", str(out), "--quiet", "--no-record"]) == 0
