"""A finished job's networks as ONNX files: per adjective, preprocessed instances -> decision value.

Each adjective's file is the plain-torch network its modality builds from the stored weights
(``Modality.onnx_network``, ``tactile_exp.modalities.networks``), exported with torch's
TorchScript-based exporter (``dynamo=False``: it needs no onnxscript; the torch.export one does).
The GoogLeNet trunk (rows K-N) is exported once (``googlenet.onnx``); the adjectives' files take
its pooled inception (5a) features. ``manifest.json`` says what each input holds and
``preprocess.npz`` keeps each adjective's fitted preprocessing (docs/deployment.md has a numpy
reference of it). A modality or model that declares it cannot export (``onnx_refusal``: rows
A-F's hand-designed features, row O's random scores) is refused, with its reason, before any
file is written.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_exp import artifacts
from tactile_exp.combine import COMBINERS
from tactile_exp.jobs import PredictError, StoredJob
from tactile_exp.metrics import THRESHOLD
from tactile_exp.modalities import MODALITIES
from tactile_exp.modalities.networks import TRUNK_FILE
from tactile_exp.models.registry import MODELS
from tactile_exp.pipeline import AdjectivePipeline

MANIFEST_FORMAT = 1
OPSET = 17
TORCH = {"impl": "torch"}  # load the kernels-trained networks as plain torch (same weights)


class TrunkNet(nn.Module):
    """The GoogLeNet trunk's ``features``: network input -> pooled, L2-normalised 5a (n, 832)."""

    def __init__(self, trunk: nn.Module) -> None:
        super().__init__()
        self.trunk = trunk

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.trunk.features(images)


def _export(
    net: nn.Module, args: tuple[torch.Tensor, ...], names: list[str], path: Path, output: str
) -> None:
    """``net`` to ``path`` with a dynamic first axis, then checked by ``onnx.checker``."""
    import onnx

    net.eval()
    axes = {name: {0: "n"} for name in [*names, output]}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation and tracer notes
        torch.onnx.export(
            net, args, str(path), input_names=names, output_names=[output],
            dynamic_axes=axes, opset_version=OPSET, dynamo=False,
        )  # fmt: skip
    onnx.checker.check_model(str(path), full_check=True)


def export_job(
    run_id: str | None,
    out: str | Path,
    *,
    experiment: str = "tactile_exp",
    tracking_uri: str | None = None,
    adjectives: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Write job ``run_id``'s networks, ``manifest.json`` and ``preprocess.npz`` into ``out``;
    return the manifest. PredictError, in one line, for a job whose modality or model declares
    it cannot export (``onnx_refusal``)."""
    stored = StoredJob.open(run_id, experiment=experiment, tracking_uri=tracking_uri)
    job_id, spec = stored.id, stored.spec
    modality, model_name = spec.modality.name, spec.model.name
    refusals = [
        f"{kind} {name}: {why}"
        for kind, name, why in (
            ("modality", modality, MODALITIES[modality].onnx_refusal),
            ("model", model_name, MODELS[model_name].onnx_refusal),
        )
        if why is not None
    ]
    if refusals:
        raise PredictError(
            f"run {job_id} is a {model_name} job on modality {modality}: it keeps no network to "
            f"export to ONNX ({'; '.join(refusals)}); `python -m tactile_exp.deploy log` makes "
            "an MLflow model of it instead"
        )
    combiner, combine = spec.combiner, spec.combine
    keeps = COMBINERS.build(combiner).keeps_instances
    children = stored.children(adjectives)
    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, np.ndarray] = {}
    entries: dict[str, Any] = {}
    manifest: dict[str, Any] = {
        "format": MANIFEST_FORMAT,
        "job": job_id,
        "row": spec.row,
        "modality": modality,
        "model": model_name,
        "combine_instances": combiner,
        "combine": combine,
        "threshold": THRESHOLD,
    }
    trunk_key: tuple[Any, ...] | None = None
    for adjective, child in children.items():
        where = f"run {child}"
        saved = stored.folder(child)
        pipeline = AdjectivePipeline.load(saved, where)
        settings = pipeline.modality.params  # the modality's hyperparameters, as the job set them
        state = pipeline.preprocess.get_state()[1]

        def load(path: str, saved: Path = saved, child: str = child) -> Any:
            return artifacts.read_model(saved / path, f"run {child}: artifact {path}", TORCH)

        try:
            exported = MODALITIES[modality].onnx_network(load, settings, keeps, combine)
        except (KeyError, TypeError, ValueError) as err:
            raise artifacts.ArtifactError(
                f"{where}/pipeline.json: missing or bad entry {err}"
            ) from None
        manifest.update(exported.layouts)
        # The state's arrays under the input kind they prepare (multimodal's carry theirs).
        prefix = "" if len(exported.layouts) > 1 else f"{next(iter(exported.layouts))}."
        arrays.update({f"{adjective}.{prefix}{k}": np.asarray(v) for k, v in state.items()})
        if exported.trunk is not None:
            if trunk_key is not None and exported.trunk != trunk_key:
                raise PredictError(f"run {job_id}: adjectives use different GoogLeNet trunks")
            trunk_key = exported.trunk
        net, inputs = exported.net, exported.inputs
        path = folder / f"{adjective}.onnx"
        dummy = tuple(torch.zeros([2, *dims[1:]]) for dims in inputs.values())
        _export(net, dummy, list(inputs), path, "decision")
        entries[adjective] = {"file": path.name, "run_id": child, "inputs": inputs}
        print(f"{adjective}: {path.name} ({path.stat().st_size / 1e3:.1f} kB)", flush=True)
    if trunk_key is not None:
        _export_trunk(manifest["visual"], folder / TRUNK_FILE)
        print(f"trunk: {TRUNK_FILE} ({(folder / TRUNK_FILE).stat().st_size / 1e6:.1f} MB)")
    manifest["adjectives"] = entries
    np.savez(folder / "preprocess.npz", **arrays)
    (folder / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest


def _export_trunk(visual: dict[str, Any], path: Path) -> None:
    """The frozen GoogLeNet trunk the job used (its weights file, or its seeded random init)."""
    from tactile_exp.preprocess.trunk import build_trunk

    weights = visual["weights"]
    if weights is not None and not Path(weights).is_file():
        raise PredictError(f"the job's GoogLeNet weights file {weights} is not there")
    trunk = build_trunk(
        None if weights is None else Path(weights), visual["seed"], visual["layout"]
    )
    size = visual["size"]
    _export(TrunkNet(trunk), (torch.zeros(2, 3, size, size),), ["images"], path, "features")
