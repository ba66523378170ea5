"""benchmarks/loop.py, the edit-run-read loop's measurement: the CPU time of a command's whole
process tree (an orphaned grandchild included), what a run says about its units, and the
documentation pages that show its record (bench/cli/docs.py). Nothing here times a run."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

from radarbench.bench.cli.docs import LOOP_REPORT, MEASURED_MARKER, durations, fill_measured, loop_record

from conftest import scaled

REPO = Path(__file__).resolve().parent.parent
LOOP = REPO / "benchmarks" / "loop.py"


def _loop_module():
    spec = importlib.util.spec_from_file_location("loop_benchmark", LOOP)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module                  # its dataclasses resolve their annotations there
    spec.loader.exec_module(module)
    return module


#: a command whose only CPU work is in a grandchild it leaves running (as the forkserver's workers)
ORPHANING = """
import subprocess, sys
subprocess.Popen([sys.executable, "-c", "import time\\nt = time.process_time()\\nwhile time.process_time() - t < 0.6: pass"])
"""

#: run in a fresh process: the subreaper setting is the process's own, not the test runner's
MEASURE = """
import importlib.util, json, sys
from pathlib import Path
spec = importlib.util.spec_from_file_location("loop_benchmark", sys.argv[1])
loop = sys.modules[spec.name] = importlib.util.module_from_spec(spec)
spec.loader.exec_module(loop)
loop.become_subreaper()
m = loop.run_timed("probe", "probe", [sys.executable, "-c", sys.argv[2]], None, Path.cwd(), Path(sys.argv[3]))
print(json.dumps({"cpu_s": m.cpu_s, "exit_code": m.exit_code, "note": m.note}))
"""


def test_the_cpu_of_a_grandchild_its_parent_left_running_is_counted(tmp_path):
    """The command exits at once; its grandchild burns 0.6 s of CPU after that. As its subreaper
    the script reaps it and counts its CPU (``/usr/bin/time`` would count none of it)."""
    done = subprocess.run([sys.executable, "-c", MEASURE, str(LOOP), ORPHANING, str(tmp_path / "log")],
                          capture_output=True, text=True, timeout=scaled(), check=True)
    measured = json.loads(done.stdout)
    assert measured["exit_code"] == 0 and measured["note"] == ""
    assert measured["cpu_s"] >= 0.6


def test_unit_counts_read_what_a_run_says():
    loop = _loop_module()
    phases = ("bench: warm-up: done, 3/3 units in 0:36\nbench: calibration: done, 40/40 units in 0:10\n"
              "bench: evaluation: 0/4 units (0%), 0:00 elapsed\nbench: evaluation: done, 4/4 units in 0:01\n")
    assert loop.unit_counts(phases) == (44, None)                   # the warm-up's units are not results
    assert loop.unit_counts("Nothing to run: all 40 units stored in runs/quick\n") == (0, None)
    said = ("bench: evaluation: done, 3/3 units in 0:01\n"
            "units: 30 reused from runs/quick, 7 from the results cache, 3 computed\n"
            "bench: report: done, 16/16 sections (figures: 6 drawn, 26 reused) in 0:09\n")
    assert loop.unit_counts(said) == (3, 37)                        # the figures' reuse is not the units'
    assert loop.unit_counts("no word about units\n") == (None, None)


def test_the_edit_names_a_method_of_the_maneuver_detection_preset():
    import tomllib

    loop = _loop_module()
    key = loop.edit_key(*loop.EDIT)
    index = int(key.split(".")[1])
    preset = tomllib.loads((REPO / "bench" / "presets" / "maneuver-detection.toml").read_text())
    assert preset["methods"][index]["name"] == loop.EDIT[0]
    assert key.endswith(f".params.{loop.EDIT[1]}={loop.EDIT[2]}")


def _record(loop, suite_s):
    steps = [loop.Measured("first", "first", "bench run --preset quick", 150.4, 201.2, 0, 40, None, "",
                           (1.5, 1.0, 0.5), (2.0, 1.2, 0.6)),
             loop.Measured("warm", "warm", "bench run --preset quick", 31.6, 40.7, 0, 40, 0),
             loop.Measured("noop", "noop", "bench run --preset quick", 1.2, 1.1, 0, 0, None)]
    fake = type("Fake", (), {"results": steps, "checks": {"a check": "yes"}})
    return loop.document(fake, suite_s, 2, True, "0123abcd")


def test_the_docs_show_the_loop_records_durations(tmp_path):
    """The Getting-started marker and the presets page take the durations from the committed
    loop.md's JSON (never typed); without it they say how to measure them."""
    loop = _loop_module()
    assert "Not measured yet" in durations(tmp_path, "getting-started.md")
    (tmp_path / LOOP_REPORT).parent.mkdir(parents=True)
    (tmp_path / LOOP_REPORT).write_text(loop.markdown(_record(loop, 1234.5)))
    assert loop_record(tmp_path)["test_suite_wall_s"] == 1234.5
    page = fill_measured(f"# Getting started\n\n{MEASURED_MARKER}\n\nThen:\n", tmp_path, "getting-started.md")
    assert MEASURED_MARKER not in page
    for cells in ("| 150 s | 201 s | 1.5, 1, 0.5 |", "| 32 s | 41 s |", "| 1 s | 1 s |", "| 1234 s | – | – |"):
        assert cells in " ".join(page.split()), cells
    assert "[reports/perf/loop.md](reports/perf/loop.md)" in page
    assert fill_measured("# no marker\n", tmp_path, "x.md") == "# no marker\n"


def _report(folder: Path, rows: dict[str, float]) -> Path:
    folder.mkdir()
    table = "\n".join(f"| `{config}` | {ms:.3g} | 100 | {ms / 10:.3g} |" for config, ms in rows.items())
    (folder / "report.md").write_text("# Report\n\n## Runtime\n\n![runtime](figures/runtime.png)\n\n"
                                      "| config | CPU ms per trial | trials run | total CPU seconds |\n"
                                      f"|---|---|---|---|\n{table}\n\n## Provenance\n\n| `x` | 999 |\n")
    return folder / "report.md"


def test_the_runtime_check_compares_every_config_of_the_first_and_warm_reports_either_way(tmp_path):
    loop = _loop_module()
    warm = _report(tmp_path / "warm", {"cv-kf": 0.5, "imm-cv-ca[window=3]": 2.0})
    assert loop.runtime_table(warm) == {"cv-kf": 0.5, "imm-cv-ca[window=3]": 2.0}     # the next section's rows left out
    close = _report(tmp_path / "close", {"cv-kf": 0.9, "imm-cv-ca[window=3]": 1.2})
    assert loop.runtimes_agree(close, warm).startswith("yes (max ratio 1.80 for cv-kf")
    compiled = _report(tmp_path / "compiled", {"cv-kf": 0.5, "imm-cv-ca[window=3]": 2410.0})
    assert loop.runtimes_agree(compiled, warm).startswith("no (max ratio 1205.00 for imm-cv-ca[window=3]")
    faster = _report(tmp_path / "faster", {"cv-kf": 0.2, "imm-cv-ca[window=3]": 2.0})
    assert loop.runtimes_agree(faster, warm).startswith("no (max ratio 2.50 for cv-kf")
    assert loop.runtimes_agree(tmp_path / "none" / "report.md", warm).startswith("no runtime table")


def test_the_report_share_reads_the_build_cpu_the_run_recorded(tmp_path):
    import sqlite3
    loop = _loop_module()
    store = tmp_path / "results.sqlite"
    with sqlite3.connect(store) as db:
        db.execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT)")
    run = loop.Measured("warm", "warm", "bench run", 10.0, 20.0, 0)
    assert loop.report_share(store, run) == "not recorded by this bench"
    with sqlite3.connect(store) as db:
        db.execute("INSERT INTO meta VALUES (?, ?)", (loop.REPORT_CPU, repr(2.9)))
    assert loop.report_share(store, run) == "yes (2.9 s of 20.0 s, 14%)"
    with sqlite3.connect(store) as db:
        db.execute("UPDATE meta SET value = ? WHERE key = ?", (repr(3.1), loop.REPORT_CPU))
    assert loop.report_share(store, run) == "no (3.1 s of 20.0 s, 16%)"
    assert loop.report_share(tmp_path / "none.sqlite", run) == "no none.sqlite"


def test_the_loop_reads_the_key_the_report_records():
    from radarbench.bench.report import REPORT_CPU
    assert _loop_module().REPORT_CPU == REPORT_CPU
