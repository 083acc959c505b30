"""Regenerate the documentation's report figures from a real run: ``python docs/figures.py``.

Runs the README's main job (``experiment=quick_table1_i``: row I on the quick schedule, the
embedded synthetic data) into a fresh MLflow store under ``--work``, builds the report from it,
and copies the report's figures into ``docs/img/`` under the names the walkthrough shows. The
report's ``table1.md`` and ``table1_summary.md`` are printed: getting-started.md quotes the
latter. Nothing is drawn here: every image is a file ``python -m tactile_exp.report`` wrote.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
IMG = ROOT / "docs" / "img"
# report file -> docs/img file (the walkthrough's names)
FIGURES = {
    "fig5_per_adjective.png": "report_fig5_per_adjective.png",
    "fig6_metallic.png": "report_fig6_metallic.png",
}


def _run(cmd: list[str], env: dict[str, str]) -> None:
    print("+", " ".join(cmd), flush=True)
    subprocess.run(cmd, cwd=ROOT, env=env, check=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--work",
        type=Path,
        default=None,
        help="MLflow store, job and report folder (default: temp)",
    )
    parser.add_argument(
        "--job-arg",
        action="append",
        default=[],
        metavar="OVERRIDE",
        help="extra Hydra override for the job, e.g. adjectives=[metallic,compressible]",
    )
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="tactile_exp_docs_"))
    work.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "MLFLOW_TRACKING_URI": f"sqlite:///{work / 'mlflow.db'}"}
    py = sys.executable
    _run(
        [
            py,
            "-m",
            "tactile_exp",
            "experiment=quick_table1_i",
            f"hydra.run.dir={work / 'outputs'}",
            *args.job_arg,
        ],
        env,
    )
    report = work / "report"
    _run([py, "-m", "tactile_exp.report", "--out", str(report)], env)
    IMG.mkdir(parents=True, exist_ok=True)
    for src, dst in FIGURES.items():
        shutil.copyfile(report / src, IMG / dst)
        print(f"wrote {(IMG / dst).relative_to(ROOT)} (from {report / src})")
    print((report / "table1.md").read_text(), end="")
    print((report / "table1_summary.md").read_text(), end="")  # getting-started.md's sample


if __name__ == "__main__":
    main()
