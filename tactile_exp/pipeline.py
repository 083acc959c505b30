"""One adjective's fitted classifier, from trials to scores: what training builds, the store
keeps, and predict and the exported models load and call.

``AdjectivePipeline`` chains the modality's preprocessing (fitted on the training trials), the
model, the combiner that groups ``combine`` instances of an object into a unit (T4) and, when
units combine instances, the head retrained on them. ``save(folder)`` / ``load(folder)`` is the
one storage protocol: ``pipeline.json`` (what to build), ``preprocess/`` (what the modality
learned), ``model/``, ``head/`` and ``parts/<part>/`` (``artifacts.write_model``'s folders:
JSON, npz and ``weights_only`` tensors; loading runs no stored code).

A modality may be built on trained parts (rows M and N: the haptic ConvNet beside the visual
trunk): it declares them (``Modality.parts``) and the pipeline is given them fitted, found or
trained by whoever fits it (``core.fit_adjective`` from a model cache), never by the modality.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from tactile_exp import artifacts
from tactile_exp.combine import COMBINERS
from tactile_exp.data.layout import Instances, Trials
from tactile_exp.modalities import MODALITIES, Modality
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS
from tactile_exp.registry import Component

SETTINGS = "pipeline.json"
Trainer = Callable[[Callable[[], tuple[Model, History]]], tuple[Model, History]]


class AdjectivePipeline:
    """Preprocessing -> model -> combiner -> head, for one label (an adjective).

    Hyperparameters are the config's components; ``cache_dir`` is where the modality caches
    what it computes for a whole data set (None: nothing cached, as for a new object).
    """

    def __init__(
        self,
        modality: Component,
        model: Component,
        combiner: str = "concat",
        combine: int = 1,
        *,
        label: str = "",
        cache_dir: Path | None = None,
    ) -> None:
        self.modality = modality
        self.model = model
        self.combiner = combiner
        self.combine = combine
        self.label = label
        self.preprocess: Modality = MODALITIES.build(
            modality.name, cache_dir=cache_dir, **modality.params
        )
        self._combine_units = COMBINERS.build(combiner)
        self.parts_: dict[str, Model] = {}
        # Unfitted: what the model declares (an estimator learns a representation only with a
        # transformer, so it is the instance's to say, not the class's).
        self._declared = MODELS.build(model.name, **model.params)

    @property
    def trains_model(self) -> bool:
        """Whether the model itself is trained: when it scores instances (no head) or learns
        the features the head classifies (a ConvNet); a fixed transform (``linear``) is not."""
        return self.keeps_instances or self._declared.learns_representation

    @property
    def stores_model(self) -> bool:
        """Whether the trained model is kept (and found again) by its training key."""
        return self.trains_model and self._declared.storable

    @property
    def fits_representation_only(self) -> bool:
        """Whether the model is fitted for the head alone, and less than whole: a model whose
        transform is fitted apart from its classifier (``Model.representation_apart``) under a
        combiner that retrains a head fits no classifier nothing would use."""
        return not self.keeps_instances and self._declared.representation_apart

    @property
    def keeps_instances(self) -> bool:
        return self._combine_units.keeps_instances

    def fit(
        self,
        train: Trials,
        *,
        model: Model | None = None,
        parts: dict[str, Model] | None = None,
        on_epoch: EpochCallback | None = None,
        trainer: Trainer | None = None,
    ) -> History:
        """Fit on ``train``; ``model``: an already trained model to use instead of training one,
        ``trainer``: what trains the model when none is given (``fit_instances``), ``parts``:
        the modality's fitted parts (``parts()``). Returns the training curves (model, then
        ``head_*``). The training instances are this call's alone: they are freed once their
        units are made, before the head trains."""
        return self.fit_instances(self.fit_preprocess(train, parts or {}), model, on_epoch, trainer)

    def fit_preprocess(self, train: Trials, parts: dict[str, Model]) -> Instances:
        """Give the modality its fitted ``parts``, fit it on ``train``: the training instances."""
        self.preprocess.set_parts(parts)
        self.parts_ = parts
        return self.preprocess.fit(train).transform(train)

    def train_model(
        self, instances: Instances, on_epoch: EpochCallback | None = None
    ) -> tuple[Model, History]:
        """A new model trained on the training ``instances``, and its curves: only what
        ``transform`` needs when the head alone classifies (``fits_representation_only``)."""
        model = MODELS.build(self.model.name, **self.model.params)
        fit = model.fit_representation if self.fits_representation_only else model.fit
        return model, fit(instances, on_epoch)

    def fit_instances(
        self,
        instances: Instances,
        model: Model | None = None,
        on_epoch: EpochCallback | None = None,
        trainer: Trainer | None = None,
    ) -> History:
        """``fit`` after the preprocessing: the model (unless given trained) and the head.
        ``trainer(train)`` returns the model and its curves, from ``train()`` or found elsewhere
        (a job's model cache, by the model's training key); without it ``train()`` is called."""
        self.n_train_instances_ = len(instances)
        history: History = {}
        if model is None and self.trains_model:
            train = partial(self.train_model, instances, on_epoch)
            model, history = train() if trainer is None else trainer(train)
            del train
        elif model is None:
            model = MODELS.build(self.model.name, **self.model.params)
        self.model_ = model
        self.head_: Model | None = None
        if self.keeps_instances:
            self.train_units_ = instances
            return history
        units = self._units(instances)
        del instances  # freed here when the caller holds no reference (``fit``)
        self.head_ = model.head()
        history |= {f"head_{k}": v for k, v in self.head_.fit(units).items()}
        self.train_units_ = units
        return history

    def train_scores(self) -> tuple[np.ndarray, Instances]:
        """Scores of the units the pipeline was fitted on (the training AUC), without
        preprocessing them again; ``train_units_`` is kept for this and never saved."""
        units = self.train_units_
        scorer = self.model_ if self.head_ is None else self.head_
        return scorer.decision_function(units.X), units

    def _units(self, instances: Instances) -> Instances:
        features = self.model_.transform(instances.X)
        return self._combine_units(features, instances, self.combine, pad=self.preprocess.pad_units)

    def decision_function(self, trials: Trials) -> tuple[np.ndarray, Instances]:
        """One score per unit of ``trials`` (> 0: the label applies) and the units scored."""
        return self.score(self.preprocess.transform(trials))

    def score(self, instances: Instances) -> tuple[np.ndarray, Instances]:
        """Scores of preprocessed ``instances``' units, and the units."""
        if self.head_ is None:
            return self.model_.decision_function(instances.X), instances
        units = self._units(instances)
        return self.head_.decision_function(units.X), units

    def save(self, folder: Path) -> None:
        """Everything ``load`` needs, into ``folder`` (which may hold other artifacts)."""
        settings = {
            "format": artifacts.FORMAT,
            "label": self.label,
            "modality": {"name": self.modality.name, "params": self.modality.params},
            "model": {"name": self.model.name, "params": self.model.params},
            "combiner": self.combiner,
            "combine": self.combine,
        }
        (folder / SETTINGS).write_text(json.dumps(settings, indent=1, default=artifacts.jsonable))
        state, arrays = self.preprocess.get_state()
        (folder / "preprocess").mkdir()
        artifacts.write_state(folder / "preprocess", state, arrays)
        if self.trains_model and self.model_.storable:
            _write_model(folder / "model", self.model.name, self.model_)
        if self.head_ is not None and self.head_.storable:
            _write_model(folder / "head", artifacts.model_name(self.head_), self.head_)
        for part, fitted in self.parts_.items():
            name = self.preprocess.parts()[part][1].name
            _write_model(folder / "parts" / part, name, fitted)

    @classmethod
    def load(cls, folder: Path, where: str) -> AdjectivePipeline:
        """The pipeline ``save`` wrote into ``folder``; ``where`` names it in errors (run id).
        Raises ``artifacts.ArtifactError`` naming the file when anything is missing or off."""

        def at(path: str) -> str:
            return f"{where}: artifact {path}"

        settings = artifacts.read_json(folder, where, SETTINGS)
        try:
            modality = Component(settings["modality"]["name"], settings["modality"]["params"])
            model = Component(settings["model"]["name"], settings["model"]["params"])
            pipeline = cls(
                modality,
                model,
                str(settings["combiner"]),
                int(settings["combine"]),
                label=str(settings["label"]),
            )
        except (KeyError, TypeError, ValueError) as err:
            raise artifacts.ArtifactError(f"{at(SETTINGS)}: missing or bad entry {err}") from None
        pre = folder / "preprocess"
        artifacts.check_files(pre, artifacts.STATE_FILES, at("preprocess"))
        state = artifacts.read_json(pre, at("preprocess"))
        try:
            pipeline.preprocess.set_state(state, artifacts.read_arrays(pre, at("preprocess")))
        except (KeyError, TypeError, ValueError) as err:
            raise artifacts.ArtifactError(f"{at('preprocess')}: {err}") from None
        pipeline.parts_ = {
            part: artifacts.read_model(folder / "parts" / part, at(f"parts/{part}"))
            for part in pipeline.preprocess.parts()
        }
        pipeline.preprocess.set_parts(pipeline.parts_)
        if (folder / "model").is_dir():
            pipeline.model_ = artifacts.read_model(folder / "model", at("model"))
        elif pipeline.trains_model:
            raise artifacts.ArtifactError(f"{where}: no artifact model/, but the model is trained")
        else:
            pipeline.model_ = MODELS.build(model.name, **model.params)
        pipeline.head_ = None
        if not pipeline.keeps_instances:
            pipeline.head_ = artifacts.read_model(folder / "head", at("head"))
        return pipeline


def _write_model(folder: Path, name: str, model: Model) -> None:
    folder.mkdir(parents=True)
    artifacts.write_model(folder, name, model)
