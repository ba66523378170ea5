"""Sweep-file validation and grid expansion."""

import pytest

from radarbench.bench.sweep.config import parse_sweep, parse_sweep_text
from radarbench.bench.errors import ConfigError


def sweep(**over):
    base = {"name": "t", "scenario": "cv-turn-cv", "trials": 10, "snr_db": [0, 5],
            "methods": [{"name": "innovation", "params": {"window": 5}}]}
    base.update(over)
    return base


def error_of(data) -> str:
    with pytest.raises(ConfigError) as exc:
        parse_sweep(data)
    return str(exc.value)


def test_grid_expansion_is_cartesian_with_readable_labels():
    plan = parse_sweep(sweep(methods=[{"name": "cumulant", "params": {"window": [16, 32],
                                                                    "moment": ["centred", "raw"]}}]))
    labels = [m.label for m in plan.methods]
    assert labels == ["cumulant[window=16,moment=centred]", "cumulant[window=16,moment=raw]",
                      "cumulant[window=32,moment=centred]", "cumulant[window=32,moment=raw]"]
    assert plan.methods[0].params_text == "window=16,moment=centred"


def test_snr_range_is_inclusive_and_sorted():
    plan = parse_sweep(sweep(snr_db={"start": -5, "stop": 15, "step": 1}))
    assert plan.snr_db[0] == -5 and plan.snr_db[-1] == 15 and len(plan.snr_db) == 21
    assert parse_sweep(sweep(snr_db=[5, -1.5])).snr_db == (-1.5, 5.0)


def test_defaults_are_filled_and_plan_round_trips_as_a_sweep():
    import tomllib

    from radarbench.bench.sweep import tomlw
    plan = parse_sweep(sweep())
    again = parse_sweep(tomllib.loads(tomlw.dumps(plan.to_dict())))
    assert again.fingerprint() == plan.fingerprint()
    assert [m.label for m in again.methods] == [m.label for m in plan.methods]
    assert plan.calibration.mode == "empirical" and plan.chunk == 50


@pytest.mark.parametrize("data, expected", [
    (sweep(methods=[{"name": "innovation", "params": {"window": -2}}]),
     "methods[0].params.window: expected int >= 1, got -2"),
    (sweep(methods=[{"name": "nope"}]), "methods[0].name: unknown method 'nope'"),
    (sweep(methods=[{"name": "innovation", "params": {"windw": 3}}]), "methods[0].params.windw: unknown parameter"),
    (sweep(methods=[{"name": "innovation", "params": {"window": "5"}}]), "methods[0].params.window: expected int"),
    (sweep(snr_db=[]), "snr_db: empty list"),
    (sweep(snr_db={"start": 0, "stop": 5, "step": 0}), "snr_db.step: expected a number > 0"),
    (sweep(trials=-3), "trials: expected int in [1,"),
    (sweep(scenario="nowhere"), "scenario: unknown scenario 'nowhere'"),
    (sweep(colour="blue"), "colour: unknown key"),
    (sweep(name="../../x"), "name: expected letters"),
    (sweep(calibration={"pfa": 0.7}), "calibration.pfa: expected a number in [1e-300, 0.5)"),
    (sweep(calibration={"mode": "gumbel"}), "calibration.mode: 'gumbel'"),
    (sweep(scenario_params={"turn_steps": 500}), "scenario_params"),
    (sweep(methods=[{"name": "innovation", "params": {"window": []}}]), "methods[0].params.window: empty list"),
    (sweep(methods=[{"name": "innovation"}, {"name": "innovation"}]), "methods[1]: config 'innovation' repeats"),
    (sweep(snr_db=[1, float("nan")]), "snr_db[1]: expected a finite number"),
])
def test_bad_input_names_the_field(data, expected):
    message = error_of(data)
    assert expected in message
    assert "\n" not in message


def test_file_level_errors_are_one_line():
    for raw, expected in [(b"name = [", "invalid TOML"), (b"\xff\xfe\x00", "not UTF-8")]:
        with pytest.raises(ConfigError) as exc:
            parse_sweep_text(raw, "x.toml")
        assert expected in str(exc.value) and "\n" not in str(exc.value)


def test_huge_sweeps_need_consent():
    data = sweep(trials=10_000_000, snr_db={"start": 0, "stop": 20, "step": 1})
    assert "--yes" in error_of(data)
    assert parse_sweep(data, allow_large=True).trial_runs == 210_000_000
