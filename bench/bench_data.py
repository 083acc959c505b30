"""Synthetic data generation: time and size of the full default, and of a paper-size photograph.

Target: the full default (60 objects x 10 trials, 8 views at 480x320) in under 2 minutes on the
2-core development machine. Figures are measured in one run; other load on the machine shows up
in all of them alike, so read the ratios.

``--before REV`` checks a generator change instead: the package at git revision ``REV``
(exported to a temporary folder) and this checkout's each generate the full default file in a
child process, alternating for ``--rounds`` rounds (wall time, and CPU time of the child and its
workers); then the two files must hold the same arrays (bytes, dtype, shape), attributes and
links (which paths share an object), and the same JPEG bytes; and reading every trial's datasets
of each file is timed (alternating, twice).

    .venv/bin/python bench/bench_data.py [--skip-full] [--before REV [--rounds 2]]
"""

from __future__ import annotations

import argparse
import io
import json
import multiprocessing.forkserver
import os
import resource
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from tactile_exp.data import render, synthetic
from tactile_exp.data.layout import TrialName
from tactile_exp.data.synthetic import SyntheticSpec

TARGET_S = 120.0
ROOT = Path(__file__).resolve().parents[1]


def per_trial(spec: SyntheticSpec, oids: tuple[int, ...]) -> float:
    """Mean seconds to simulate one trial (no writing)."""
    props = synthetic.object_properties(spec)
    start = time.perf_counter()
    for oid in oids:
        synthetic._trial(props[oid], spec.duration_scale, np.random.default_rng([0, oid, 1]))
    return (time.perf_counter() - start) / len(oids)


def generate_here(folder: Path) -> None:
    """Child mode: the default file under ``folder`` with the package on this process's path."""
    start = time.perf_counter()
    synthetic.default_file(folder)
    wall = time.perf_counter() - start
    server = multiprocessing.forkserver._forkserver
    if server._forkserver_pid is not None:
        server._stop()  # reaped: its workers' CPU time now counts in RUSAGE_CHILDREN
    cpu = sum(
        getattr(resource.getrusage(who), field)
        for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN)
        for field in ("ru_utime", "ru_stime")
    )
    print(json.dumps({"wall": wall, "cpu": cpu, "module": synthetic.__file__}))


def generate_with(package_root: Path, folder: Path) -> dict:
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([str(package_root), os.environ.get("PYTHONPATH", "")]),
    }
    out = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--generate", str(folder)],
        env=env, check=True, capture_output=True, text=True, cwd=package_root,
    ).stdout  # fmt: skip
    result = json.loads(out.strip().splitlines()[-1])
    assert Path(result["module"]).is_relative_to(package_root), result
    return result


def inventory(path: Path) -> dict[str, object]:
    """Everything the file holds, storage aside: links, arrays, attributes, shared objects."""
    links, arrays, attrs, objects = {}, {}, {}, {}

    def attributes(obj) -> dict:
        return {
            k: (np.asarray(v).tobytes(), str(np.asarray(v).dtype)) for k, v in obj.attrs.items()
        }

    with h5py.File(path, "r") as f:
        attrs["/"] = attributes(f)

        def visit(name: str, link) -> None:
            links[name] = type(link).__name__
            if isinstance(link, h5py.HardLink):
                obj = f[name]
                objects.setdefault(h5py.h5o.get_info(obj.id).addr, []).append(name)
                attrs[name] = attributes(obj)
                if isinstance(obj, h5py.Dataset):
                    v = obj[()]
                    arrays[name] = (v.tobytes(), str(v.dtype), v.shape)

        f.visititems_links(visit)
    shared = sorted(tuple(sorted(paths)) for paths in objects.values())
    return {"links": links, "arrays": arrays, "attributes": attrs, "shared objects": shared}


def read_all_trials(path: Path) -> float:
    """Seconds to read every dataset of every trial group, as the preprocessing does."""

    def read(name: str, obj) -> None:
        if isinstance(obj, h5py.Dataset):
            obj[()]

    start = time.perf_counter()
    with h5py.File(path, "r") as f:
        for name in f:
            if TrialName.parse(name):
                f[name].visititems(read)
    return time.perf_counter() - start


def before_and_now(rev: str, rounds: int) -> None:
    sha = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", rev], check=True, capture_output=True, text=True
    ).stdout.strip()
    with tempfile.TemporaryDirectory() as tmp:
        before = Path(tmp) / "before"
        before.mkdir()
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", sha, "tactile_exp"], check=True, capture_output=True
        ).stdout
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(before, filter="data")
        sides = {"before": before, "now": ROOT}
        times: dict[str, list[dict]] = {side: [] for side in sides}
        files = {}
        for r in range(rounds):
            for side in ("before", "now") if r % 2 == 0 else ("now", "before"):
                folder = Path(tmp) / f"{side}-{r}"
                times[side].append(generate_with(sides[side], folder))
                if side in files:  # only the latest file of each side is kept
                    shutil.rmtree(files[side].parents[1])
                files[side] = next(folder.glob("*/phac_synthetic.h5"))
                t = times[side][-1]
                print(
                    f"round {r}, {side}: {t['wall']:.1f} s wall, {t['cpu']:.1f} s CPU", flush=True
                )
        for side, ts in times.items():
            wall = " ".join(f"{t['wall']:.1f}" for t in ts)
            cpu = " ".join(f"{t['cpu']:.1f}" for t in ts)
            mb = files[side].stat().st_size / 1e6
            print(f"{side}: wall {wall} s, CPU {cpu} s; HDF5 {mb:.0f} MB")
        a, b = (inventory(files[side]) for side in ("before", "now"))
        for key in a:
            same = "equal" if a[key] == b[key] else "DIFFERENT"
            print(f"{key}: {same} ({len(a[key])} in before, {len(b[key])} now)")
        photos = [sorted((files[s].parent / "photographs").iterdir()) for s in ("before", "now")]
        same = [p.name for p in photos[0]] == [p.name for p in photos[1]] and all(
            p.read_bytes() == q.read_bytes() for p, q in zip(*photos, strict=True)
        )
        print(f"JPEGs: {'equal' if same else 'DIFFERENT'} ({len(photos[0])} files)")
        for r in range(2):
            for side in ("before", "now"):
                took = read_all_trials(files[side])
                print(f"read every trial's datasets, round {r}, {side}: {took:.1f} s", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-full", action="store_true", help="skip the full default file")
    ap.add_argument("--before", help="compare the generator at this git revision with this one")
    ap.add_argument("--rounds", type=int, default=2, help="with --before: generations per side")
    ap.add_argument("--generate", type=Path, help=argparse.SUPPRESS)  # child mode
    args = ap.parse_args()
    if args.generate:
        return generate_here(args.generate)
    if args.before:
        return before_and_now(args.before, args.rounds)
    spec = SyntheticSpec()
    oids = (101, 211, 318, 406, 508, 509, 601, 703)
    sim = per_trial(spec, oids)
    print(f"simulate one trial: {sim * 1e3:.0f} ms (x600 = {sim * 600:.0f} s of one core)")

    props = synthetic.object_properties(spec)[406]
    with tempfile.TemporaryDirectory() as tmp:
        for w, h in ((480, 320), (3000, 2000)):
            start = time.perf_counter()
            view = render.render_view(props, 0, w, h, seed=0)
            took = time.perf_counter() - start
            jpg = Path(tmp) / f"{w}x{h}.jpg"
            render.write_jpeg(jpg, view.image)
            size = jpg.stat().st_size / 1e6
            print(f"render {w}x{h}: {took:.2f} s, JPEG {size:.2f} MB")

        if args.skip_full:
            return
        start = time.perf_counter()
        path = synthetic.generate(Path(tmp) / "phac_synthetic.h5", spec)
        took = time.perf_counter() - start
        h5_mb = path.stat().st_size / 1e6
        photos = list((path.parent / "photographs").iterdir())
        jpg_mb = sum(p.stat().st_size for p in photos) / 1e6
        print(
            f"full default: {took:.1f} s ({took / TARGET_S:.2f} x the {TARGET_S:.0f} s target, "
            f"{synthetic._workers(spec, 60)} workers); HDF5 {h5_mb:.0f} MB "
            f"(real file 472 MB); {len(photos)} JPEGs {jpg_mb:.1f} MB"
        )
        print(f"simulation share of the full run: {sim * 600 / took:.2f} core-s per wall-s")
        print(f"read every trial's datasets: {read_all_trials(path):.1f} s")


if __name__ == "__main__":
    main()
