"""Where a result came from: versions, git commit, machine, time."""

from __future__ import annotations

import platform
import time
from pathlib import Path

#: the label of the report's Provenance row that holds the wall time of the last run's units
#: (written by bench.report, read back from a committed report by bench.docs)
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


def git_commit() -> str:
    import subprocess
    root = Path(__file__).resolve().parent.parent
    try:
        out = subprocess.run(["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, timeout=5)
        # the committed reports are outputs, not code: their changes do not make the code dirty
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no",
                                "--", ".", ":!reports"], capture_output=True, text=True, timeout=5)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    if out.returncode != 0:
        return "unknown (not a git checkout)"
    return out.stdout.strip() + (" (with uncommitted changes)" if dirty.stdout.strip() else "")


def provenance() -> dict:
    return {"created": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "git_commit": git_commit(),
            "machine": f"{platform.machine()}, {platform.system()}", **_versions()}
