"""``python -m tactile_exp.deploy log RUN_ID [--register NAME]`` and ``... onnx RUN_ID OUT/``."""

from __future__ import annotations

import argparse
import sys

from mlflow.exceptions import MlflowException

from tactile_exp import artifacts
from tactile_exp.errors import EXIT_USER_ERROR
from tactile_exp.predict import PredictError


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_exp.deploy",
        description="A finished job as an MLflow model (log) or as ONNX networks (onnx).",
    )
    parser.add_argument("--experiment", default="tactile_exp", help="MLflow experiment name")
    parser.add_argument("--tracking-uri", help="MLflow store (default: as the jobs use)")
    commands = parser.add_subparsers(dest="command", required=True)
    log = commands.add_parser("log", help="log the job as one MLflow pyfunc model")
    log.add_argument("run_id", help="the job's (parent) run id")
    log.add_argument("--register", metavar="NAME", help="also a Model Registry version of NAME")
    onnx = commands.add_parser("onnx", help="export the job's networks as ONNX files")
    onnx.add_argument("run_id", help="the job's (parent) run id")
    onnx.add_argument("out", help="folder for the .onnx files, manifest.json, preprocess.npz")
    args = parser.parse_args(argv)
    where = {"experiment": args.experiment, "tracking_uri": args.tracking_uri}
    try:
        if args.command == "log":
            from tactile_exp.deploy.mlflow_model import log_job

            info, version = log_job(args.run_id, register=args.register, **where)
            print(f"logged {info.model_uri} (run {args.run_id}, artifact path {info.name})")
            if version is not None:
                print(f"registered models:/{args.register}/{version}")
        else:
            from tactile_exp.deploy.onnx_export import export_job

            manifest = export_job(args.run_id, args.out, **where)
            print(f"wrote {len(manifest['adjectives'])} networks, manifest.json, preprocess.npz "
                  f"to {args.out}")  # fmt: skip
    except ImportError as err:
        print(f"error: {err.name} is missing: pip install 'tactile_exp[deploy]'", file=sys.stderr)
        return EXIT_USER_ERROR
    except (PredictError, artifacts.ArtifactError) as err:
        print(f"error: {err}", file=sys.stderr)
        return EXIT_USER_ERROR
    except MlflowException as err:  # e.g. --register on a store without a Model Registry
        print(f"error: {err.message}", file=sys.stderr)
        return EXIT_USER_ERROR
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
