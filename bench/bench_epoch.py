"""Where a training epoch's time goes outside the compiled step: the ConvNet (row H) and the LSTM
(row G) on one adjective's real training set, against the same run's sgemm.

Each model's figures, per epoch of its stage 1 (the whole network; the paper's batch of 1000):

- whole fit: seconds per epoch of ``fit`` (``Model.fit`` with a job's epoch callback, what a
  job's adjective runs), from two fits of ``EPOCHS`` (few, many) epochs without stage 2: the
  difference over the difference of epochs, so what a fit pays once (the body's build, the
  training set's copy, the first calls) cancels and what every epoch pays remains;
- step alone: the model's compiled step (``SGDModel._train_step``) called back to back over one
  epoch's batches (the same sizes, a new shuffle each epoch, gradients set to None between calls
  as the optimiser's ``zero_grad`` does), nothing else: the floor the epoch is held against;
- the phases of the epoch loop of ``train.sgd_epochs`` outside the step (``PHASES``), each timed
  alone over one epoch's batches: the shuffle, the optimiser
  (the gradients reset and ``train.momentum_step`` per batch), the loss bookkeeping (``total +=
  value * len(batch)``) and the per-epoch sync (``float(total)``);
- an epoch at the rate of the step's fastest call (a batch's seconds per row, the best of the
  epoch's calls, times the rows): what a best-of timing of the step (bench_roofline) would
  predict for the epoch;
- the last epoch's loss of the long fit, so a ``--before`` run shows the curves equal.

FLOPs per epoch as bench_roofline counts them (the useful arithmetic of forward + backward, 2 per
multiply-add), against the same run's sgemm (torch, 2000^3, every thread): % of sgemm. Wall time
and CPU time (all threads of the process) are both kept: with other work on the cores CPU time is
the steadier.

The models run in a child process per package: this checkout's and, with ``--before REV``, the
package's at git revision ``REV`` (exported under the cache folder, as bench_roofline does),
items interleaved round by round with sgemm, so load changes hit all alike; the median of
``--repeats`` rounds.

Run: ``.venv/bin/python bench/bench_epoch.py [--repeats 3] [--threads 2] [--adjective hard]
[--before REV] [--json bench/results/bench_epoch.json]``
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
import torch
from revision import package_at

ROOT = Path(__file__).resolve().parent.parent
SGEMM = 2000
ROWS = {"convnet": "table1_h_haptic_cnn_separate", "lstm": "table1_g_haptic_lstm"}
EPOCHS = {"convnet": (2, 22), "lstm": (2, 62)}  # (few, many): ~2 s apart on a 2-core CPU
PHASES = ("shuffle", "optimiser", "bookkeeping", "sync")


def gflop_per_instance(model: str, channels: int, steps: int) -> float:
    """Useful GFLOP of forward + backward for one instance (bench_roofline's count)."""
    if model == "convnet":
        layers, c_in, length = [], channels // 32, steps
        for _ in range(3):
            t_out = (length + 2 * 2 - 5) // 2 + 1
            layers.append(2 * 32 * 4 * c_in * 5 * t_out)
            c_in, length = 4, t_out
        head = 2 * 32 * 4 * length
        return (2 * sum(layers) + sum(layers[1:]) + 3 * head) / 1e9
    hidden = 10
    per_step = 2 * 4 * hidden * (channels + hidden)
    return (2 * per_step + 2 * 4 * hidden * hidden) * steps / 1e9


Timing = tuple[float, float]  # (wall s, CPU s)


def _timed(fn: Callable[[], object]) -> Timing:
    start, start_cpu = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - start, time.process_time() - start_cpu


class Subject:
    """One model on one adjective's training set, in a child process (``serve``)."""

    def __init__(self, model: str, adjective: str) -> None:
        from tactile_exp import api, core

        settings = api.compose(f"experiment={ROWS[model]}", f"adjectives=[{adjective}]")
        dataset, _, splits = core.load(settings)
        pipeline = core.new_pipeline(settings, adjective)
        trials = core.sides(settings, dataset, splits[adjective])
        self.instances = pipeline.fit_preprocess(trials["train"], {})
        self.name, self.params = pipeline.model.name, dict(pipeline.model.params)
        self.model = model
        self.fitted = self.build(1)
        self.fitted.fit(self.instances)  # the kernels loaded, the body built

    def build(self, epochs: int):  # noqa: ANN201 (a Model of either revision)
        from tactile_exp.models.registry import MODELS

        schedule = {"epochs": epochs, "finetune_epochs": 0}
        return MODELS.build(self.name, **{**self.params, "schedule": schedule})

    def fit_loss(self, epochs: int) -> dict[str, float]:
        from tactile_exp.recording import epoch_logger

        model = self.build(epochs)
        out: dict[str, float] = {}
        start, start_cpu = time.perf_counter(), time.process_time()
        history = model.fit(self.instances, epoch_logger(self.model))  # as a job's adjective
        out["wall"], out["cpu"] = time.perf_counter() - start, time.process_time() - start_cpu
        out["last loss"] = float(history["train_loss"][-1])
        return out

    def _loop_parts(self):  # noqa: ANN202
        model = self.fitted
        X = model._tensor(np.asarray(self.instances.X), training=True)
        y = torch.as_tensor(np.asarray(self.instances.y), dtype=torch.float32)
        body, head = model.body_, model.classifier_
        params = [*body.parameters(), *head.parameters()]
        step = model._train_step(body, head, model.pretrain_loss or model.loss)
        return X, y, params, step, model.schedule.batch_size

    def steps(self) -> dict[str, float]:
        """One epoch of the step alone (see the module docstring)."""
        X, y, params, step, batch = self._loop_parts()
        order = torch.randperm(len(X))
        batches = [order[i : i + batch] for i in range(0, len(X), batch)]

        per_row = []  # each call's wall seconds per row

        def epoch() -> None:
            for rows in batches:
                for p in params:
                    p.grad = None
                start = time.perf_counter()
                step(X, y, rows)
                per_row.append((time.perf_counter() - start) / len(rows))

        with self.fitted._torch_threads():
            epoch()  # untimed: as every epoch but a fit's first follows another
            wall, cpu = _timed(epoch)
        return {"wall": wall, "cpu": cpu, "best call": min(per_row) * len(X)}

    def phases(self) -> dict[str, float]:
        """Each phase of ``train.sgd_epochs``' loop outside the step (``PHASES``), over one epoch's
        batches, alone: wall seconds."""
        from tactile_exp import train

        X, y, params, step, batch = self._loop_parts()
        n = len(X)
        if hasattr(train, "momentum_step"):  # the loop's own update (a --before package: torch's)
            velocity = [None] * len(params)
            update = partial(train.momentum_step, params, velocity, lr=1e-9, momentum=0.9)
        else:
            update = torch.optim.SGD(params, lr=1e-9, momentum=0.9).step
        with self.fitted._torch_threads():
            value = step(X, y, torch.arange(min(n, batch)))  # gradients to step with
            grads = [p.grad.clone() for p in params]
            generator = torch.Generator().manual_seed(0)
            sizes = [min(batch, n - i) for i in range(0, n, batch)]
            out = {}
            out["shuffle"] = _timed(lambda: torch.randperm(n, generator=generator))[0]

            def optimise() -> None:
                for _ in sizes:
                    for p, g in zip(params, grads, strict=True):
                        p.grad = None
                        p.grad = g
                    update()

            out["optimiser"] = _timed(optimise)[0]
            total = torch.zeros(())

            def book() -> None:
                nonlocal total
                for size in sizes:
                    total += value * size

            out["bookkeeping"] = _timed(book)[0]
            out["sync"] = _timed(lambda: float(total))[0]
        return out


def serve(threads: int, adjective: str) -> None:
    """Child mode: answer one JSON line per request line (``<model> <what> [epochs]``)."""
    from tactile_exp.models.numba_setup import numba

    torch.set_num_threads(threads)
    numba.set_num_threads(threads)
    subjects = {model: Subject(model, adjective) for model in ROWS}
    shapes = {m: list(np.asarray(s.instances.X).shape) for m, s in subjects.items()}
    print(json.dumps(shapes), flush=True)
    for line in sys.stdin:
        model, what, *rest = line.split()
        subject = subjects[model]
        answer = subject.fit_loss(int(rest[0])) if what == "fit" else getattr(subject, what)()
        print(json.dumps(answer), flush=True)


class Package:
    """``tactile_exp`` at a git revision (None: this checkout), serving in a child process."""

    def __init__(self, rev: str | None, threads: int, adjective: str) -> None:
        env, folder = dict(os.environ), ROOT
        if rev is not None:
            folder = package_at(rev)
            env["NUMBA_CACHE_DIR"] = str(folder / "numba")
        env["PYTHONPATH"] = str(folder)
        self.child = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--serve", "--threads", str(threads),
             "--adjective", adjective],
            env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=folder,
        )  # fmt: skip
        self.shapes = json.loads(self.child.stdout.readline())

    def ask(self, request: str) -> dict[str, float]:
        self.child.stdin.write(request + "\n")
        self.child.stdin.flush()
        return json.loads(self.child.stdout.readline())

    def close(self) -> None:
        self.child.stdin.close()
        self.child.wait()


def sgemm_rate(threads: int) -> tuple[float, float]:
    """torch's sgemm, GFLOP per wall s and per CPU s (best of 3 after one untimed call)."""
    a = torch.randn(SGEMM, SGEMM)
    torch.set_num_threads(threads)
    torch.mm(a, a)
    best = min((_timed(lambda: torch.mm(a, a)) for _ in range(3)), key=lambda t: t[0])
    return 2 * SGEMM**3 / 1e9 / best[0], 2 * SGEMM**3 / 1e9 / best[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--adjective", default="hard")
    parser.add_argument("--before", default=None, help="also time the package at this git rev")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument("--serve", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.serve:
        serve(args.threads, args.adjective)
        return
    packages = {"now": Package(None, args.threads, args.adjective)}
    if args.before is not None:
        packages["before"] = Package(args.before, args.threads, args.adjective)
    shapes = packages["now"].shapes
    samples: dict[str, list[float]] = {}

    def keep(key: str, value: float) -> None:
        samples.setdefault(key, []).append(value)

    for _ in range(args.repeats):
        wall, cpu = sgemm_rate(args.threads)
        keep("sgemm GFLOP/s", wall)
        keep("sgemm GFLOP per CPU s", cpu)
        for model, (few, many) in EPOCHS.items():
            for tag, package in packages.items():
                short, long = package.ask(f"{model} fit {few}"), package.ask(f"{model} fit {many}")
                for kind in ("wall", "cpu"):
                    keep(f"{model} {tag} epoch {kind}", (long[kind] - short[kind]) / (many - few))
                keep(f"{model} {tag} last loss", long["last loss"])
                step = package.ask(f"{model} steps")
                for kind in ("wall", "cpu", "best call"):
                    keep(f"{model} {tag} step {kind}", step[kind])
                if tag == "now":
                    for phase, seconds in package.ask(f"{model} phases").items():
                        keep(f"{model} phase {phase}", seconds)
    for package in packages.values():
        package.close()
    med = {key: statistics.median(values) for key, values in samples.items()}
    sgemm, sgemm_cpu = med["sgemm GFLOP/s"], med["sgemm GFLOP per CPU s"]
    print(
        f"torch {torch.__version__}, {args.threads} threads, adjective {args.adjective}, median of "
        f"{args.repeats} interleaved rounds, load average {os.getloadavg()[0]:.1f} at the end; "
        f"sgemm {sgemm:.1f} GFLOP/s, {sgemm_cpu:.1f} per CPU s"
    )
    figures: dict[str, float] = {
        "sgemm, GFLOP/s": round(sgemm, 1),
        "sgemm, GFLOP per CPU s": round(sgemm_cpu, 1),
    }
    for model in EPOCHS:
        n, channels, steps = shapes[model]
        gflop = n * gflop_per_instance(model, channels, steps)
        print(f"{model} ({ROWS[model]}): {n} instances of {channels} x {steps}, "
              f"{gflop:.2f} GFLOP per epoch")  # fmt: skip
        print(f"  {'':22s} {'ms':>8s} {'% sgemm':>8s} {'CPU ms':>8s} {'% sgemm':>8s} "
              f"{'epoch/step':>10s}")  # fmt: skip
        for tag in packages:
            epoch = med[f"{model} {tag} epoch wall"], med[f"{model} {tag} epoch cpu"]
            step = med[f"{model} {tag} step wall"], med[f"{model} {tag} step cpu"]
            for what, (wall, cpu) in (("whole-fit epoch", epoch), ("step alone", step)):
                share, share_cpu = 100 * gflop / wall / sgemm, 100 * gflop / cpu / sgemm_cpu
                ratio = f"{epoch[0] / step[0]:10.2f}" if what == "whole-fit epoch" else ""
                label = f"{what} ({tag})" if len(packages) > 1 else what
                print(f"  {label:22s} {wall * 1e3:8.1f} {share:7.1f}% {cpu * 1e3:8.1f} "
                      f"{share_cpu:7.1f}% {ratio}")  # fmt: skip
                key = f"{model}, {what}" + (f" ({tag})" if tag != "now" else "")
                figures[f"{key}, ms"] = round(wall * 1e3, 2)
                figures[f"{key}, % of sgemm"] = round(share, 1)
                figures[f"{key}, % of sgemm per CPU s"] = round(share_cpu, 1)
            suffix = f" ({tag})" if tag != "now" else ""
            figures[f"{model}, whole-fit epoch / step alone{suffix}"] = round(epoch[0] / step[0], 3)
            best = med[f"{model} {tag} step best call"]
            figures[f"{model}, an epoch at its fastest step call's rate, ms{suffix}"] = round(
                best * 1e3, 2
            )
            print(f"  an epoch at the step's fastest call's rate ({tag}): {best * 1e3:.1f} ms, "
                  f"{100 * gflop / best / sgemm:.1f}% of sgemm")  # fmt: skip
            figures[f"{model}, last epoch's loss{suffix}"] = med[f"{model} {tag} last loss"]
            print(f"  last epoch's loss ({tag}): {med[f'{model} {tag} last loss']!r}")
        outside = "  the loop's phases outside the step, ms per epoch:"
        for phase in PHASES:
            value = med[f"{model} phase {phase}"] * 1e3
            figures[f"{model}, the loop's {phase}, ms per epoch"] = round(value, 3)
            outside += f" {phase} {value:.2f}"
        print(outside)
        if "before" in packages:
            speedup = med[f"{model} before epoch wall"] / med[f"{model} now epoch wall"]
            figures[f"{model}, whole-fit epoch, before / now"] = round(speedup, 2)
            print(f"  whole-fit epoch, before / now: x{speedup:.2f}")
    if args.json:
        sys.path.insert(0, str(Path(__file__).parent))
        from record import write

        notes = (
            f"median of {args.repeats} rounds interleaved with sgemm, {args.threads} threads, "
            f"adjective {args.adjective}'s training set; whole-fit epoch from fits of "
            f"{EPOCHS} epochs (stage 1 only); step alone: the compiled step over one epoch's "
            "batches back to back; each package in a child process"
        )
        if args.before is not None:
            notes += f"; before = the package at --before {args.before}"
        write(args.json, "bench_epoch", figures, notes)


if __name__ == "__main__":
    main()
