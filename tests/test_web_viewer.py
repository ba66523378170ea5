"""`bench view --web` the way a user sees it: a headless Chromium loads the served viewer
and its screenshot shows the default view (the summary's bar charts in the methods'
colours), not the loading or welcome screen. Skipped where Chromium is absent.

Chromium's ``--screenshot`` fires at the page's load event, long before the Wasm viewer
has fetched and drawn the recording; so the viewer is opened in an iframe of a page
whose load event waits for an image served after ``LOAD_WAIT_S`` seconds.
"""

import http.server
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from bench.recording.layout import PALETTE

CHROMIUM = "/usr/bin/chromium"
ROOT = Path(__file__).resolve().parent.parent
#: Seconds the page holds its load event: the viewer's Wasm compiles and the recording
#: streams with a software rasterizer on a busy machine.
LOAD_WAIT_S = 120

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


def _holding_page(url: str, wait_s: float) -> tuple[http.server.ThreadingHTTPServer, int]:
    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            if self.path.startswith("/hold"):
                time.sleep(wait_s)
                body, kind = b"GIF89a\x01\x00\x01\x00\x00\x00\x00;", "image/gif"
            else:
                body = (f'<html><body style="margin:0"><iframe src="{url}" style="border:0;width:100vw;'
                        f'height:100vh"></iframe><img src="/hold" style="display:none"></body></html>').encode()
                kind = "text/html"
            self.send_response(200)
            self.send_header("Content-Type", kind)
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Page)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, server.server_address[1]


def _hue_pixels(png: Path, colors) -> list[int]:
    """Per colour, the saturated pixels of its hue (±15°) in the viewport (the sidebars and
    the top bar cropped away). The viewer draws bars lighter than their colour, so hues,
    not exact RGB values, are counted."""
    import colorsys

    from PIL import Image

    hsv = np.asarray(Image.open(png).convert("RGB").resize((1600, 1000)).convert("HSV"), float)[80:850, 230:1020]
    hue, sat, val = hsv[..., 0] * 360 / 255, hsv[..., 1] / 255, hsv[..., 2] / 255
    vivid = (sat > 0.35) & (val > 0.35)
    counts = []
    for color in colors:
        target = colorsys.rgb_to_hsv(*(c / 255 for c in color))[0] * 360
        counts.append(int((vivid & (np.abs((hue - target + 180) % 360 - 180) < 15)).sum()))
    return counts


@pytest.fixture
def served(write_sweep, tmp_path):
    run = tmp_path / "run"
    done = subprocess.run([sys.executable, "-m", "bench", "run", str(write_sweep()), "--out", str(run),
                           "--workers", "1", "--quiet"], capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    port = _free_port_pair()
    proc = subprocess.Popen([sys.executable, "-m", "bench", "view", str(run), "--web", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        url, deadline = None, time.monotonic() + 90
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
        assert proc.wait(timeout=30) == 0
    assert not _listen_addresses(port) and not _listen_addresses(port + 1)   # nothing left listening


def test_web_viewer_serves_on_loopback_with_webgl(served):
    url, port = served
    assert url == (f"http://127.0.0.1:{port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{port + 1}%2Fproxy"
                   "&renderer=webgl")
    loopback = {"0100007F", "00000000000000000000000001000000"}          # 127.0.0.1, ::1
    for p in (port, port + 1):
        addresses = _listen_addresses(p)
        assert addresses and addresses <= loopback, (p, addresses)


def test_web_viewer_screenshot_shows_the_summary(served, tmp_path):
    url, _ = served
    server, page_port = _holding_page(url, LOAD_WAIT_S)
    shot = tmp_path / "viewer.png"
    profile = tmp_path / "chromium-profile"
    profile.mkdir()
    try:
        subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                        "--disable-background-networking", "--disable-component-update", "--disable-sync",
                        f"--user-data-dir={profile}", "--window-size=1600,1000", f"--screenshot={shot}",
                        f"http://127.0.0.1:{page_port}/"], capture_output=True, timeout=LOAD_WAIT_S + 120)
    finally:
        server.shutdown()
    assert shot.exists()
    # The small sweep has three method configs: their bars (tab10 blue, orange, green) fill
    # the summary charts, thousands of pixels each (about 10^5 at 1600 x 1000). The loading
    # screen and the welcome page hold none; a trial tab with only its track, a few hundred.
    counts = _hue_pixels(shot, PALETTE[:3])
    assert min(counts) >= 5000, (counts, str(shot))
