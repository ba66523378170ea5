"""``bench compare`` never hides anything: a config
failed in one run is listed as failed and gates CI; an incomplete run is compared on
the trials both runs hold; configs, scenario configs and SNR levels of one run only
are listed with their metrics; Pd at two false-alarm levels is refused; claims whose
verdict flipped are listed; stores are read without writing anything.

Three small runs (seconds each); the other cases are copies of one of them whose
store is edited as a failed or interrupted run would have left it."""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from radarbench.bench.cli import EXIT_REGRESSION, main
from conftest import scaled, small_sweep_text

OTHER_METHODS = """
[[methods]]
name = "innovation"
params = { window = 1 }

[[methods]]
name = "wavelet"

"""


def _run(folder: Path, snr: str, pfa: float, methods: str | None = None) -> Path:
    """The shared small sweep (tests/conftest.py), at ``pfa``, its methods replaced by ``methods``."""
    text = small_sweep_text(trials=10, snr=snr, chunk=5, h0=60).replace("pfa = 0.02", f"pfa = {pfa}")
    if methods is not None:
        text = text[:text.index("[[methods]]")] + methods + text[text.index("[calibration]"):]
    sweep = folder.with_suffix(".toml")
    sweep.write_text(text)
    assert main(["run", str(sweep), "--out", str(folder), "--workers", "1", "--quiet", "--no-record"]) == 0
    return folder


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    """base: Pfa 0.01; loose: the same at Pfa 0.1; other: another method set and SNR grid."""
    root = tmp_path_factory.mktemp("compare")
    return {"base": _run(root / "base", "[0, 8]", 0.01), "loose": _run(root / "loose", "[0, 8]", 0.1),
            "other": _run(root / "other", "[0, 4]", 0.01, OTHER_METHODS)}


def _copy(run: Path, dest: Path) -> Path:
    shutil.copytree(run, dest)
    return dest


def _edit(folder: Path, *statements: tuple[str, tuple]) -> Path:
    with sqlite3.connect(folder / "results.sqlite") as con:
        for sql, args in statements:
            con.execute(sql, args)
    return folder


def _fail(folder: Path, config: str, units: str = "evaluation/%") -> Path:
    """The store a run leaves when ``config`` failed on the units matching ``units``."""
    return _edit(folder, ("UPDATE runs SET error = 'RuntimeError: broken (mine.py:3)' WHERE method = ? AND unit LIKE ?",
                          (config, units)),
                 ("DELETE FROM metrics WHERE method = ? AND unit LIKE ?", (config, units)))


def _compare(a: Path, b: Path, out: Path | None = None, gate: bool = True) -> tuple[int, str, str]:
    import contextlib
    import io
    stdout, stderr = io.StringIO(), io.StringIO()
    args = ["compare", str(a), str(b), *(["--out", str(out)] if out else []),
            *(["--fail-on-regression"] if gate else [])]
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(args)
    return code, stdout.getvalue(), stderr.getvalue()


def _overall(out: Path) -> pd.DataFrame:
    diffs = pd.read_csv(out / "compare.csv")
    return diffs[diffs.snr_db.isna()].set_index("config")


# ------------------------------------------------------------------ failures

def test_a_config_failed_on_every_unit_of_b_is_listed_and_is_a_regression(runs, tmp_path):
    broken = _fail(_copy(runs["base"], tmp_path / "broken"), "cumulant[window=16]")
    code, out, err = _compare(runs["base"], broken, tmp_path / "cmp")
    assert code == EXIT_REGRESSION and "cumulant[window=16] on cv-turn-cv (failed in B)" in err
    overall = _overall(tmp_path / "cmp")
    assert list(overall.index) == ["innovation[window=1]", "innovation[window=5]", "cumulant[window=16]"]
    row = overall.loc["cumulant[window=16]"]
    assert row.change == "failed in B" and row.units_failed_b == 4 and row.units_failed_a == 0
    assert "RuntimeError: broken" in row.note and np.isfinite(row.mean_a)
    assert "**failed in B**" in out and "2 (scenario config, method config) compared" in out
    # the other way round it is a fix, listed, not a regression
    code, out, _ = _compare(broken, runs["base"], tmp_path / "back")
    assert code == 0 and _overall(tmp_path / "back").loc["cumulant[window=16]"].change == "failed in A"


def test_failures_on_some_units_of_b_fail_the_gate(runs, tmp_path):
    partly = _fail(_copy(runs["base"], tmp_path / "partly"), "innovation[window=5]", "evaluation/%/+8/%")
    code, out, err = _compare(runs["base"], partly, tmp_path / "cmp")
    assert code == EXIT_REGRESSION and "innovation[window=5] on cv-turn-cv (failed units in B)" in err
    row = _overall(tmp_path / "cmp").loc["innovation[window=5]"]
    assert (row.units_failed_a, row.units_failed_b) == (0, 2)
    assert (row.n_a, row.n_b) == (10, 10)            # compared on the level that ran in both
    assert "failed units" in out
    assert _compare(runs["base"], partly, gate=False)[0] == 0


# ------------------------------------------------------------------ incomplete runs

def test_an_incomplete_run_is_compared_on_the_trials_both_hold(runs, tmp_path):
    """B interrupted after the first unit of each level: 5 trials against the same 10."""
    cut = _copy(runs["base"], tmp_path / "cut")
    late = "evaluation/%/000000005+5"
    _edit(cut, ("DELETE FROM runs WHERE unit LIKE ?", (late,)), ("DELETE FROM metrics WHERE unit LIKE ?", (late,)),
          ("DELETE FROM records WHERE unit LIKE ?", (late,)), ("DELETE FROM units WHERE key LIKE ?", (late,)))
    code, out, _ = _compare(runs["base"], cut, tmp_path / "cmp")
    assert code == 0
    assert "**B is incomplete**: 14 of 16 units stored" in out.split("|")[0]
    overall = _overall(tmp_path / "cmp")
    assert overall.paired.all() and (overall.n_a == 10).all() and (overall.n_b == 10).all()
    assert (overall.difference == 0).all() and (overall.change == "no significant change").all()

    def five_trials(plan):                  # the same store as a complete sweep of 5 trials per level
        plan["sweep"]["trials"] = plan["scenarios"][0]["trials"] = 5
    _edit(_edit_plan(cut, five_trials), ("UPDATE meta SET value = '14' WHERE key = 'units_total'", ()))
    code, out, _ = _compare(runs["base"], cut)
    top = out.split("|")[0]
    assert code == 0 and "is incomplete" not in top
    assert "**Trials per level of `cv-turn-cv` differ**: A 10, B 5; compared on the trials both runs hold" in top


def test_a_store_alone_compares_both_ways_with_its_summary(runs, tmp_path):
    """A folder holding only results.sqlite, as ``previous/`` and an interrupted run are (no
    report built): its summary is rebuilt from the store, so compare_summary.csv has both sides."""
    bare = tmp_path / "previous"
    bare.mkdir()
    shutil.copy(runs["base"] / "results.sqlite", bare / "results.sqlite")
    for a, b, name in ((bare, runs["base"], "ab"), (runs["base"], bare, "ba")):
        code, _, err = _compare(a, b, tmp_path / name)
        assert code == 0, err
        side = pd.read_csv(tmp_path / name / "compare_summary.csv")
        assert len(side) and side.a.notna().all() and side.b.notna().all() and (side.difference == 0).all()


# ------------------------------------------------------------------ one run only

def test_disjoint_methods_and_snr_levels_are_listed_on_both_sides(runs, tmp_path):
    code, out, _ = _compare(runs["base"], runs["other"], tmp_path / "cmp")
    assert code == 0
    diffs = pd.read_csv(tmp_path / "cmp" / "compare.csv")
    only = diffs[diffs.change.str.startswith("only in")]
    over_all = only[only.snr_db.isna()].set_index("config")
    assert dict(over_all.change) == {"innovation[window=5]": "only in A", "cumulant[window=16]": "only in A",
                                     "wavelet": "only in B"}
    assert over_all.loc["wavelet"].n_b == 20 and np.isfinite(over_all.loc["wavelet"].mean_b)
    assert over_all.loc["cumulant[window=16]"].n_a == 20 and np.isfinite(over_all.loc["cumulant[window=16]"].mean_a)
    levels = only[only.snr_db.notna() & (only.config == "innovation[window=1]")]
    assert {(r.snr_db, r.change) for r in levels.itertuples()} == {(8.0, "only in A"), (4.0, "only in B")}
    matched = diffs[(diffs.config == "innovation[window=1]") & ~diffs.change.str.startswith("only in")]
    assert list(matched.snr_db.fillna(-1)) == [-1, 0.0] and matched.paired.all()
    assert "**SNR levels of `cv-turn-cv` differ**: A 0.0, 8.0 dB, B 0.0, 4.0 dB" in out
    assert "In one run only" in out and "wavelet" in out and "cumulant[window=16]" in out
    summary = pd.read_csv(tmp_path / "cmp" / "compare_summary.csv")
    wavelet = summary[summary.config == "wavelet"]
    assert wavelet.a.isna().all() and wavelet.b.notna().any()          # its metrics, on its side only


def _edit_plan(folder: Path, change) -> Path:
    """``change(plan)`` applied to the plan stored in the run folder's store."""
    with sqlite3.connect(folder / "results.sqlite") as con:
        plan = json.loads(con.execute("SELECT value FROM meta WHERE key='plan'").fetchone()[0])
        change(plan)
        con.execute("UPDATE meta SET value=? WHERE key='plan'", (json.dumps(plan),))
    return folder


def test_runs_with_disjoint_method_sets_are_both_listed(runs, tmp_path):
    """B's innovation config relabelled "mine": no config in common, all five listed, no gate failure."""
    def relabel(plan):
        plan["methods"][0]["label"] = "mine"
    mine = _edit_plan(_copy(runs["other"], tmp_path / "mine"), relabel)
    _edit(mine, *[(f"UPDATE {t} SET method = 'mine' WHERE method = 'innovation[window=1]'", ()) for t in
                  ("runs", "metrics", "null_stats")])
    code, out, _ = _compare(runs["base"], mine, tmp_path / "cmp")
    assert code == 0 and "nothing to rank" in out
    diffs = pd.read_csv(tmp_path / "cmp" / "compare.csv")
    over_all = diffs[diffs.snr_db.isna()]
    assert dict(zip(over_all.config, over_all.change)) == {
        "innovation[window=1]": "only in A", "innovation[window=5]": "only in A", "cumulant[window=16]": "only in A",
        "mine": "only in B", "wavelet": "only in B"}
    assert over_all.mean_a.notna().sum() == 3 and over_all.mean_b.notna().sum() == 2


# ------------------------------------------------------------------ comparability

def test_pd_at_two_false_alarm_levels_is_refused(runs, tmp_path):
    """Pfa 0.1 against 0.01: B detects more because it alarms ten times more often; never "better"."""
    code, out, err = _compare(runs["base"], runs["loose"], tmp_path / "cmp")
    assert code == EXIT_REGRESSION and "(not comparable)" in err
    top = out.split("|")[0]
    assert "**Calibration differs**: Pfa 0.01 in A, 0.1 in B" in top and "not comparable" in top
    overall = _overall(tmp_path / "cmp")
    assert (overall.change == "not comparable").all() and overall.difference.isna().all()
    assert "better" not in out and "worse" not in out
    assert _compare(runs["base"], runs["loose"], gate=False)[0] == 0


def test_a_changed_scenario_config_is_stated_at_the_top(runs, tmp_path):
    def harder(plan):
        plan["sweep"]["scenario_params"]["turn_rate_deg_s"] = 1.5
    changed = _edit_plan(_copy(runs["base"], tmp_path / "harder"), harder)
    out = _compare(runs["base"], changed)[1]
    assert "**Scenario config `cv-turn-cv` differs**: turn_rate_deg_s = 3.0 in A, 1.5 in B" in out.split("|")[0]


def test_claims_whose_verdict_flipped_are_listed_first(runs, tmp_path):
    a, b = _copy(runs["base"], tmp_path / "a"), _copy(runs["base"], tmp_path / "b")
    head = "id,claim,where,verdict,reason\n"
    (a / "claims.csv").write_text(head + "beats,X beats Y,Fig. 3,reproduces,\nsame,Z,Eq. 1,reproduces,\n"
                                         "gone,W,Fig. 4,does not reproduce,\n")
    (b / "claims.csv").write_text(head + "beats,X beats Y,Fig. 3,does not reproduce,\nsame,Z,Eq. 1,reproduces,\n")
    code, out, _ = _compare(a, b)
    assert code == 0
    top = out.split("scenario config")[0]
    assert "Claims whose verdict differs** (2)" in top
    assert "| `beats` | X beats Y | reproduces | does not reproduce |" in " ".join(top.split()).replace("| |", "|")
    assert "`gone`" in top and "absent" in top and "`same`" not in top
    (b / "claims.csv").unlink()                      # one run without claims: nothing to compare
    assert "Claims whose verdict" not in _compare(a, b)[1]


# ------------------------------------------------------------------ read-only stores

def _files(folder: Path) -> dict[str, tuple[int, bytes]]:
    return {p.name: (p.stat().st_mtime_ns, p.read_bytes()) for p in sorted(folder.iterdir()) if p.is_file()}


def test_compare_writes_nothing_in_the_run_folders(runs, tmp_path):
    a, b = _copy(runs["base"], tmp_path / "a"), _copy(runs["loose"], tmp_path / "b")
    before = {a: _files(a), b: _files(b)}
    assert _compare(a, b, gate=False)[0] == 0
    for folder, files in before.items():
        assert _files(folder) == files          # no -wal, -shm or -journal; every byte and mtime as it was


def _unshare_works() -> bool:
    try:
        return subprocess.run(["unshare", "-rm", "true"], capture_output=True, timeout=scaled(60)).returncode == 0
    except (OSError, subprocess.TimeoutExpired):
        return False


@pytest.mark.slow          # an end-to-end CLI run (or fuzzing): CI runs it, the inner loop does not
@pytest.mark.skipif(not _unshare_works(), reason="needs unshare (user and mount namespaces) for a read-only mount")
def test_compare_works_on_a_read_only_file_system(runs, tmp_path):
    """The run folders on a read-only bind mount (as root, chmod would not stop a write)."""
    media = tmp_path / "media"
    _copy(runs["base"], media / "a")
    _copy(runs["other"], media / "b")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(__file__).parents[1]),
                                                        *filter(None, [os.environ.get("PYTHONPATH")])])}
    script = (f"mount --bind {media} {media} && mount -o remount,bind,ro {media} && "
              f"! touch {media}/probe 2>/dev/null && exec {sys.executable} -m radarbench.bench compare {media}/a {media}/b")
    proc = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, env=env,
                          timeout=scaled())
    assert proc.returncode == 0, proc.stderr
    assert "In one run only" in proc.stdout and not proc.stderr
