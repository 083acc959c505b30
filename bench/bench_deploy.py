"""Bench: a registered job served by ``mlflow models serve`` (CPU), one object's trials per request.

Starts the server on a free localhost port (``--env-manager local``), sends ``--requests`` POSTs of
the object's trials to ``/invocations`` one after the other (the first one, which loads torch and
the weights, is reported apart), and prints the median, min and max wall-clock latency; beside
it, alternating with the requests, ``predict()`` of the same job on the same trials in this
process (the tracking store instead of the model's folder). With ``--onnx DIR`` (what
``python -m tactile_exp.deploy onnx`` wrote) it lists the files there and their sizes.

    .venv/bin/python bench/bench_deploy.py --tracking-uri sqlite:///mlflow.db --model touch \
        --data DATA.h5 --object 101 --onnx onnx/
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

from tactile_exp.data.phac2 import PHAC2
from tactile_exp.predict import predict


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _post(url: str, body: bytes) -> float:
    request = urllib.request.Request(url, body, {"Content-Type": "application/json"})
    start = time.perf_counter()
    with urllib.request.urlopen(request, timeout=120) as response:
        json.loads(response.read())
    return time.perf_counter() - start


def _summary(name: str, seconds: list[float]) -> str:
    ms = [s * 1e3 for s in seconds]
    return (f"{name}: median {statistics.median(ms):.0f} ms (min {min(ms):.0f}, "
            f"max {max(ms):.0f}, {len(ms)} requests)")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--tracking-uri", required=True)
    parser.add_argument("--model", required=True, help="registered model name (version 1)")
    parser.add_argument("--data", required=True, help="the PHAC-2-layout file of the trials")
    parser.add_argument("--object", type=int, required=True, help="the object whose trials")
    parser.add_argument("--requests", type=int, default=10)
    parser.add_argument("--onnx", help="a folder written by `deploy onnx`: list its file sizes")
    args = parser.parse_args()

    from mlflow.tracking import MlflowClient

    job = MlflowClient(args.tracking_uri).get_model_version(args.model, "1").tags["job"]
    trials = sorted(t.name for t in PHAC2(args.data).trials if t.object_id == args.object)
    frame = {"columns": ["data", "trial"], "data": [[args.data, t] for t in trials]}
    body = json.dumps({"dataframe_split": frame}).encode()
    port = _free_port()
    env = {**os.environ, "MLFLOW_TRACKING_URI": args.tracking_uri}
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    command = [sys.executable, "-m", "mlflow", "models", "serve", "-m", f"models:/{args.model}/1"]
    command += ["--env-manager", "local", "--host", "127.0.0.1", "--port", str(port)]
    url = f"http://127.0.0.1:{port}/invocations"
    with tempfile.TemporaryFile() as log:
        server = subprocess.Popen(
            command, env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        try:
            start = time.perf_counter()
            while True:
                try:
                    first = _post(url, body)
                    break
                except (ConnectionError, urllib.error.URLError):
                    if server.poll() is not None or time.perf_counter() - start > 120:
                        log.seek(0)
                        sys.exit(f"the server did not answer:\n{log.read().decode()[-2000:]}")
                    time.sleep(0.2)
            served, direct = [], []
            for _ in range(args.requests):
                served.append(_post(url, body))
                t0 = time.perf_counter()
                predict(run_id=job, tracking_uri=args.tracking_uri, data=args.data, trials=trials)
                direct.append(time.perf_counter() - t0)
        finally:
            os.killpg(server.pid, signal.SIGTERM)  # mlflow and the uvicorn it starts
            server.wait(timeout=30)
    print(f"object {args.object}: {len(trials)} trials per request; first request {first:.2f} s")
    print(_summary("served (mlflow models serve, CPU)", served))
    print(_summary(f"predict() of job {job} in process", direct))
    if args.onnx:
        for path in sorted(Path(args.onnx).iterdir()):
            print(f"{path.name}: {path.stat().st_size / 1e3:.1f} kB")


if __name__ == "__main__":
    main()
