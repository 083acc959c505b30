"""The real MLflow UI, driven as a person sees it: ``mlflow ui`` on a free localhost port and
its pages loaded by Debian's headless Chromium through its command line (``--dump-dom``,
``--screenshot``), no browser download. Used by tests/test_tracking.py and docs/screenshots.py.
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
SERVER_START_S = 90  # ``mlflow ui`` imports MLflow and migrates the store first: ~10 s here
PAGE_BUDGET_MS = 10000  # virtual time a page gets to fetch its runs and render them


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextmanager
def mlflow_ui(uri: str, cwd: Path) -> Iterator[str]:
    """``mlflow ui`` on store ``uri`` (one worker) until the block ends; yields its address."""
    port = free_port()
    base = f"http://127.0.0.1:{port}"
    log = (cwd / "mlflow_ui.log").open("w")
    command = [sys.executable, "-m", "mlflow", "ui", "--backend-store-uri", uri]
    command += ["--host", "127.0.0.1", "--port", str(port), "--workers", "1"]
    env = {**os.environ, "MLFLOW_DISABLE_TELEMETRY": "true"}
    server = subprocess.Popen(command, cwd=cwd, stdout=log, stderr=log, env=env)
    try:
        deadline = time.monotonic() + SERVER_START_S
        while True:
            try:
                with urllib.request.urlopen(f"{base}/health", timeout=2) as response:
                    response.read()
                break
            except OSError:
                if server.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(
                        f"mlflow ui did not start: see {cwd / 'mlflow_ui.log'}"
                    ) from None
                time.sleep(0.5)
        yield base
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
        log.close()


def page(url: str, *, screenshot: Path | None = None, size: tuple[int, int] = (1500, 720)) -> str:
    """The page's DOM once it has rendered (and a PNG of it when ``screenshot`` is given), in a
    fresh browser profile: nothing the UI remembers from an earlier visit changes what opens."""
    if CHROMIUM is None:
        raise RuntimeError("no chromium on PATH (Debian: apt-get install chromium)")
    with tempfile.TemporaryDirectory() as profile:
        base = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars"]
        base += [f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}"]
        base += [f"--virtual-time-budget={PAGE_BUDGET_MS}"]
        run = {"capture_output": True, "text": True, "timeout": 90, "check": True}
        dom = subprocess.run([*base, "--dump-dom", url], **run).stdout
        if screenshot is not None:
            subprocess.run([*base, f"--screenshot={screenshot}", url], **run)
    return dom
