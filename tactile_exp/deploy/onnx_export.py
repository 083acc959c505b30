"""A finished job's networks as ONNX files: per adjective, preprocessed instances -> decision value.

Each adjective's file is a plain-torch module (``DecisionNet``) built from the stored weights and
exported with torch's TorchScript-based exporter (``dynamo=False``: it needs no onnxscript; the
torch.export one does). The ConvNet and the LSTM train with numba kernels, but their weights are
ordinary ``nn.Module`` parameters, so the stored model loaded with ``impl="torch"`` (a setting that
changes no weight, ``keys.MODEL_UNKEYED``) is already plain torch: grouped ``Conv1d`` and
``nn.LSTM``. The GoogLeNet trunk (rows K-N) is exported once (``googlenet.onnx``); the adjectives'
files take its pooled inception (5a) features. ``manifest.json`` says what each input holds and
``preprocess.npz`` keeps each adjective's fitted preprocessing (docs/deployment.md has a numpy
reference of it). Rows A-F are refused: their classifier is a linear SVM on hand-designed
features that only this package computes, not a network.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_exp import artifacts
from tactile_exp.combine import COMBINERS
from tactile_exp.data.layout import EPS
from tactile_exp.jobs import PredictError, StoredJob
from tactile_exp.metrics import THRESHOLD
from tactile_exp.models.registry import MODELS
from tactile_exp.pipeline import AdjectivePipeline
from tactile_exp.preprocess.haptic import N_SCALAR, SIGNALS
from tactile_exp.preprocess.trunk import INCEPTION5A_CHANNELS as FEATURES

MANIFEST_FORMAT = 1
TRUNK_FILE = "googlenet.onnx"
FINGERS = 2
OPSET = 17
TORCH = {"impl": "torch"}  # load the kernels-trained networks as plain torch (same weights)


class DecisionNet(nn.Module):
    """Inputs -> one decision value per row (> 0: the adjective applies), in plain torch.

    ``body`` maps an instance to its features. With ``per_unit`` the first input holds ``k``
    instances per row whose features are concatenated in order (T4's ``concat``); any further
    input (a visual unit: views x 832) is flattened and appended. ``mean``/``scale``: the
    standardisation of a ``linear`` layer (None: none), then ``layer`` gives the score.
    """

    def __init__(
        self,
        body: nn.Module,
        layer: nn.Linear,
        mean: np.ndarray | None = None,
        scale: np.ndarray | None = None,
        *,
        per_unit: bool = False,
    ) -> None:
        super().__init__()
        self.body, self.layer, self.per_unit = body, layer, per_unit
        as_tensor = None if mean is None else torch.as_tensor(np.asarray(mean, np.float32))
        self.register_buffer("mean", as_tensor)
        as_tensor = None if scale is None else torch.as_tensor(np.asarray(scale, np.float32))
        self.register_buffer("scale", as_tensor)

    def forward(self, first: torch.Tensor, *more: torch.Tensor) -> torch.Tensor:
        n = first.shape[0]
        x = self.body(first.flatten(0, 1) if self.per_unit else first).reshape(n, -1)
        if more:
            x = torch.cat([x, *(m.reshape(n, -1) for m in more)], dim=1)
        if self.mean is not None:
            x = (x - self.mean) / self.scale
        return self.layer(x).squeeze(1)


class TrunkNet(nn.Module):
    """The GoogLeNet trunk's ``features``: network input -> pooled, L2-normalised 5a (n, 832)."""

    def __init__(self, trunk: nn.Module) -> None:
        super().__init__()
        self.trunk = trunk

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.trunk.features(images)


def channel_names(pca_components: int) -> list[str]:
    """The haptic instance's channels in order: per EP, PAC, PDC, TAC, TDC and the electrode PCs."""
    own = [s.upper() for s in SIGNALS[:N_SCALAR]] + [f"PC{i + 1}" for i in range(pca_components)]
    return [f"{ep}.{name}" for ep in EPS for name in own]


def _layer(model: Any) -> tuple[nn.Linear, np.ndarray | None, np.ndarray | None]:
    """A stored SGD model's classification layer and its standardisation (``linear`` only)."""
    model.classifier_.eval()
    return model.classifier_, getattr(model, "mean_", None), getattr(model, "scale_", None)


def _haptic_layout(settings: dict[str, Any], trials: int) -> dict[str, Any]:
    return {
        "steps": int(settings["steps"]),
        "offsets": int(settings["offsets"]),
        "pac_downsample": settings["pac_downsample"],
        "pca_components": int(settings["pca_components"]),
        "per_finger": bool(settings["per_finger"]),
        "fingers": FINGERS,
        "trials_per_unit": trials,
        "instances_per_unit": trials * FINGERS * int(settings["offsets"]),
        "raw_signals": list(SIGNALS),
        "eps": list(EPS),
        "channels": channel_names(int(settings["pca_components"])),
        "instance": "(channels, steps): one finger's sub-sampled copy of a trial",
        "unit_order": "trials by name (an object's first ones repeated in order when fewer), "
        "then finger_0, finger_1, then offset",
    }


def _visual_layout(settings: dict[str, Any], views: int) -> dict[str, Any]:
    return {
        "trunk": TRUNK_FILE,
        "size": int(settings["size"]),
        "layout": settings["layout"],
        "weights": settings["weights"],
        "seed": settings["seed"],
        "views_per_unit": views,
        "features": FEATURES,
        "unit_order": "the object's photographs by file name: the first views_per_unit (all of "
        "them repeated in order when fewer)",
    }


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


@dataclass(frozen=True)
class Network:
    """One adjective's exported network: its inputs' shapes (None: any number of rows), the
    manifest's layout of each input kind it takes (``haptic``, ``visual``) and, for visual
    inputs, the trunk that computes them (weights, seed, ...: one per job)."""

    net: DecisionNet
    inputs: dict[str, list[int | None]]
    layouts: dict[str, dict[str, Any]]
    trunk: tuple[Any, ...] | None = None


Load = Callable[[str], Any]  # artifact path of the saved pipeline -> its model (plain torch)


def _haptic(load: Load, settings: dict[str, Any], keeps: bool, combine: int) -> Network:
    """Row H (instances scored one by one), I and J (``combine`` trials' conv3, then the head)."""
    model = load("model")
    shape = list(model.input_shape_)
    if keeps:
        net = DecisionNet(model.body_, *_layer(model))
        return Network(net, {"instances": [None, *shape]}, {"haptic": _haptic_layout(settings, 1)})
    count = combine * FINGERS * int(settings["offsets"])
    net = DecisionNet(model.body_, *_layer(load("head")), per_unit=True)
    layout = _haptic_layout(settings, combine)
    return Network(net, {"instances": [None, count, *shape]}, {"haptic": layout})


def _visual(load: Load, settings: dict[str, Any], keeps: bool, combine: int) -> Network:
    """Rows K (one view per row) and L (``combine`` views' features, then the head)."""
    trunk = (settings["size"], settings["layout"], settings["seed"], settings["weights"])
    if keeps:
        net = DecisionNet(nn.Identity(), *_layer(load("model")))
        layout = {"visual": _visual_layout(settings, 1)}
        return Network(net, {"features": [None, FEATURES]}, layout, trunk)
    net = DecisionNet(nn.Identity(), *_layer(load("head")), per_unit=True)
    layout = {"visual": _visual_layout(settings, combine)}
    return Network(net, {"views": [None, combine, FEATURES]}, layout, trunk)


def _multimodal(load: Load, settings: dict[str, Any], keeps: bool, combine: int) -> Network:
    """Rows M and N: the ConvNet part on ``trials`` trials, the object's views, one layer."""
    part, model = load("parts/haptic"), load("model")
    trials, views = int(settings["trials"]), int(settings["views"])
    haptic, visual = settings["haptic"], settings["visual"]
    count = trials * FINGERS * int(haptic["offsets"])
    inputs = {"instances": [None, count, *part.input_shape_], "views": [None, views, FEATURES]}
    layouts = {"haptic": _haptic_layout(haptic, trials), "visual": _visual_layout(visual, views)}
    trunk = (visual["size"], visual["layout"], visual["seed"], visual["weights"])
    net = DecisionNet(part.body_, *_layer(model), per_unit=True)
    return Network(net, inputs, layouts, trunk)


# The modalities whose fitted pipelines export to ONNX, each by its own rule; any other
# (haptic_features, signals) cannot: its features need this package's code.
NETWORKS: dict[str, Callable[[Load, dict[str, Any], bool, int], Network]] = {
    "haptic": _haptic,
    "visual": _visual,
    "multimodal": _multimodal,
}


def export_job(
    run_id: str | None,
    out: str | Path,
    *,
    experiment: str = "tactile_exp",
    tracking_uri: str | None = None,
    adjectives: Sequence[str] | None = None,
) -> dict[str, Any]:
    """Write job ``run_id``'s networks, ``manifest.json`` and ``preprocess.npz`` into ``out``;
    return the manifest. PredictError for a job that keeps no network (rows A-F, O)."""
    stored = StoredJob.open(run_id, experiment=experiment, tracking_uri=tracking_uri)
    job_id, spec = stored.id, stored.spec
    modality, model_name = spec.modality.name, spec.model.name
    if modality not in NETWORKS or not MODELS[model_name].applies:
        raise PredictError(
            f"run {job_id} is a {model_name} job on modality {modality} (Table I rows A-F, O): "
            "it keeps no network to export to ONNX (rows A-F: a linear SVM on hand-designed "
            "features only this package computes); `python -m tactile_exp.deploy log` makes an "
            "MLflow model of it instead"
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
            exported = NETWORKS[modality](load, settings, keeps, combine)
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
