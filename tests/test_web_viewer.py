"""`bench view --web` the way a user sees it: a headless Chromium loads the served viewer
at 1280 x 800 and its screenshot shows the default view, the summary's first sub-tab: as
many plot panels side by side as the recording's blueprint puts there, each with every
method config's colour (its curve, or at least its legend entry) and none filled like a
bar chart, not the loading or welcome screen. Skipped where Chromium is absent.

The viewer draws long after the page's load event (its Wasm compiles, then the recording
streams, with a software rasterizer), so the test drives Chromium over the DevTools
protocol (``--remote-debugging-pipe``) and takes a screenshot every ``POLL_S`` until one
shows the summary, for at most ``VIEWER_TIMEOUT_S``.
"""

import base64
import fcntl
import io
import json
import os
import select
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from radarbench.bench.recording.layout import PALETTE
from conftest import scaled

#: The browser: Debian's ``chromium`` unless ``BENCH_TEST_CHROMIUM`` names another
#: (Chromium's ``chromium-headless-shell`` does as well).
CHROMIUM = os.environ.get("BENCH_TEST_CHROMIUM", "/usr/bin/chromium")
ROOT = Path(__file__).resolve().parent.parent
#: Seconds the viewer gets to show the summary (its Wasm compiles and the recording streams
#: with a software rasterizer on a busy machine; tests/conftest.py's scaled()); screenshots are taken every POLL_S and
#: the test goes on at the first that shows it.
VIEWER_TIMEOUT_S = scaled(600)
POLL_S = 1.0
#: Pixels of each method config's colour in each plot panel of the summary: a legend entry's
#: dot is about 50 (measured), a line 2 px wide across a panel a few thousand at most.
PANEL_MIN_PIXELS = 30
#: More pixels of one colour in a panel than a line can have: a bar (tens of thousands).
PANEL_MAX_PIXELS = 6000
#: The plots' rows in a 1280 x 800 screenshot: below the top bar and the two tab bars (the
#: summary's and its task's) and the views' titles, above the time panel's play bar.
PLOT_ROWS = slice(120, 760)
#: The window a newcomer's laptop gives the viewer (legible at 1280 x 800).
VIEWPORT = (1280, 800)

pytestmark = pytest.mark.skipif(not os.path.exists(CHROMIUM), reason=f"{CHROMIUM} is absent (apt-get install chromium)")


def _free_port_pair() -> int:
    """A port P such that P and P + 1 are free on 127.0.0.1."""
    for _ in range(50):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        if port >= 65534:
            continue
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port + 1))
            except OSError:
                continue
        return port
    raise RuntimeError("no free pair of ports")


def _listen_addresses(port: int) -> set[str]:
    """Local addresses (hex, /proc/net/tcp*) with a listening socket on ``port``."""
    out = set()
    for table in ("/proc/net/tcp", "/proc/net/tcp6"):
        if not os.path.exists(table):
            continue
        for line in Path(table).read_text().splitlines()[1:]:
            fields = line.split()
            address, hex_port = fields[1].rsplit(":", 1)
            if int(hex_port, 16) == port and fields[3] == "0A":      # 0A: LISTEN
                out.add(address)
    return out


def _hue_pixels(rgb: np.ndarray, colors) -> list[int]:
    """Per colour, the saturated pixels of its hue (±15°) in the image ``rgb`` (H, W, 3).
    The viewer draws lines and legend dots anti-aliased and bars lighter than their colour,
    so hues, not exact RGB values, are counted."""
    import colorsys

    from PIL import Image

    hsv = np.asarray(Image.fromarray(rgb).convert("HSV"), float)
    hue, sat, val = hsv[..., 0] * 360 / 255, hsv[..., 1] / 255, hsv[..., 2] / 255
    vivid = (sat > 0.35) & (val > 0.35)
    counts = []
    for color in colors:
        target = colorsys.rgb_to_hsv(*(c / 255 for c in color))[0] * 360
        counts.append(int((vivid & (np.abs((hue - target + 180) % 360 - 180) < 15)).sum()))
    return counts


def panel_pixels(png: bytes, panels: int, colors) -> list[list[int]]:
    """Per plot panel (``panels`` side by side across the window), :func:`_hue_pixels` of
    ``colors`` in its plot rows (a margin at each side left out: the panels' borders)."""
    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))[PLOT_ROWS]
    edges = np.linspace(0, rgb.shape[1], panels + 1).astype(int)
    return [_hue_pixels(rgb[:, a + 5:b - 5], colors) for a, b in zip(edges[:-1], edges[1:])]


@pytest.fixture
def served(small_run, tmp_path):
    """``bench view --web`` serving a copy of the small sweep's run: its URL and port."""
    run = tmp_path / "run"
    shutil.copytree(small_run, run, symlinks=True)
    port = _free_port_pair()
    proc = subprocess.Popen([sys.executable, "-m", "radarbench.bench", "view", str(run), "--web", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        url, deadline = None, time.monotonic() + scaled(300)
        while url is None and time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            if line.strip().startswith("http://"):
                url = line.strip()
        assert url is not None, proc.stderr.read() if proc.poll() is not None else "no URL printed"
        yield url, port
    finally:
        proc.terminate()                 # SIGTERM: bench stops the server as on Ctrl-C
        assert proc.wait(timeout=scaled(300)) == 0
    assert not _listen_addresses(port) and not _listen_addresses(port + 1)   # nothing left listening


def test_web_viewer_serves_on_loopback_with_webgl(served):
    url, port = served
    assert url == (f"http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{port + 1}%2Fproxy"
                   "&renderer=webgl")
    loopback = {"0100007F", "00000000000000000000000001000000"}          # 127.0.0.1, ::1
    for p in (port, port + 1):
        addresses = _listen_addresses(p)
        assert addresses and addresses <= loopback, (p, addresses)


class DevTools:
    """Chromium driven over the DevTools protocol through ``--remote-debugging-pipe``: the
    browser reads commands on its fd 3 and writes replies and events on its fd 4, each a
    JSON message ended by a NUL byte."""

    def __init__(self, args: list[str]):
        to_browser, self._to_browser = os.pipe()
        self._from_browser, from_browser = os.pipe()
        # numbered 10 or above, so that moving them onto 3 and 4 in the child overwrites neither
        child_in, child_out = (fcntl.fcntl(fd, fcntl.F_DUPFD_CLOEXEC, 10) for fd in (to_browser, from_browser))
        for fd in (to_browser, from_browser):
            os.close(fd)

        def pipes_on_3_and_4():                   # in the child, before exec
            os.dup2(child_in, 3)
            os.dup2(child_out, 4)

        # close_fds=False keeps 3 and 4 (dup2 made them inheritable); every other pipe or
        # file Python opened is close-on-exec
        self.proc = subprocess.Popen([CHROMIUM, "--remote-debugging-pipe", *args], stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, close_fds=False,
                                     preexec_fn=pipes_on_3_and_4)
        for fd in (child_in, child_out):
            os.close(fd)
        self._received, self._last_id = b"", 0

    def call(self, method: str, session: str | None = None, timeout: float | None = None, **params) -> dict:
        """Send one command (to the page of ``session``, or to the browser) and return its
        result; the events that arrive meanwhile are dropped."""
        self._last_id += 1
        message = {"id": self._last_id, "method": method, "params": params}
        if session is not None:
            message["sessionId"] = session
        os.write(self._to_browser, json.dumps(message).encode() + b"\0")
        deadline = time.monotonic() + (scaled(300) if timeout is None else timeout)
        while True:
            while b"\0" in self._received:
                raw, self._received = self._received.split(b"\0", 1)
                reply = json.loads(raw)
                if reply.get("id") == self._last_id:
                    assert "error" not in reply, (method, reply["error"])
                    return reply["result"]
            left = deadline - time.monotonic()
            assert left > 0 and select.select([self._from_browser], [], [], left)[0], f"no reply to {method}"
            chunk = os.read(self._from_browser, 1 << 20)
            assert chunk, f"Chromium closed the DevTools pipe (exit code {self.proc.poll()})"
            self._received += chunk

    def close(self) -> None:
        try:
            self.call("Browser.close", timeout=scaled(60))
        except (AssertionError, OSError):
            pass                                  # already gone: the wait below reaps it
        try:
            self.proc.wait(timeout=scaled(300))
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        for fd in (self._to_browser, self._from_browser):
            os.close(fd)


def _summary_panels(run: Path) -> int:
    """The views of the summary's first sub-tab, which the viewer opens on, as the
    recording's blueprint lays them out (side by side: one task, one scenario config)."""
    from tests.rrd_blueprint import HORIZONTAL, read_blueprint

    blueprint = read_blueprint(run / "recording.rrd")
    summary = blueprint.tab("summary")
    first = blueprint.child(summary.contents[0])
    assert getattr(first, "kind", None) == HORIZONTAL, first
    return len(blueprint.views_under(first))


@pytest.mark.slow
def test_web_viewer_screenshot_shows_the_summary(small_run, served, tmp_path):
    url, _ = served
    panels = _summary_panels(small_run)
    assert panels == 2                            # the detection task's Pd and mean delay
    # The small sweep's three method configs are one task's: PALETTE's first three colours
    # (bench.recording.layout.method_colors), in every panel's legend and curves. The loading
    # screen and the welcome page hold none.
    colors = PALETTE[:3]
    profile = tmp_path / "chromium-profile"
    profile.mkdir()
    browser = DevTools(["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                        "--disable-background-networking", "--disable-component-update", "--disable-sync",
                        f"--user-data-dir={profile}", f"--window-size={VIEWPORT[0]},{VIEWPORT[1]}", "about:blank"])
    try:
        # a size on Target.createTarget is refused by Debian's Chromium ("Target position can
        # only be set for new windows"): the page's viewport is sized once attached
        target = browser.call("Target.createTarget", url=url)["targetId"]
        session = browser.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        browser.call("Emulation.setDeviceMetricsOverride", session, width=VIEWPORT[0], height=VIEWPORT[1],
                     deviceScaleFactor=1, mobile=False)
        deadline = time.monotonic() + VIEWER_TIMEOUT_S
        while True:
            png = base64.b64decode(browser.call("Page.captureScreenshot", session, format="png")["data"])
            counts = panel_pixels(png, panels, colors)
            if min(map(min, counts)) >= PANEL_MIN_PIXELS or time.monotonic() > deadline:
                break
            time.sleep(POLL_S)
    finally:
        browser.close()
    shot = tmp_path / "viewer.png"
    shot.write_bytes(png)                         # the last screenshot, for whoever reads a failure
    assert min(map(min, counts)) >= PANEL_MIN_PIXELS, (counts, str(shot))   # every config in every panel
    assert max(map(max, counts)) <= PANEL_MAX_PIXELS, (counts, str(shot))   # lines, not bars
