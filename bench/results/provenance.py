"""Where a result came from: versions, git commit, machine, time, and the module and
distribution of each config's plugin (:func:`distribution_of`)."""

from __future__ import annotations

import functools
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

#: the label of the report's Provenance row that holds the wall time of the last run's units
#: (written by bench.report, read back from a committed report by bench.cli.docs)
WALL_TIME_ROW = "wall time of the units in the last `bench run` (before report and recording)"


def _versions() -> dict[str, str]:
    import importlib.metadata as md
    out = {"python": platform.python_version()}
    for pkg in ("radar-maneuver-bench", "numpy", "scipy", "numba", "pandas", "filterpy", "rerun-sdk", "matplotlib"):
        try:
            out[pkg] = md.version(pkg)
        except md.PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _git(folder: Path, *args: str) -> subprocess.CompletedProcess | None:
    """``git -C folder ARGS``; None where git cannot run (not installed, hung)."""
    try:
        return subprocess.run(["git", "-C", str(folder), *args], capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return None


def git_commit() -> str:
    root = Path(__file__).resolve().parents[1].parent
    out = _git(root, "rev-parse", "--short=12", "HEAD")
    # the committed reports are outputs, not code: their changes do not make the code dirty
    dirty = _git(root, "status", "--porcelain", "--untracked-files=no", "--", ".", ":!reports")
    if out is None or dirty is None:
        return "unknown"
    if out.returncode != 0:
        return "unknown (not a git checkout)"
    return out.stdout.strip() + (" (with uncommitted changes)" if dirty.stdout.strip() else "")


def head_of(folder: Path) -> str | None:
    """The commit checked out where ``folder`` lies; None outside a checkout or without git."""
    out = _git(folder, "rev-parse", "--short=12", "HEAD")
    return out.stdout.strip() if out is not None and out.returncode == 0 else None


#: folder -> the commit :func:`_git_head` found there (what this process's provenance named)
_HEADS: dict[str, str | None] = {}


@functools.lru_cache(maxsize=None)
def _git_head(folder: Path) -> str | None:
    _HEADS[str(folder)] = head = head_of(folder)
    return head


def git_heads() -> dict[str, str | None]:
    """Folder -> the commit checked out there, of every folder this process's provenance
    named a commit of (:func:`distribution_of`): a later run compares them
    (:mod:`bench.results.unchanged`)."""
    return dict(_HEADS)


@functools.lru_cache(maxsize=1)
def package_owners() -> dict[str, list[str]]:
    """Top-level package -> the distributions installing it: a scan of every distribution's
    files (a quarter of a second), once per process for the provenance and the identities."""
    import importlib.metadata as md
    return md.packages_distributions()


def _is_editable(dist) -> bool:
    """Installed with ``pip install -e`` (PEP 660: ``direct_url.json`` says so)."""
    try:
        return bool(json.loads(dist.read_text("direct_url.json") or "{}").get("dir_info", {}).get("editable"))
    except (ValueError, AttributeError):
        return False


@functools.lru_cache(maxsize=None)
def _installing(top: str):
    """The distribution that installs top-level package ``top`` (None: none does)."""
    import importlib.metadata as md

    for name in package_owners().get(top, []):
        try:
            return md.distribution(name)
        except md.PackageNotFoundError:
            continue
    return None


def distribution_of(module: str, dist=None) -> str:
    """The distribution that provides ``module`` (``dist``, else the one installing its
    top-level package), as a report names it: ``name version``; for an editable install
    ``name, editable, git commit X`` (the commit checked out where the module's top-level
    package lies; ``name, editable`` without git or a checkout); for code that no
    distribution installs, ``not installed`` (with the commit likewise)."""
    top = module.split(".")[0]
    return _distribution_text(top, dist if dist is not None else _installing(top))


@functools.lru_cache(maxsize=None)
def _distribution_text(top: str, dist) -> str:
    """:func:`distribution_of` for a top-level package and its distribution, once per process
    (reading a distribution's metadata parses its file: ~10 ms, for each of a sweep's configs)."""
    if dist is not None and not _is_editable(dist):
        return f"{dist.metadata['Name']} {dist.version}"
    where = getattr(sys.modules.get(top), "__file__", None)
    commit = _git_head(Path(where).resolve().parent) if where else None
    said = f"{dist.metadata['Name']}, editable" if dist is not None else "not installed"
    return said + (f", git commit {commit}" if commit else "")


def provenance(created: float | None = None) -> dict:
    """Where and when (``created``: seconds since the epoch; None: now) a result was made."""
    return {"created": time.strftime("%Y-%m-%d %H:%M:%S %Z", time.localtime(created)), "git_commit": git_commit(),
            "machine": f"{platform.machine()}, {platform.system()}", **_versions()}


def origin_text(origin: dict) -> str:
    """``mylab.glr (mylab 0.1)`` of a :func:`bench.registry.origin`."""
    return f"{origin['module']} ({origin['distribution']})"
