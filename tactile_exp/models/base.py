"""What every classifier looks like to the experiment engine.

A model is scikit-learn shaped: ``fit`` on training instances, ``decision_function`` on anything.
Models that learn a representation (the haptic CNN's conv3, the LSTM) also ``transform`` instances
into features, and ``head()`` gives a fresh classifier for features combined over several
instances: the paper's "concatenate activations and retrain only the loss layer" (T4).
"""

from __future__ import annotations

import inspect
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from typing import Any, Self

import numpy as np

from tactile_exp.data.layout import Instances, InstanceSpec

# on_epoch(epoch, n_epochs, metrics): called after each epoch (1-based) to show progress.
EpochCallback = Callable[[int, int, dict[str, float]], None]
History = dict[str, list[float]]  # metric name -> one value per epoch


class Model(ABC):
    """A binary classifier for one adjective.

    Like a scikit-learn estimator, every constructor parameter is an explicit keyword argument
    stored under its own name, so ``get_params`` and ``clone`` rebuild an unfitted copy.
    """

    # Capabilities, declared (scikit-learn's tags). learns_representation False: transform()
    # needs no fit (e.g. hand features). accepts: the kinds of instance rows it takes
    # (`INSTANCE_KINDS`: signals, features, images); empty: any (it flattens rows).
    learns_representation: bool = True
    accepts: tuple[str, ...] = ()
    # storable: ``state()``/``restore()`` keep the fitted model as tensors and arrays (artifacts).
    storable: bool = False
    # applies: its scores depend on the input, so a finished job's model is worth applying to
    # new trials (predict, deploy); False for a chance floor whose scores ignore the input.
    applies: bool = True
    # Why a fitted model of this kind cannot be exported to ONNX, or None where the modality's
    # network (`Modality.onnx_network`) takes its torch body and classification layer.
    onnx_refusal: str | None = "it is not a torch network with a classification layer"
    # The config groups beside its own node that its YAML takes values from (``marks.
    # MODEL_GROUPS``: schedule, loss). A group it does not read is left out of a job's config
    # hash, run name and logged config: a model without epochs carries no ``schedule``.
    reads: tuple[str, ...] = ("schedule", "loss")
    # Its parameters (dotted, e.g. ``transform.n_jobs``) that change how fast it trains, not
    # what it learns: left out of the training key, as ``marks``' ``keyed=False`` keys are.
    speed_params: tuple[str, ...] = ()
    # Fitted (storable models): the shape of one training row, what ``restore`` rebuilds for.
    input_shape_: tuple[int, ...] | None = None

    def get_params(self) -> dict[str, Any]:
        """The constructor's keyword arguments as this model holds them."""
        names = inspect.signature(type(self).__init__).parameters
        return {n: getattr(self, n) for n in names if n != "self"}

    @abstractmethod
    def fit(self, train: Instances, on_epoch: EpochCallback | None = None) -> History:
        """Train on ``train``; return per-epoch curves (empty for non-iterative models)."""

    @abstractmethod
    def decision_function(self, X: np.ndarray) -> np.ndarray:
        """One real score per row of ``X``; larger means more likely positive."""

    def fit_representation(
        self, train: Instances, on_epoch: EpochCallback | None = None
    ) -> History:
        """Fit what ``transform`` needs, when only ``head()`` classifies (combined instances).
        The whole model by default: a network learns its representation through its own
        classifier. A model whose transform is fitted apart from its classifier fits only the
        transform (``representation_apart``)."""
        return self.fit(train, on_epoch)

    @property
    def representation_apart(self) -> bool:
        """Whether ``fit_representation`` fits less than ``fit`` (then such a model is another
        trained model: its training key says so)."""
        return type(self).fit_representation is not Model.fit_representation

    def kernels(self) -> tuple[str, ...]:
        """The modules of compiled (numba) kernels ``fit`` runs, each with a ``warm_up()`` that
        compiles them: a job compiles them ahead, beside its data loading, while their cache is
        empty (``numba_setup.compile_ahead``). None by default."""
        return ()

    def transform(self, X: np.ndarray) -> np.ndarray:
        """Features (n, D) to combine over instances; the identity unless overridden."""
        return X.reshape(len(X), -1)

    def head(self) -> Model:
        """A fresh classifier for combined features (T4: retrain only the loss layer)."""
        raise NotImplementedError(f"{type(self).__name__} cannot classify combined instances")

    def check_steps(self, n_steps: int) -> None:
        """Raise ValueError when instances of ``n_steps`` time steps do not suit this model:
        checked against ``modality.steps`` before any run. Any length, unless overridden."""
        return None

    def check_input(self, spec: InstanceSpec) -> None:
        """Raise ValueError when rows ``spec`` describes do not suit this model, its message
        starting with the parameter to change (``groups: ...``): checked when the data opens,
        before any run. A declared kind (``accepts``) is checked before this is called."""
        return None

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The fitted model as tensors (a flat ``state_dict``) and arrays: what ``restore``
        takes. Storable models (``storable``) override it and ``restore``."""
        raise NotImplementedError(f"{type(self).__name__} is not storable")

    def restore(
        self,
        input_shape: tuple[int, ...],
        tensors: Mapping[str, Any],
        arrays: Mapping[str, np.ndarray],
    ) -> Self:
        """This (unfitted) model made the fitted one ``state()`` described, for rows of
        ``input_shape``; raises ValueError when a tensor or array does not fit."""
        raise NotImplementedError(f"{type(self).__name__} is not storable")


def clone(model: Model) -> Model:
    """A fresh, unfitted model with ``model``'s parameters (scikit-learn's ``clone``)."""
    return type(model)(**model.get_params())
