"""What a user types and sees: --version, bench list's presets, did-you-mean, progress
lines outside a terminal, resuming a finished run, bench view without a display, the
default output folder (a fresh clone stays clean) and reading a recording into pandas
as docs/recordings.md shows."""

import io
import os
import re
import shutil
import subprocess
import sys
import time
import tomllib
from pathlib import Path

import pytest

from radarbench.bench import __version__
from radarbench.bench.sweep.listing import preset_descriptions, presets
from radarbench.bench.run.progress import Progress
from conftest import scaled

ROOT = Path(__file__).resolve().parent.parent


def _bench(*args, env=None, cwd=None):
    return subprocess.run([sys.executable, "-m", "radarbench.bench", *map(str, args)], capture_output=True, text=True,
                          timeout=scaled(), cwd=cwd, env={**os.environ, "PYTHONPATH": str(ROOT), **(env or {})})


def test_version_matches_pyproject():
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["version"] == __version__
    out = _bench("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"bench {__version__} (radar-maneuver-bench)"


def test_license_matches_pyproject():
    license_text = (ROOT / "LICENSE").read_text()
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert meta["license"] == "MIT" and meta["license-files"] == ["LICENSE"] and license_text.startswith("MIT License")


def test_list_shows_every_preset_with_its_description(tmp_path):
    out = _bench("list", env={"XDG_CACHE_HOME": str(tmp_path)})
    assert out.returncode == 0, out.stderr
    head = out.stdout.split("tasks:")[0]
    assert head.startswith("presets")
    described = dict(preset_descriptions())
    assert set(described) == set(presets()) and "quick" in described
    for name, description in described.items():
        line = next(x for x in head.splitlines() if x.split()[:1] == [name])
        assert description[:40] in line


def test_list_from_the_cache_imports_no_plugin(tmp_path):
    """The second `bench list` prints the same listing without importing NumPy (the
    plugins): what makes it answer at once."""
    env = {"XDG_CACHE_HOME": str(tmp_path)}
    probe = ("import sys, contextlib, io; from radarbench.bench.cli import main; buf = io.StringIO()\n"
             "with contextlib.redirect_stdout(buf): main(['list'])\n"
             "print(buf.getvalue()); print('numpy imported:', 'numpy' in sys.modules)")
    run = [sys.executable, "-c", probe]
    first = subprocess.run(run, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT), **env})
    second = subprocess.run(run, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT), **env})
    assert first.returncode == 0 and second.returncode == 0, first.stderr + second.stderr
    assert first.stdout.endswith("numpy imported: True\n")
    assert second.stdout.endswith("numpy imported: False\n")
    assert first.stdout.rsplit("numpy", 1)[0] == second.stdout.rsplit("numpy", 1)[0]
    assert list(tmp_path.glob("radar-maneuver-bench/list-*.json"))


def test_listing_fingerprint_follows_the_sources(tmp_path, monkeypatch):
    from radarbench.bench.sweep import listing

    pkg = tmp_path / "fakeplugins"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(listing, "PACKAGES", (*listing.PACKAGES, "fakeplugins"))
    before = listing.fingerprint()
    (pkg / "more.py").write_text("X = 1\n")
    assert listing.fingerprint() != before


@pytest.mark.parametrize("args, expected", [
    (["run", "--preset", "quik"], "error: --preset: unknown preset 'quik' (did you mean 'quick'?"),
    (["perf", "--methods", "cumulnt"], "error: --methods: unknown method 'cumulnt' (did you mean 'cumulant'?"),
])
def test_did_you_mean_on_the_command_line(args, expected, tmp_path):
    out = _bench(*args, cwd=tmp_path)
    lines = out.stderr.splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert lines[0].startswith(expected)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("field, wrong, right", [("scenario", "cv-turn-vc", "cv-turn-cv"),
                                                  ("method", "inovation", "innovation")])
def test_did_you_mean_in_a_sweep_file(field, wrong, right, write_sweep, tmp_path):
    text = write_sweep().read_text()
    text = text.replace('scenario = "cv-turn-cv"', f'scenario = "{wrong}"') if field == "scenario" else \
        text.replace('name = "innovation"', f'name = "{wrong}"')
    sweep = tmp_path / "typo.toml"
    sweep.write_text(text)
    out = _bench("run", sweep, "--out", tmp_path / "run")
    lines = out.stderr.splitlines()
    assert out.returncode == 2 and len(lines) == 1, out.stderr
    assert f"unknown {field} '{wrong}' (did you mean '{right}'?" in lines[0]
    assert not (tmp_path / "run").exists()


def test_progress_prints_periodic_lines_to_a_file():
    stream = io.StringIO()
    progress = Progress(stream=stream, period_s=0.05)
    progress.phase("calibration", total=4)
    progress.advance(2)
    deadline = time.monotonic() + scaled(300)     # a bound on the wait for a periodic line, never a timing
    while "ETA" not in stream.getvalue() and time.monotonic() < deadline:
        time.sleep(0.01)
    progress.phase("report")
    progress.close()
    lines = stream.getvalue().splitlines()
    clock = r"\d+:\d\d"                 # whatever the machine's load made the times
    assert re.fullmatch(rf"bench: calibration: 0/4 units \(0%\), {clock} elapsed", lines[0]), lines
    assert any(re.fullmatch(rf"bench: calibration: 2/4 units \(50%\), {clock} elapsed, ETA {clock}", x) for x in lines)
    assert any(re.fullmatch(rf"bench: calibration: done, 2/4 units in {clock}", x) for x in lines)
    assert lines[-2] == "bench: report: started" and re.fullmatch(rf"bench: report: done, in {clock}", lines[-1])


def test_quiet_progress_prints_nothing():
    stream = io.StringIO()
    progress = Progress(stream=stream, quiet=True, period_s=0.01)
    progress.phase("evaluation", total=3)
    progress.advance()
    time.sleep(0.05)
    progress.close()
    assert stream.getvalue() == ""


@pytest.mark.slow
def test_run_names_its_phases_on_stderr_and_resuming_a_finished_run_says_so(write_sweep, tmp_path):
    sweep, out = write_sweep(), tmp_path / "run"
    first = _bench("run", sweep, "--out", out, "--workers", 1)     # stderr is a pipe: plain lines
    assert first.returncode == 0, first.stderr
    for phase in ("calibration", "evaluation", "report", "recording"):
        assert re.search(rf"^bench: {phase}: .*$", first.stderr, re.M), (phase, first.stderr)
        assert re.search(rf"^bench: {phase}: done", first.stderr, re.M), (phase, first.stderr)
    assert "\r" not in first.stderr
    again = _bench("run", sweep, "--out", out, "--workers", 1, "--no-record")
    assert again.returncode == 0, again.stderr
    assert re.search(rf"^Nothing to run: all \d+ units stored in {re.escape(str(out))}$", again.stderr, re.M), \
        again.stderr
    assert "calibration" not in again.stderr and "evaluation" not in again.stderr


def test_view_without_a_display_says_so_and_suggests_web(write_sweep, tmp_path):
    run = tmp_path / "run"
    (run / "recording.rrd").parent.mkdir()
    (run / "recording.rrd").write_bytes(b"")
    env = {k: "" for k in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")}
    out = _bench("view", run, env=env)
    lines = out.stderr.splitlines()
    assert out.returncode == 3 and len(lines) == 1, out.stderr
    assert "no display" in lines[0] and f"bench view {run} --web" in lines[0]


def test_view_of_a_folder_without_recording_is_bad_input(tmp_path):
    out = _bench("view", tmp_path, "--web")
    assert out.returncode == 2 and "recording.rrd does not exist" in out.stderr


@pytest.mark.slow
def test_a_fresh_clone_stays_clean_after_a_run(tmp_path, write_sweep):
    """The README's quick command writes to runs/NAME/, which git ignores. A copy of the
    tracked files in a new repository stands for a fresh clone; a tiny sweep stands for
    the quick preset (same default folder, a fraction of the time)."""
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("needs git and a git checkout")
    files = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True,
                           check=True).stdout.decode().split("\0")
    clone = tmp_path / "clone"
    for name in filter(None, files):
        if (ROOT / name).is_symlink():             # radarbench/bench -> ../bench: a link, as git checks it out
            (clone / name).parent.mkdir(parents=True, exist_ok=True)
            os.symlink(os.readlink(ROOT / name), clone / name)
        elif (ROOT / name).is_file():
            (clone / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, clone / name)
    git = ["git", "-C", str(clone), "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "-A"], check=True)
    subprocess.run([*git, "commit", "-qm", "clone"], check=True)
    sweep = write_sweep()
    out = subprocess.run([sys.executable, "-m", "radarbench.bench", "run", str(sweep), "--workers", "1", "--quiet"],
                         cwd=clone, capture_output=True, text=True, timeout=scaled(),
                         env={**os.environ, "PYTHONPATH": str(clone)})
    assert out.returncode == 0, out.stderr
    assert (clone / "runs" / "small" / "report.md").is_file()
    status = subprocess.run([*git, "status", "--porcelain", "--ignored=no"], capture_output=True, text=True)
    assert status.stdout == ""


def test_the_documented_example_reads_a_trial_statistic_into_pandas(small_run, tmp_path, monkeypatch):
    """The 'Reading a recording from Python' example (docs/recordings.md), run as printed (in a
    folder whose runs/small/ is the small sweep's run)."""
    page = (ROOT / "docs" / "recordings.md").read_text()
    example = page.split("<!-- example: read-recording -->")[1].split("```python")[1].split("```")[0]
    shutil.copytree(small_run, tmp_path / "runs" / "small", symlinks=True)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {}
    exec(compile(example.replace("runs/quick", "runs/small"), "docs/recordings.md example", "exec"), namespace)
    df = namespace["df"]
    assert len(df) > 10 and df["statistic"].notna().all()
    assert df["step"].is_monotonic_increasing
