"""Each case found, as a regression test.

* a sweep's file name and the ``--out`` path holding a backtick and markup (the
  real console script, so the command and the recording's paths are the CLI's);
* report.html's Content-Security-Policy: every inline script hashed (plotly.js too),
  nothing loaded from anywhere;
* a plugin cannot be named with markup; its docstring reaches ``bench list`` with its
  control characters escaped;
* the ``bench list`` cache: a symlink planted in its folder (at the listing's name or
  at the temporary name it used to take) is never written through, a linked or
  shared cache folder is not used, a forged entry is printed escaped.

The description, labels, parameter strings and a plugin's error text and reason are
driven by tests/property/test_hostile_markup.py.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import re
from dataclasses import dataclass

import html5lib
import pytest

from radarbench.bench.sweep import listing
from radarbench.bench import registry
from radarbench.bench.core import MANEUVER_DETECTION, Method

ESCAPES = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f\u202a-\u202e\u2066-\u2069]")


# ------------------------------------------------------------------ file name and --out through the CLI

@pytest.mark.slow
def test_a_backtick_in_the_file_name_or_out_path_breaks_no_code_span(write_sweep, bench_cli, tmp_path):
    name = "s`<img src=x onerror=alert(1)>.toml"
    out = "o`<svg onload=alert(2)>"
    sweep = write_sweep(name, trials=4, snr="[0]", chunk=4, h0=20)
    proc = bench_cli("run", sweep.name, "--out", out, "--workers", 1, "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / out / "report.html").read_text()
    doc = html5lib.HTMLParser(namespaceHTMLElements=False).parse(page)
    tags = {el.tag for el in doc.iter()}
    assert "svg" not in tags and all(img.get("src", "").startswith("data:image/png;base64,")
                                     for img in doc.iter("img"))
    assert not [(el.tag, k) for el in doc.iter() for k in el.attrib if k.startswith("on")]
    codes = ["".join(el.itertext()) for el in doc.iter("code")]
    assert name in codes                                               # provenance: the sweep file, whole
    assert any(c.startswith("bench run") and name in c and out in c for c in codes)      # the command, whole
    assert f"bench view {out}" in codes and f"rerun {out}/recording.rrd" in codes
    md = (tmp_path / out / "report.md").read_text()
    assert f"``{name}``" in md                                         # a fence longer than the name's backticks


# ------------------------------------------------------------------ the policy of report.html

def test_every_inline_script_of_report_html_is_hashed_in_its_policy(small_run):
    page = (small_run / "report.html").read_text()
    head = page[:page.index("<style>")]
    policy = re.search(r'<meta http-equiv="Content-Security-Policy" content="([^"]+)">', head).group(1)
    scripts = re.findall(r"<script\b[^>]*>(.*?)</script>", page, re.S)
    assert len(scripts) >= 3 and any("Plotly.newPlot" in s for s in scripts)     # plotly.js and its figures
    hashes = {f"'sha256-{base64.b64encode(hashlib.sha256(s.encode()).digest()).decode()}'" for s in scripts}
    directives = dict(d.strip().split(" ", 1) for d in policy.split(";"))
    assert directives["default-src"] == "'none'" and directives["img-src"] == "data:"
    assert set(directives["script-src"].split()) == hashes                        # each script, nothing else
    assert "http" not in policy and "unsafe-eval" not in policy
    assert page.count("<script") == len(scripts)                                 # no script outside these


# ------------------------------------------------------------------ plugins' names and docstrings

class Loud(Method):
    """Shouts \x1b[2J\x1b]0;owned\x07 and \u202egnp.exe <script>alert(1)</script>."""

    name = "loud"
    task = MANEUVER_DETECTION

    @dataclass(frozen=True)
    class Params:
        pass


def test_a_plugin_named_with_markup_is_refused():
    bad = type("Bad", (Loud,), {"name": "<script>alert(1)</script>"})
    with pytest.raises(registry.PluginError, match="expected letters, digits"):
        registry.register_method(bad)
    assert "<script>alert(1)</script>" not in registry.methods()


def test_a_plugin_docstring_reaches_bench_list_escaped():
    registry.register_method(Loud)
    try:
        text = listing.plugin_listing()                 # in-process: the registry, not the cache
    finally:
        registry._METHODS.pop("loud", None)
    line = next(x for x in text.splitlines() if x.split()[:1] == ["loud"])
    assert not ESCAPES.search(text)
    assert "\\x1b[2J\\x1b]0;owned\\x07" in line and "\\u202egnp.exe" in line


# ------------------------------------------------------------------ the bench list cache

@pytest.fixture
def cache(tmp_path, monkeypatch):
    """``bench list``'s cache as a fresh process sees it: plugins not yet imported, a
    fixed fingerprint, the listing itself a known text."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    monkeypatch.setattr(registry, "discovered", lambda: False)
    monkeypatch.setattr(listing, "fingerprint", lambda: "f" * 32)
    monkeypatch.setattr(listing, "_render", lambda verbose: "tasks:\n  fresh listing")
    return tmp_path / "xdg" / "radar-maneuver-bench"


def test_the_cache_folder_is_private(cache):
    assert listing.plugin_listing() == "tasks:\n  fresh listing"
    assert (cache.stat().st_mode & 0o777) == 0o700
    written = list(cache.iterdir())
    assert [p.name for p in written] == [f"list-{'f' * 32}.json"] and (written[0].stat().st_mode & 0o077) == 0


@pytest.mark.parametrize("planted", [f"list-{'f' * 32}.json", f".list-{'f' * 32}.json.{{pid}}.tmp"],
                         ids=["final name", "old pid-named temporary"])
def test_a_symlink_planted_in_the_cache_is_not_written_through(cache, tmp_path, planted):
    planted = planted.format(pid=os.getpid())      # the old predictable name; ids fixed for xdist
    victim = tmp_path / "victim"
    victim.write_text("precious")
    cache.mkdir(parents=True, mode=0o700)
    (cache / planted).symlink_to(victim)
    assert listing.plugin_listing() == "tasks:\n  fresh listing"
    assert victim.read_text() == "precious"
    final = cache / f"list-{'f' * 32}.json"
    assert not final.is_symlink() and json.loads(final.read_text())["text"] == "tasks:\n  fresh listing"


def test_a_linked_or_shared_cache_folder_is_not_used(cache, tmp_path):
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    cache.parent.mkdir()
    cache.symlink_to(elsewhere)
    assert listing.plugin_listing() == "tasks:\n  fresh listing"
    assert not list(elsewhere.iterdir())                            # nothing written through the link
    cache.unlink()
    cache.mkdir()
    cache.chmod(0o777)                                             # anyone may write: not a private cache
    (cache / f"list-{'f' * 32}.json").write_text(json.dumps({"text": "forged"}))
    assert listing.plugin_listing() == "tasks:\n  fresh listing"


def test_a_forged_cache_entry_is_printed_escaped(cache, capsys):
    from radarbench.bench.cli import main
    cache.mkdir(parents=True, mode=0o700)
    forged = "tasks:\n  \x1b[2J\x1b]0;owned\x07 \x9b31m \u202etxt.exe \x00"
    (cache / f"list-{'f' * 32}.json").write_text(json.dumps({"text": forged}))
    assert main(["list"]) == 0
    out = capsys.readouterr().out
    assert not ESCAPES.search(out)
    assert "\\x1b[2J\\x1b]0;owned\\x07 \\x9b31m \\u202etxt.exe \\x00" in out
