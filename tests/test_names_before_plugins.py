"""A sweep's unknown plugin name is answered before the plugins are imported, with the
registry's own line, once a process that imported them kept their names
(bench.sweep.listing.cached_names)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from radarbench.bench.sweep.config import check_names
from radarbench.bench.errors import ConfigError
from conftest import scaled

#: ``bench`` in a process that then says whether it imported NumPy or started the forkserver
PROBE = """
import sys
from multiprocessing import forkserver
from radarbench.bench.cli import main
code = main(sys.argv[1:])
heavy = "numpy" in sys.modules or forkserver._forkserver._forkserver_pid is not None
print(f"probe: heavy={heavy}", file=sys.stderr)
sys.exit(code)
"""

SWEEP = """
name = "names"
scenario = "SCENARIO"
trials = 4
snr_db = [0]

[[methods]]
name = "cusum"

[[methods]]
name = "METHOD"
"""


def _bench(tmp_path, *args):
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    done = subprocess.run([sys.executable, "-c", PROBE, *map(str, args)], env=env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=scaled())
    lines = done.stderr.splitlines()
    assert done.returncode == 2 and len(lines) == 2 and lines[1].startswith("probe: "), done.stderr
    return lines[0], lines[1] == "probe: heavy=True"


@pytest.mark.parametrize("scenario, method, extra, said", [
    ("cv-turn-cv", "cusumm", (), "error: sweep.toml: methods[1].name: unknown method 'cusumm' (did you mean 'cusum'?"),
    ("cv-turn-cvv", "cusum", (), "error: sweep.toml: scenario: unknown scenario 'cv-turn-cvv' (did you mean"),
    ("cv-turn-cv", "cusum", ("--methods", "glrr"), "error: --methods: "),
])
def test_an_unknown_name_is_answered_without_the_plugins_once_their_names_are_kept(tmp_path, scenario, method,
                                                                                   extra, said):
    sweep = tmp_path / "sweep.toml"
    sweep.write_text(SWEEP.replace("SCENARIO", scenario).replace("METHOD", method))
    first, heavy = _bench(tmp_path, "run", sweep.name, "--out", tmp_path / "out", *extra)
    assert heavy and first.startswith(said), first             # the registry's answer, its names kept
    again, heavy = _bench(tmp_path, "run", sweep.name, "--out", tmp_path / "out", *extra)
    assert not heavy and again == first
    assert not (tmp_path / "out").exists()


def test_names_are_checked_in_the_order_the_sweep_is_read_and_optional_methods_are_not():
    known = {("scenario", "cv-turn-cv"), ("method", "cusum")}

    def absent(kind: str, name: str) -> str:
        return "" if (kind, name) in known else f"unknown {kind} {name!r}"
    check_names({"scenario": "cv-turn-cv", "methods": [{"name": "cusum"}, {"name": "gone", "optional": True}]}, absent)
    with pytest.raises(ConfigError, match=r"^scenarios\[1\]\.name: unknown scenario 'x'$"):
        check_names({"scenarios": [{"name": "cv-turn-cv"}, {"name": "x"}], "methods": [{"name": "y"}]}, absent)
    with pytest.raises(ConfigError, match=r"^methods\[1\]\.name: unknown method 'y'$"):
        check_names({"scenario": "cv-turn-cv", "methods": [{"name": "cusum"}, {"name": "y"}]}, absent)
    check_names({"scenario": 3, "methods": [{"name": ["cusum"]}]}, absent)      # not names: parse_sweep's to refuse
