"""``python -m tactile_exp.data generate|inspect|validate|import-csv|public``: make, show and
check PHAC-2 files; turn per-trial CSV recordings, or a public data set by its recipe, into the
folder layout."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tactile_exp.data.csv_import import DEFAULT_PATTERN, TIME_COLUMNS, TIME_UNITS, import_csv
from tactile_exp.data.phac2 import PHAC2, DataError, default_cache_dir
from tactile_exp.data.validate import checks, summary, validate


def _image_size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        msg = f"--image-size {text!r}: expected WxH, e.g. 480x320"
        raise argparse.ArgumentTypeError(msg) from None
    return w, h


def _generate(args: argparse.Namespace) -> Path:
    from tactile_exp.data.synthetic import SyntheticSpec, default_file, generate

    spec = SyntheticSpec(
        seed=args.seed,
        trials=args.trials,
        duration_scale=args.duration_scale,
        views=args.views,
        image_width=args.image_size[0],
        image_height=args.image_size[1],
    )
    return generate(args.out, spec) if args.out else default_file(default_cache_dir(), spec)


def _default_file() -> Path:
    from tactile_exp import docs_test
    from tactile_exp.data.synthetic import SyntheticSpec, default_file

    small = docs_test.adjectives() is not None  # the documentation's command test
    return default_file(
        default_cache_dir(), SyntheticSpec(**docs_test.TINY_DATA) if small else SyntheticSpec()
    )


def _progress(line: str) -> None:
    """Progress of a long check on stderr, so that stdout stays the result."""
    print(line, file=sys.stderr, flush=True)


def _inspect(path: Path, photo_dir: Path | None) -> None:
    s = summary(PHAC2(path, photo_dir), _progress)
    print(f"{s['path']}: {s['objects']} objects, {s['trials']} trials ({s['bad_trials']} bad)")
    for ep, st in s["ep_rows"].items():
        rows = f"{st['min']}..{st['max']} (median {st['median']:g})" if st else "none readable"
        print(f"  EP {ep:<10} rows {rows}")
    print("  adjective     +obj  train  test")
    for adj, n_pos in s["positive_objects"].items():
        sp = s["splits"][adj]
        sizes = f"{sp['train']:>5}  {sp['test']:>4}" if "error" not in sp else sp["error"]
        print(f"  {adj:<12} {n_pos:>4}  {sizes}")
    missing = s["objects_without_photographs"]
    print(f"  photographs: {s['photographs']}; objects without: {missing or 'none'}")


def _public(args: argparse.Namespace) -> int:
    from tactile_exp.data.public import freeze, import_public, listing
    from tactile_exp.data.recipe import find

    try:
        if args.verb == "list":
            print("\n".join(listing()))
        elif args.verb == "freeze":
            print(freeze(find(args.name)))
        else:
            print("\n".join(import_public(args.name, args.src, args.dst).summary()))
    except DataError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tactile_exp.data", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    gen = sub.add_parser("generate", help="write a synthetic PHAC-2 file and its photographs")
    gen.add_argument("--out", type=Path, help="output .h5 (default: the cached default file)")
    gen.add_argument("--seed", type=int, default=0)
    gen.add_argument("--trials", type=int, default=10, help="trials per object")
    gen.add_argument("--duration-scale", type=float, default=1.0)
    gen.add_argument("--views", type=int, default=8, help="photographs per object")
    gen.add_argument("--image-size", type=_image_size, default=(480, 320), metavar="WxH")
    for name, text in (("inspect", "print a summary"), ("validate", "list every problem")):
        cmd = sub.add_parser(name, help=text)
        cmd.add_argument("path", nargs="?", type=Path, help="PHAC-2 .h5 (default: synthetic)")
        cmd.add_argument("--photo-dir", type=Path, help="default: <file folder>/photographs")
    sub.choices["validate"].add_argument(
        "--no-photographs", action="store_true", help="skip the photograph checks"
    )
    imp = sub.add_parser(
        "import-csv",
        help="per-trial CSV files -> the folder layout (data=folder)",
        description="One CSV per trial (rows = samples, columns = channels, an optional time "
        "column from which the rate is read), the object from each file's path, and a labels "
        "table (object, then one 0/1 column per label): written as the folder layout.",
    )
    imp.add_argument("src", type=Path, help="the folder of per-trial CSV files")
    imp.add_argument("dst", type=Path, help="the data set to write (a new folder)")
    imp.add_argument("--labels", type=Path, help="labels table (default: SRC/labels.csv)")
    imp.add_argument(
        "--object-pattern",
        default=DEFAULT_PATTERN,
        help="regular expression on each file's path under SRC whose group 'object' (or first "
        f"group) names its object (default {DEFAULT_PATTERN!r}: the folder it is in)",
    )
    imp.add_argument("--glob", default="**/*.csv", help="which files are trials (default **/*.csv)")
    imp.add_argument("--time-column", help=f"default: the first of {', '.join(TIME_COLUMNS)}")
    imp.add_argument("--time-unit", default="s", choices=sorted(TIME_UNITS))
    imp.add_argument("--rate", type=float, help="samples per second, when there is no time column")
    imp.add_argument("--sensor", help="the sensor's name (default: SRC's folder name)")
    public = sub.add_parser(
        "public",
        help="public data sets by recipe: list them, import one (the folder layout)",
        description="Each recipe names its upstream (pinned commit), licence, files, rate, "
        "channels, label table and frozen folds; import checks the files' count and checksum.",
    )
    verbs = public.add_subparsers(dest="verb", required=True)
    verbs.add_parser("list", help="every recipe and what it declares")
    pub = verbs.add_parser("import", help="check SRC against a recipe, write DST")
    pub.add_argument("name", help="a recipe's name (public list) or a recipe file NAME.yaml")
    pub.add_argument(
        "--from", dest="src",
        help="a local clone or copy of the upstream (a folder), an archive of it, or its URL "
        "(default: download the upstream's archive at the recipe's pinned commit)",
    )  # fmt: skip
    pub.add_argument("dst", type=Path, help="the data set to write (a new folder)")
    freeze = verbs.add_parser("freeze", help="(re)write a recipe's frozen folds (maintainers)")
    freeze.add_argument("name")
    args = parser.parse_args(argv)

    if args.command == "public":
        return _public(args)
    if args.command == "import-csv":
        try:
            found = import_csv(
                args.src, args.dst, labels=args.labels, pattern=args.object_pattern,
                glob=args.glob, time_column=args.time_column, time_unit=args.time_unit,
                rate=args.rate, sensor=args.sensor,
            )  # fmt: skip
        except DataError as e:
            print(f"error: {e}", file=sys.stderr)
            return 1
        print("\n".join(found.summary()))
        return 0
    if args.command == "generate":
        print(_generate(args))
        return 0
    path = args.path or _default_file()
    if args.command == "inspect":
        try:
            _inspect(path, args.photo_dir)
        except DataError as e:
            print(e, file=sys.stderr)
            return 1
        return 0
    photographs = not args.no_photographs
    problems = validate(path, args.photo_dir, photographs=photographs, progress=_progress)
    for p in problems:
        print(p)
    if not problems:
        print(f"OK: {path}")
        print("".join(f"  checked: {what}\n" for what in checks(photographs)), end="")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
