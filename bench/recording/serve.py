"""``bench view``: a run's recording in the native Rerun viewer or in a browser.

The native viewer needs a display; without one (``DISPLAY``, ``WAYLAND_DISPLAY`` and
``WAYLAND_SOCKET`` unset on Linux) ``bench view`` says so in one line and suggests
``--web`` (exit 3, the environment), instead of the viewer's windowing error.

``--web`` runs ``rerun --serve-web --bind 127.0.0.1`` on the file: the web viewer
(HTML + Wasm) over HTTP on ``port`` and the recording from a gRPC server on ``port +
1``, both bound to the loopback interface only. (The Python APIs ``rr.serve_grpc`` and
``rr.serve_web_viewer`` of rerun-sdk 0.41 bind 0.0.0.0 and take no address, so the
CLI is used.) The URL printed opens the viewer connected to that server with the
WebGL renderer (``renderer=webgl``), which browsers without WebGPU (most Linux
browsers, headless ones) need; ``--renderer webgpu`` asks for WebGPU. The server
runs until Ctrl-C and dies with ``bench`` (docs/architecture.md, 'Recordings').
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.parse
from pathlib import Path

from radarbench.bench.errors import ConfigError, Fault

__all__ = ["has_display", "listening", "rerun_executable", "view", "web_url"]

#: Seconds to wait for the web viewer to listen before giving up.
START_TIMEOUT_S = 60.0


def has_display() -> bool:
    """False on Linux/BSD without X11 or Wayland: a native viewer cannot open."""
    if sys.platform.startswith(("win", "darwin")):
        return True
    return any(os.environ.get(v) for v in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"))


def rerun_executable() -> str | None:
    """The ``rerun`` binary: rerun-sdk's own (``rerun_cli/rerun``: the ``rerun`` on PATH is
    a Python wrapper that would outlive a stop signal's target), else next to this
    interpreter (venv not activated), else on PATH."""
    import importlib.util

    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        binary = Path(spec.origin).with_name("rerun.exe" if os.name == "nt" else "rerun")
        if binary.is_file() and os.access(binary, os.X_OK):
            return str(binary)
    local = Path(sys.executable).with_name("rerun.exe" if os.name == "nt" else "rerun")
    if local.exists():
        return str(local)
    return shutil.which("rerun")


def web_url(port: int, grpc_port: int, renderer: str = "webgl") -> str:
    """The browser URL of a web viewer on ``port`` reading the gRPC server on ``grpc_port``."""
    source = urllib.parse.quote(f"rerun+http://127.0.0.1:{grpc_port}/proxy", safe="")
    return f"http://127.0.0.1:{port}/?url={source}&renderer={renderer}"


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def listening(port: int, timeout_s: float = 0.5) -> bool:
    """Whether something accepts connections on 127.0.0.1:``port``."""
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=timeout_s):
            return True
    except OSError:
        return False


def _die_with_parent() -> None:
    """In the child: SIGTERM when bench dies (even by kill -9), on Linux."""
    if sys.platform.startswith("linux"):
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)


def _recording(run_dir: Path) -> Path:
    path = run_dir / "recording.rrd"
    if not path.is_file():
        raise ConfigError("", f"{path} does not exist (was the run made with --no-record?)")
    return path


def _executable() -> str:
    exe = rerun_executable()
    if exe is None:
        raise Fault("bench view", "the `rerun` executable (from rerun-sdk) was not found")
    return exe


def view(run_dir: Path, *, web: bool = False, port: int = 9090, renderer: str = "webgl") -> int:
    """Open ``run_dir/recording.rrd``: the native viewer, or (``web``) serve it to a browser."""
    path = _recording(run_dir)
    if not web:
        if not has_display():
            raise Fault("bench view", "no display (DISPLAY and WAYLAND_DISPLAY are unset): use "
                                      f"`bench view {run_dir} --web` to view the recording in a browser")
        # The viewer's own gRPC server on loopback only (it would listen on 0.0.0.0).
        return subprocess.call([_executable(), "--bind", "127.0.0.1", str(path)])
    return _serve_web(path, port, renderer)


def _serve_web(path: Path, port: int, renderer: str) -> int:
    grpc_port = port + 1
    for p, option in ((port, "--port"), (grpc_port, "--port (the next port, for gRPC)")):
        if not _port_free(p):
            raise ConfigError(option, f"port {p} on 127.0.0.1 is in use; choose another with --port")
    cmd = [_executable(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(port),
           "--port", str(grpc_port), "--renderer", renderer, str(path)]
    log = tempfile.TemporaryFile()        # the server's log: its last line explains a failed start
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=log,
                            preexec_fn=_die_with_parent if os.name == "posix" else None)
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not (listening(port) and listening(grpc_port)):
            if proc.poll() is not None:
                log.seek(0)
                last = log.read().decode(errors="replace").strip().splitlines()
                raise Fault("bench view --web", f"the Rerun web viewer stopped: {last[-1] if last else proc.returncode}")
            if time.monotonic() > deadline:
                raise Fault("bench view --web", f"the Rerun web viewer did not listen on 127.0.0.1:{port} "
                                                f"within {START_TIMEOUT_S:.0f} s")
            time.sleep(0.1)
        print(f"serving {path} (127.0.0.1 only) at\n\n    {web_url(port, grpc_port, renderer)}\n\n"
              "open it in a browser; Ctrl-C stops the server", flush=True)
        return proc.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        log.close()
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
