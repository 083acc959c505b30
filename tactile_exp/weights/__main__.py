"""``python -m tactile_exp.weights convert-caffe MODEL.caffemodel OUT``: a Caffe GoogLeNet (the
MINC release, bvlc_googlenet) as a weights file for ``modality.layout=caffe modality.weights=OUT``.

Bad input (not a caffemodel, a truncated file, a missing layer, a blob shape that does not fit)
ends with one ``error:`` line and exit status 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tactile_exp.models.googlenet import save_weights
from tactile_exp.weights.caffe import CaffeModelError, convert_googlenet, read_caffemodel


def convert_caffe(model: Path, out: Path) -> None:
    layers = read_caffemodel(model)
    state, mapped, ignored = convert_googlenet(layers, source=model)
    print(f"{model}: {len(layers)} layers, {len(mapped)} mapped onto the Caffe-layout trunk:")
    for line in mapped:
        print(f"  {line}")
    print(f"ignored {len(ignored)} layers with weights (above inception_5a, auxiliary heads):")
    print(f"  {', '.join(ignored) if ignored else '(none)'}")
    try:
        save_weights(out, state, layout="caffe")
    except OSError as err:
        raise CaffeModelError(f"{out}: cannot write: {err.strerror or err}") from None
    n = sum(t.numel() for t in state.values())
    print(f"wrote {out} ({len(state)} tensors, {n:,} parameters, layout caffe)")
    print(f"use it with: modality.layout=caffe modality.weights={out}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tactile_exp.weights", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    convert = commands.add_parser(
        "convert-caffe", help="convert a Caffe GoogLeNet .caffemodel into a trunk weights file"
    )
    convert.add_argument("model", type=Path, help="the .caffemodel (binary NetParameter)")
    convert.add_argument("out", type=Path, help="the weights file to write (.pth)")
    args = parser.parse_args(argv)
    try:
        convert_caffe(args.model, args.out)
    except CaffeModelError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
