"""``python -m tactile_exp.predict``: per-adjective scores of new trials or photographs."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tactile_exp import artifacts
from tactile_exp.errors import EXIT_USER_ERROR
from tactile_exp.predict import PredictError, predict


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_exp.predict",
        description="Per-adjective scores of new trials or photographs from a finished job.",
    )
    parser.add_argument("run_id", nargs="?", help="the job's (parent) run id; default: newest")
    parser.add_argument("--experiment", default="tactile_exp", help="MLflow experiment name")
    parser.add_argument("--tracking-uri", help="MLflow store (default: as the jobs use)")
    parser.add_argument(
        "--data",
        help="the file or folder holding the trials (a PHAC-2 HDF5 file, a folder-layout data "
        "set, or what any registered data source reads; the job's own source is tried first); "
        "default: the job's own data",
    )
    parser.add_argument("--trial", action="append", default=[], help="a trial group (repeat)")
    parser.add_argument("--object", type=int, help="all trials of this object id")
    parser.add_argument("--photos", help="a folder of one object's photographs")
    parser.add_argument("--adjective", action="append", help="only these adjectives (repeat)")
    parser.add_argument("--format", choices=("table", "csv", "json"), default="table")
    parser.add_argument("--out", help="write here instead of standard output")
    args = parser.parse_args(argv)
    try:
        result = predict(
            run_id=args.run_id, experiment=args.experiment, tracking_uri=args.tracking_uri,
            data=args.data, trials=args.trial, object_id=args.object, photos=args.photos,
            adjectives=args.adjective,
        )  # fmt: skip
    except (PredictError, artifacts.ArtifactError) as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_USER_ERROR
    if args.format != "table":  # the table says it itself; csv and json stay data only
        print("\n".join(result.header()), file=sys.stderr)
    text = {"table": result.to_table, "csv": result.to_csv, "json": result.to_json}[args.format]()
    if args.out:
        Path(args.out).write_text(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
