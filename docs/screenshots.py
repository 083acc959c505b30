"""Make the screenshots of docs/mlflow_ui.md from a real tiny sweep, and print what the docs
quote (the link a job prints, the jobs' names, predict's output).

    python docs/screenshots.py [--out docs/img]

A 4-job sweep (loss x combine, 2 adjectives, schedule=tiny) on a tiny generated file in the
PHAC-2 layout, in a temporary MLflow store; then ``mlflow ui`` on a free port and Debian's
headless Chromium (``apt-get install chromium``) take ``mlflow_runs.png`` (the link's runs
table) and ``mlflow_overview.png`` (the experiment opened without the link). ~2 min.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))  # the UI driver the slow UI test uses

from mlflow_ui_fixture import mlflow_ui, page  # noqa: E402

from tactile_exp.data.sources import DATA_SOURCES  # noqa: E402
from tactile_exp.tracking import UI_DEFAULT  # noqa: E402

TINY = {"trials": 2, "duration_scale": 0.1, "views": 1, "image_width": 96, "image_height": 64}
SWEEP = ["loss=hinge,logistic", "combine=1,2", "schedule=tiny", "adjectives=[hard,soft]"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "img")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        generated = DATA_SOURCES.build("synthetic", cache_dir=str(work / "cache"), **TINY).path
        data = work / "phac2_tiny.h5"
        shutil.copy(generated, data)
        uri = f"sqlite:///{work / 'mlflow.db'}"
        sweep = [sys.executable, "-m", "tactile_exp", "-m", "data=phac2", f"data.path={data}"]
        sweep += [*SWEEP, f"cache_dir={work / 'cache'}", f"tracking.uri={uri}"]
        sweep += [f"hydra.sweep.dir={work / 'multirun'}"]
        log = subprocess.run(sweep, capture_output=True, text=True, check=True, cwd=ROOT)
        lines = (log.stdout + log.stderr).splitlines()
        print("\n".join(line for line in lines if "MLflow run" in line or "runs table" in line))
        link = next(line for line in lines if "runs table" in line).split(": ", 1)[1]
        predict = [sys.executable, "-m", "tactile_exp.predict", "--tracking-uri", uri]
        for extra in (["--object", "101"], ["--trial", "car_sponge_101_01", "--format", "csv"]):
            shown = subprocess.run([*predict, *extra], capture_output=True, text=True, cwd=ROOT)
            print(f"\n$ python -m tactile_exp.predict {' '.join(extra)}")
            print(shown.stdout + shown.stderr, end="")
        with mlflow_ui(uri, work) as base:
            page(link.replace(UI_DEFAULT, base), screenshot=args.out / "mlflow_runs.png",
                 size=(1800, 560))  # fmt: skip
            page(f"{base}/#/experiments/1", screenshot=args.out / "mlflow_overview.png",
                 size=(1400, 560))  # fmt: skip
    print(f"\nwrote {args.out / 'mlflow_runs.png'} and {args.out / 'mlflow_overview.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
