"""Synthetic data generation: time and size of the full default, and of a paper-size photograph.

Target: the full default (60 objects x 10 trials, 8 views at 480x320) in under 2 minutes on the
2-core development machine. Figures are measured in one run; other load on the machine shows up
in all of them alike, so read the ratios.

    .venv/bin/python bench/bench_data.py [--skip-full]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from tactile_exp.data import render, synthetic
from tactile_exp.data.synthetic import SyntheticSpec

TARGET_S = 120.0


def per_trial(spec: SyntheticSpec, oids: tuple[int, ...]) -> float:
    """Mean seconds to simulate one trial (no writing)."""
    props = synthetic.object_properties(spec)
    start = time.perf_counter()
    for oid in oids:
        synthetic._trial(props[oid], spec.duration_scale, np.random.default_rng([0, oid, 1]))
    return (time.perf_counter() - start) / len(oids)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-full", action="store_true", help="skip the full default file")
    args = ap.parse_args()
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


if __name__ == "__main__":
    main()
