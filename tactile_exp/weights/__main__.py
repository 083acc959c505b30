"""Trunk weights files for ``modality.layout=caffe modality.weights=OUT``:

- ``python -m tactile_exp.weights convert-caffe MODEL.caffemodel OUT``: a Caffe GoogLeNet (the
  MINC release, bvlc_googlenet);
- ``python -m tactile_exp.weights pretrain OUT``: material classification on newly drawn
  synthetic objects (``weights/pretrain.py``), for users without the MINC weights.

Bad input (not a caffemodel, a truncated file, a missing layer, a blob shape that does not fit,
an output that cannot be written, impossible pre-training sizes) ends with one ``error:`` line
and exit status 2, before any work.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from tactile_exp.preprocess.trunk import save_weights
from tactile_exp.weights.caffe import CaffeModelError, convert_googlenet, read_caffemodel
from tactile_exp.weights.pretrain import TRAINABLE, PretrainError, PretrainSettings, pretrain


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


def run_pretrain(args: argparse.Namespace) -> None:
    settings = PretrainSettings(
        objects=args.objects,
        views=args.views,
        size=args.size,
        train_from=args.train_from,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        holdout=args.holdout,
        seed=args.seed,
    )
    figures = pretrain(settings, args.out)
    print(
        f"held-out accuracy {figures['held_out_accuracy']:.3f} (chance {figures['chance']:.3f}) "
        f"on {figures['held_out_images']:.0f} photographs of new objects never trained on; "
        f"{figures['train_images']:.0f} training photographs"
    )
    print(
        f"time {figures['total_s']:.0f} s: render {figures['render_s']:.0f} s, frozen layers "
        f"{figures['frozen_s']:.0f} s, training {figures['train_s']:.0f} s"
    )
    print(f"wrote {args.out} (layout caffe)")
    print(f"use it with: modality.layout=caffe modality.weights={args.out}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tactile_exp.weights", description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    convert = commands.add_parser(
        "convert-caffe", help="convert a Caffe GoogLeNet .caffemodel into a trunk weights file"
    )
    convert.add_argument("model", type=Path, help="the .caffemodel (binary NetParameter)")
    convert.add_argument("out", type=Path, help="the weights file to write (.pth)")
    train = commands.add_parser(
        "pretrain",
        help="train the Caffe-layout trunk on material classification of new synthetic objects",
    )
    train.add_argument("out", type=Path, help="the weights file to write (.pth)")
    defaults = PretrainSettings()
    for name, kind, what in (
        ("objects", int, "new objects, materials in turn"),
        ("views", int, "photographs per object"),
        ("size", int, "crop resized to SIZE x SIZE"),
        ("epochs", int, "training epochs"),
        ("batch-size", int, "minibatch size"),
        ("lr", float, "Adam learning rate"),
        ("holdout", float, "fraction of objects held out for the accuracy"),
        ("seed", int, "random seed (objects, photographs, init)"),
    ):
        default = getattr(defaults, name.replace("-", "_"))
        train.add_argument(f"--{name}", type=kind, default=default, help=f"{what} ({default})")
    train.add_argument(
        "--train-from",
        choices=TRAINABLE,
        default=defaults.train_from,
        help=f"lowest trained block; the layers below keep random weights ({defaults.train_from})",
    )
    args = parser.parse_args(argv)
    try:
        if args.command == "convert-caffe":
            convert_caffe(args.model, args.out)
        else:
            run_pretrain(args)
    except (CaffeModelError, PretrainError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
