"""Machine-readable bench results: ``--json OUT`` of a bench script writes one of these files.

Each file records the bench, its command line, the UTC date, the machine (CPU model, cores,
GPU, load average at the end, torch and numba versions) and the figures the bench printed, so
that the documentation's benchmark tables are generated from them (``bench/results_page.py``),
not typed.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict[str, Any]:
    """What the figures depend on: the CPU, its cores, a CUDA GPU where torch sees one, its
    load, the library versions."""
    import numba
    import torch

    gpu = {"gpu": torch.cuda.get_device_name(0)} if torch.cuda.is_available() else {}
    return {
        "cpu": _cpu_model(),
        **gpu,
        "cores": os.cpu_count(),
        "load_average_1min": round(os.getloadavg()[0], 2),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numba": numba.__version__,
        "system": platform.system(),
    }


def write(path: Path, bench: str, figures: dict[str, Any], notes: str = "") -> None:
    """Write one result file: ``figures`` maps a figure's name to its value (numbers, or
    ``{"value": x, "unit": u}``), in the order the bench printed them."""
    record = {
        "bench": bench,
        "command": shlex.join(["python", *sys.argv]),  # quoted: the line runs as printed
        "date": datetime.now(UTC).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine(),
        "notes": notes,
        "figures": figures,
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2) + "\n")
    print(f"wrote {path}")
