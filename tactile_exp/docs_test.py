"""``TACTILE_EXP_DOCS_TEST=ADJ,ADJ,...``: every job runs small, whatever its command says.

``tests/test_docs_commands.py`` runs each command the documentation shows as it is written, with
this variable set: each job then trains on ``conf/schedule/tiny.yaml``, only the listed adjectives
(of a PHAC-2 job; a command's own ``adjectives`` list is cut to those it shares with them, else to
its first), and, when it reads the embedded synthetic data, its small variant (2 trials per
object, short EPs, one small photograph). Unset (always, outside that test): no effect.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import yaml
from omegaconf import DictConfig, OmegaConf, open_dict

ENV = "TACTILE_EXP_DOCS_TEST"
TINY_SCHEDULE = Path(__file__).resolve().parents[1] / "conf" / "schedule" / "tiny.yaml"
# All 60 objects (every published split exists), as in tests/conftest.py's tiny data set.
TINY_DATA: dict[str, Any] = {
    "trials": 2,
    "duration_scale": 0.1,
    "views": 1,
    "image_width": 96,
    "image_height": 64,
}


def adjectives() -> list[str] | None:
    """The adjectives the variable lists, or None when it is unset or empty."""
    value = os.environ.get(ENV, "").strip()
    return [a.strip() for a in value.split(",") if a.strip()] or None


def shorten(cfg: DictConfig) -> DictConfig:
    """``cfg`` with the docs-test settings applied when the variable is set (a copy), else as is."""
    chosen = adjectives()
    if chosen is None:
        return cfg
    tiny = {k: v for k, v in yaml.safe_load(TINY_SCHEDULE.read_text()).items() if k != "defaults"}
    out = cfg.copy()
    own = out.get("adjectives")
    with open_dict(out):
        if OmegaConf.is_list(own) and len(own):  # cut to the chosen ones (else to its first)
            out.adjectives = [a for a in own if a in chosen] or [own[0]]
        elif own is None and out.data.get("name") in ("synthetic", "phac2"):  # PHAC-2's labels
            out.adjectives = chosen
        out.schedule = OmegaConf.merge(out.schedule, tiny)
        if out.data.get("name") == "synthetic":
            out.data = OmegaConf.merge(out.data, TINY_DATA)
    return out
