"""Numbers identical on any x86-64 machine: the quick preset's summary against the digest
committed in ``tests/quick_summary.sha256`` (docs/architecture.md, 'Portable numbers').
After a change that moves numbers on purpose: ``python -m tests.quick_hash --update``."""

import pandas as pd
import pytest

from radarbench import bench
from tests.quick_hash import committed_digest, library_versions, run_quick, summary_digest


def test_the_portable_target_precedes_numpy():
    """The test process imported numpy under bench's environment (conftest imports bench first)."""
    assert bench.portable_numpy()


def test_the_digest_ignores_timing_and_sees_a_last_bit(tmp_path):
    rows = pd.DataFrame({"scenario": ["s", "s"], "method": ["m", "m"], "config": ["m", "m"], "snr_db": [0.0, 1.0],
                         "pd": [0.5, 0.25], "seconds_per_trial": [1.0, 2.0]})
    paths = [tmp_path / f"{i}.csv" for i in range(3)]
    rows.to_csv(paths[0], index=False)
    rows.assign(seconds_per_trial=[3.0, 4.0]).to_csv(paths[1], index=False)
    rows.assign(pd=[0.5, float.fromhex("0x1.0000000000001p-2")]).to_csv(paths[2], index=False)
    first, timing, last_bit = map(summary_digest, paths)
    assert first == timing != last_bit


@pytest.mark.slow
def test_quick_preset_summary_matches_the_committed_digest(tmp_path):
    committed, versions = committed_digest()
    if versions != library_versions():
        pytest.skip(f"the digest holds for {versions}, this environment has {library_versions()}: "
                    "a library release may move a last bit; python -m tests.quick_hash --update after checking")
    digest = summary_digest(run_quick(tmp_path / "quick"))
    assert digest == committed, (
        "the quick preset's summary differs from tests/quick_summary.sha256: a number moved (this machine, "
        "or a change); if the change is meant, update it with: python -m tests.quick_hash --update")
