"""The quick preset's numbers as one digest, committed in ``quick_summary.sha256``
(docs/architecture.md, 'Portable numbers'): any x86-64 machine must reproduce it.

The digest covers summary.csv's numeric columns, except the timing ones (``seconds*``),
row by row in (scenario, config, SNR) order, each value as its float64 bytes, and leaves
out the configs of optional methods (an extra's own version decides their numbers).
A change that moves a number on purpose (a method, a scenario, numpy/scipy/numba) updates
the committed digest with one command, run from the repository root:

    python -m tests.quick_hash --update
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.resources
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd

DIGEST_FILE = Path(__file__).with_name("quick_summary.sha256")
ROW_KEYS = ["scenario", "config", "snr_db"]


def optional_methods() -> set[str]:
    """Methods the quick preset marks ``optional`` (behind an extra)."""
    preset = tomllib.loads((importlib.resources.files("radarbench.bench") / "presets" / "quick.toml").read_text())
    return {m["name"] for m in preset["methods"] if m.get("optional")}


def summary_digest(summary_csv: Path) -> str:
    """SHA-256 of the canonical serialisation of ``summary_csv``'s numbers."""
    summary = pd.read_csv(summary_csv)           # the default parser round-trips floats exactly (pandas 3)
    summary = summary[~summary.method.isin(optional_methods())].sort_values(ROW_KEYS, kind="stable")
    numeric = sorted(c for c in summary.select_dtypes("number").columns if not c.startswith("seconds"))
    digest = hashlib.sha256()
    digest.update("\n".join(summary[ROW_KEYS].astype(str).agg("|".join, axis=1)).encode())
    for column in numeric:
        values = summary[column].to_numpy(dtype="<f8")
        values = np.where(np.isnan(values), np.nan, values)          # one NaN bit pattern
        digest.update(column.encode() + b"\0" + values.tobytes())
    return digest.hexdigest()


def run_quick(out: Path) -> Path:
    """Run the quick preset into ``out``; its summary.csv."""
    subprocess.run([sys.executable, "-m", "radarbench.bench", "run", "--preset", "quick", "--out", str(out), "--quiet"],
                   check=True)
    return out / "summary.csv"


#: the libraries whose versions the digest holds for (a new release may move a last bit by
#: design: their versions are part of a result's identity, docs/architecture.md 'Identities')
LIBRARIES = ("numpy", "scipy", "numba")


def library_versions() -> str:
    """``numpy=X scipy=Y numba=Z`` of this environment."""
    from importlib.metadata import version
    return " ".join(f"{name}={version(name)}" for name in LIBRARIES)


def committed_digest() -> tuple[str, str]:
    """The committed digest and the library versions it was computed with."""
    digest, _, versions = DIGEST_FILE.read_text().strip().partition(" ")
    return digest, versions


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.quick_hash", description=__doc__.split("\n\n")[0])
    parser.add_argument("--update", action="store_true", help="write the digest to " + DIGEST_FILE.name)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        digest = summary_digest(run_quick(Path(tmp) / "quick"))
    if args.update:
        DIGEST_FILE.write_text(f"{digest} {library_versions()}\n")
    print(digest)
    return 0


if __name__ == "__main__":
    sys.exit(main())
