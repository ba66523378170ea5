"""numba's on-disk cache (bench/run/numba_cache.py): a damaged, truncated, full or read-only
cache never fails a kernel, a unit or a run; stderr says once per command which folder was
skipped and why; nothing is ever written into the package's folders."""

from __future__ import annotations

import errno
import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from radarbench.bench.run import numba_cache, progress
from tests.test_reliability_io import _mount_namespace, _read_only

from conftest import scaled

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_FOLDERS = ("bench", "methods", "models", "scenarios")
SKIPPED = "bench: numba cache skipped: "

KERNELS = '''
import numba


@numba.njit(cache=True)
def affine(x):
    return x * 2.0 + 1.0


@numba.njit(cache=True)
def square(x):
    return x * x
'''

#: a process that installs the guard (as bench.registry.discover does) and calls the kernels
SCRIPT = '''
import sys
import numpy as np
from radarbench.bench.run import numba_cache
numba_cache.install()
sys.path.insert(0, sys.argv[1])
import kernels
x = np.arange(5.0)
print(kernels.affine(x).sum(), kernels.square(x).sum(), sum(kernels.affine.stats.cache_hits.values()))
'''


def _cache_files(folder: Path, pattern: str) -> list[Path]:
    return sorted(folder.rglob(pattern))


def _package_cache_files() -> set[Path]:
    return {p for name in PACKAGE_FOLDERS for pattern in ("*.nbi", "*.nbc") for p in (ROOT / name).rglob(pattern)}


@pytest.fixture
def kernel_process(tmp_path):
    """Runs :data:`SCRIPT` in a fresh process on a cache folder; returns (stdout, stderr lines)."""
    (tmp_path / "code").mkdir()
    (tmp_path / "code" / "kernels.py").write_text(KERNELS)
    (tmp_path / "run.py").write_text(SCRIPT)

    def run(cache: Path, wrap: list[str] | None = None) -> tuple[str, list[str]]:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
        out = subprocess.run([*(wrap or []), sys.executable, str(tmp_path / "run.py"), str(tmp_path / "code")],
                             capture_output=True, text=True, env=env)
        assert out.returncode == 0, out.stderr
        return out.stdout.strip(), out.stderr.splitlines()
    return run


def _garble(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[:64] = bytes((i * 37 + 11) % 256 for i in range(64))      # numba's pickle no longer loads
    path.write_bytes(bytes(data))


def _flip_one_byte(path: Path) -> None:
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0xFF            # in the object code: pickle loads it, the checksum does not
    path.write_bytes(bytes(data))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[:len(path.read_bytes()) // 2])


@pytest.mark.parametrize("damage, pattern", [(_garble, "*.nbc"), (_flip_one_byte, "*.nbc"), (_truncate, "*.nbi")])
def test_a_damaged_entry_is_compiled_past_said_once_and_written_anew(kernel_process, tmp_path, damage, pattern):
    cache = tmp_path / "numba"
    good, err = kernel_process(cache)
    assert good.endswith(" 0") and not err                      # compiled, saved
    assert kernel_process(cache) == (good[:-1] + "1", [])       # loaded from the cache
    for path in _cache_files(cache, pattern):
        damage(path)
    out, err = kernel_process(cache)
    assert out == good                                          # compiled again: the same numbers
    assert len(err) == 1 and err[0].startswith(f"{SKIPPED}{cache} (a damaged entry: "), err
    assert kernel_process(cache) == (good[:-1] + "1", [])       # the entry was written anew


def test_a_read_only_folder_is_said_once_and_nothing_lands_in_the_package(kernel_process, tmp_path):
    cache = tmp_path / "numba"
    cache.mkdir()
    before = _package_cache_files()
    out, err = kernel_process(cache, wrap=_read_only(cache))
    assert out == kernel_process(tmp_path / "good")[0]
    assert err == [f"{SKIPPED}{cache} (not writable: Read-only file system); "
                   "the kernels it lacks are compiled in every run"]
    assert not list(cache.iterdir()) and _package_cache_files() == before


def test_a_full_folder_is_said_once(kernel_process, tmp_path):
    ns = _mount_namespace()
    if ns is None:
        pytest.skip("cannot mount a tmpfs here (needs root and unshare)")
    cache = tmp_path / "numba"
    cache.mkdir()
    out, err = kernel_process(cache, wrap=[*ns, "sh", "-c", 'mount -t tmpfs -o size=4k tmpfs "$0" && exec "$@"',
                                           str(cache)])
    assert out == kernel_process(tmp_path / "good")[0]
    assert err == [f"{SKIPPED}{cache} (full: No space left on device); "
                   "the kernels it lacks are compiled in every run until there is room"]


@pytest.fixture
def fresh_kernels(tmp_path, monkeypatch):
    """The module of :data:`KERNELS`, imported in this process with the guard installed,
    on an empty cache folder, nothing said yet."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(numba_cache.config, "CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setattr(numba_cache, "_UNWRITABLE", set())
    monkeypatch.setattr(progress, "_said", set())
    monkeypatch.delenv(progress.NOTICES_ENV, raising=False)
    numba_cache.install()
    name = f"kernels_{tmp_path.name}"
    (tmp_path / f"{name}.py").write_text(KERNELS)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module(name)
    yield module
    sys.modules.pop(name, None)


@pytest.mark.parametrize("error, reason", [(OSError(errno.ENOSPC, "No space left on device"), "full"),
                                           (PermissionError(errno.EACCES, "Permission denied"), "not writable")])
def test_a_failed_save_compiles_says_once_and_tries_that_folder_no_more(fresh_kernels, monkeypatch, capsys, tmp_path,
                                                                        error, reason):
    """A portable simulation of a full or forbidden folder: every write of the cache fails."""
    writes = []

    def refuse(self, path, payload):
        writes.append(path)
        raise error
    monkeypatch.setattr(numba_cache._CheckedFile, "_write", refuse)
    x = np.arange(5.0)
    assert fresh_kernels.affine(x).tolist() == (x * 2 + 1).tolist()
    assert fresh_kernels.square(x).tolist() == (x * x).tolist()       # a second kernel: the folder is not tried again
    assert len(writes) == 1
    assert capsys.readouterr().err == f"{SKIPPED}{tmp_path / 'numba'} ({reason}: {error.strerror}); " \
                                      f"{numba_cache._CONSEQUENCE[reason]}\n"


def test_every_kernel_keeps_a_guarded_cache_outside_the_package(fresh_kernels):
    """The kernels decorated before the guard was installed (the harness's own, imported
    by bench.registry) and after it: a GuardedCache, in the cache folder, never beside the source."""
    import radarbench.models.kalman  # noqa: F401 - kernels of the package
    kernels = list(numba_cache.kernels())
    assert fresh_kernels.affine in kernels and any(k.__module__.startswith("radarbench.models") for k in kernels)
    for kernel in kernels:
        assert isinstance(kernel._cache, numba_cache.GuardedCache), kernel
        assert not Path(kernel._cache.cache_path).is_relative_to(ROOT), kernel


#: a process that calls ``affine`` of the module ``argv[2]`` in ``argv[1]`` and prints its
#: cache hits and misses (a miss: it compiled the kernel)
WAITER = '''
import importlib, sys
import numpy as np
from radarbench.bench.run import numba_cache
numba_cache.install()
sys.path.insert(0, sys.argv[1])
kernels = importlib.import_module(sys.argv[2])
print("calling", flush=True)
kernels.affine(np.arange(5.0))
print(sum(kernels.affine.stats.cache_hits.values()), sum(kernels.affine.stats.cache_misses.values()))
'''


def test_a_kernel_another_process_compiles_is_waited_for_then_loaded_not_compiled_twice(fresh_kernels, tmp_path):
    """Two processes of a cold run call one kernel: the second waits for the first to compile
    it, then loads it from the cache (a warm-up's workers share the kernels they compile)."""
    lock = fresh_kernels.affine._cache._lock_path()
    assert numba_cache.COMPILE_LOCK.take(lock)            # this process starts compiling affine
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba"), "PYTHONPATH": str(ROOT)}
    try:
        waiter = subprocess.Popen([sys.executable, "-c", WAITER, str(tmp_path), fresh_kernels.__name__],
                                  stdout=subprocess.PIPE, text=True, env=env)
        assert waiter.stdout.readline() == "calling\n"
        fresh_kernels.affine(np.arange(5.0))              # compiled and saved while the other process calls it
    finally:
        numba_cache.COMPILE_LOCK.give_back(lock)
    out, _ = waiter.communicate(timeout=scaled())
    assert waiter.returncode == 0
    assert out.split() == ["1", "0"], "the other process compiled the kernel again instead of loading it"
    assert numba_cache.COMPILE_LOCK.held() == []


def test_a_failed_compilation_gives_its_lock_back(fresh_kernels):
    """A kernel that does not compile is never saved: its lock must not stay held (another
    process would wait on it)."""
    with pytest.raises(Exception):
        fresh_kernels.affine("not an array")
    assert numba_cache.COMPILE_LOCK.held() == []

def test_without_numba_cache_dir_the_cache_is_numbas_user_wide_folder_not_the_package(monkeypatch, tmp_path):
    monkeypatch.setattr(numba_cache.config, "CACHE_DIR", "")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert numba_cache.cache_root() == str(tmp_path / "numba")        # numba's user-wide folder


def test_a_notice_is_said_once_per_command_across_its_processes(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(progress, "_said", set())
    with progress.notices_of_one_command():
        folder = os.environ[progress.NOTICES_ENV]
        progress.say_once("k", "once")
        progress.say_once("k", "once")               # the same process again: silent
        monkeypatch.setattr(progress, "_said", set())
        progress.say_once("k", "once")               # another process of the command (its own memory): silent
        progress.say_once("other", "another notice")
    assert capsys.readouterr().err == "bench: once\nbench: another notice\n"
    assert not os.path.exists(folder) and progress.NOTICES_ENV not in os.environ


# ------------------------------------------------------------------ end to end, through the command line

SWEEP = ('name = "kalman"\nscenario = "maneuvering-1d"\ntrials = 2\nseed = 1\nsnr_db = [10]\nchunk = 1\n\n'
         '[[methods]]\nname = "cv-kf"\n')          # the batched Kalman filter's kernels: the fewest to compile
RESULTS = ("trials.csv", "calibration.csv")


def _run(sweep: Path, out: Path, cache: Path, wrap: list[str] | None = None) -> list[str]:
    """``bench run`` with two workers on ``cache``; the stderr lines (exit 0)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([*(wrap or []), sys.executable, "-m", "radarbench.bench", "run", str(sweep), "--out", str(out),
                           "--workers", "2", "--no-record", "--quiet"], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    return proc.stderr.splitlines()


@pytest.fixture(scope="module")
def good_run(tmp_path_factory):
    """A sweep with numba kernels run on an empty cache (filled by it): its results and its cache."""
    folder = tmp_path_factory.mktemp("good")
    (folder / "kalman.toml").write_text(SWEEP)
    assert not [line for line in _run(folder / "kalman.toml", folder / "run", folder / "numba") if SKIPPED in line]
    return folder


def _fault(kind: str, good: Path, cache: Path) -> list[str] | None:
    """Makes ``cache`` the fault ``kind``; returns the command's prefix (a mount), if any."""
    if kind in ("garbled-nbc", "truncated-nbi"):
        shutil.copytree(good / "numba", cache)
        for path in _cache_files(cache, "*.nbc" if kind == "garbled-nbc" else "*.nbi"):
            (_garble if kind == "garbled-nbc" else _truncate)(path)
        return None
    cache.mkdir()
    if kind == "read-only":
        return _read_only(cache)
    ns = _mount_namespace()
    if ns is None:
        pytest.skip("cannot mount a tmpfs here (needs root and unshare)")
    return [*ns, "sh", "-c", 'mount -t tmpfs -o size=4k tmpfs "$0" && exec "$@"', str(cache)]


@pytest.mark.slow
@pytest.mark.parametrize("kind, reason", [("garbled-nbc", "a damaged entry"), ("truncated-nbi", "a damaged entry"),
                                          ("read-only", "not writable"), ("full", "full")])
def test_a_run_on_a_faulty_cache_is_complete_correct_and_says_so_once(good_run, tmp_path, kind, reason):
    """Two workers on a damaged, read-only or full cache: the run ends (exit 0) with the
    results of a run on a good cache, one stderr line names the folder and the reason,
    and no cache file lands in the package's folders."""
    cache = tmp_path / "numba"
    wrap = _fault(kind, good_run, cache)
    before = _package_cache_files()
    err = _run(good_run / "kalman.toml", tmp_path / "run", cache, wrap)
    assert [line for line in err if "numba" in line] == [line for line in err if line.startswith(f"{SKIPPED}{cache} ({reason}")]
    assert len([line for line in err if "numba" in line]) == 1, err
    for name in RESULTS:
        assert (tmp_path / "run" / name).read_bytes() == (good_run / "run" / name).read_bytes(), name
    assert _package_cache_files() == before
