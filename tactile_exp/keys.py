"""The training key: what makes two trained models the same model, so one is found, not retrained.

It hashes exactly what determines a learned representation (data identity, modality and
preprocessing settings, architecture, the network's schedule, loss, split rule, seed, adjective),
not what only the head, the evaluation or the machine uses, so rows H, I and J share one ConvNet
per adjective. Every model cache (``cache``, ``store``) is keyed by it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from typing import Any

from tactile_exp import dotted, marks
from tactile_exp.artifacts import FORMAT
from tactile_exp.registry import Component

# Parameters of every model and modality marked ``keyed=False`` (``tactile_exp/marks.py``); a
# dotted key is a value inside a parameter (the T4 head's schedule inside the model's ``schedule``).
MODEL_UNKEYED = marks.unkeyed("model")
MODALITY_UNKEYED = marks.unkeyed("modality")


def training_key(
    *,
    dataset: str,
    modality: Component,
    model: Component,
    split: str,
    validation: float,
    seed: int,
    adjective: str,
    representation_only: bool = False,
) -> str:
    """Hash of what determines one adjective's trained model (not combine/combine_instances).

    ``validation`` is the fraction of training objects held out for the validation score: they
    are left out of training, so it changes the model. ``representation_only``: the model is
    fitted for a head alone (``AdjectivePipeline.fits_representation_only``), so it is not the
    whole model another job would reuse."""
    keyed = {
        "format": FORMAT,
        "dataset": dataset,
        "modality": [modality.name, dotted.without(modality.params, MODALITY_UNKEYED)],
        "model": [model.name, dotted.without(model.params, model_unkeyed(model.name))],
        "split": split,
        "validation": validation,
        "seed": seed,
        "adjective": adjective,
    }
    if representation_only:  # absent otherwise: every other model keeps the key it had
        keyed["fitted"] = "representation"
    raw = json.dumps(keyed, sort_keys=True, default=str)
    return hashlib.sha256(raw.encode()).hexdigest()[:20]


def model_unkeyed(name: str) -> tuple[str, ...]:
    """The parameters of model ``name`` left out of its training key: every model's
    (``MODEL_UNKEYED``) and those the model declares speed-only (``Model.speed_params``)."""
    from tactile_exp.models.registry import MODELS

    declared = MODELS[name].speed_params if name in MODELS else ()
    return tuple(dict.fromkeys((*MODEL_UNKEYED, *declared)))


def unkeyed(model: Component) -> dict[str, Any]:
    """The settings of ``model``'s unkeyed parameters (``model_unkeyed``) in a job's
    ``model.params``, by dotted key: what a model it reuses takes from it
    (``artifacts.read_model``'s overrides). A schedule without a head gives ``schedule.head``
    None: the head then trains like the model, as in the job; a speed parameter the job does
    not set is left as the model was stored."""
    out = {}
    for path in model_unkeyed(model.name):
        parent, _, leaf = path.rpartition(".")
        node = dotted.get(model.params, parent) if parent else model.params
        if isinstance(node, Mapping) and (leaf in node or (parent and path in MODEL_UNKEYED)):
            out[path] = node.get(leaf)
    return out
