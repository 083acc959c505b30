"""Any scikit-learn-compatible transformer and classifier as a model, with no code
(``model=estimator``): both named in YAML by ``_target_`` with their arguments, as Hydra's
``instantiate`` takes them, e.g. aeon's MiniRocket and scikit-learn's ``RidgeClassifierCV``.

The project supplies what the estimator interface leaves open: the rows' shape (``layout``:
``series``, (n, channels, time) as time-series libraries take them, or ``flat``), scores that
rank (``decision_function``, else ``predict_proba``'s positive column; a classifier whose
probabilities are one-hot is refused before any run), the head for combined instances (the
same classifier on the combined features), seeds (``random_state`` left unset is the job's
seed), the transform of the training rows kept from fitting, and storage. A stored estimator is
skops' format, which loads without unpickling: only the types of the packages its config names
(and scikit-learn's, numpy's and scipy's) are trusted, anything else is refused in one line.
``storage: pickle`` is the explicit opt-in for estimators skops cannot write; loading such a
model also needs ``TACTILE_EXP_TRUST_PICKLE=1``, since unpickling runs the code a file names.

Loading a stored estimator builds no object from its stored arguments: the classes named by
``_target_`` are only imported (a class's constructor could run anything), and the fitted
objects come from the skops file.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Mapping
from typing import Any, Self

import numpy as np

from tactile_exp.data.layout import Instances, InstanceSpec
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.registry import MODELS

LAYOUTS = ("series", "flat")  # series: (n, channels, time) rows; flat: (n, features)
STORAGES = ("skops", "pickle")
TRUST_PICKLE = "TACTILE_EXP_TRUST_PICKLE"  # =1: a stored pickle may be loaded (runs its code)
TRUSTED_PACKAGES = ("sklearn", "numpy", "scipy")  # beside the packages the config names
PROBE_ROWS = 40  # toy rows the classifier is fitted on, before any run, to see its scores rank
PROBE_STEPS = 16  # time steps of a toy row whose length only fitting tells


def _target_class(node: Any, key: str) -> type:
    """The class ``node['_target_']`` names, imported (never called); ValueError naming ``key``."""
    if not isinstance(node, Mapping) or not isinstance(node.get("_target_"), str):
        raise ValueError(
            f"{key}: expected a mapping with _target_ (a class path, e.g. "
            f"sklearn.linear_model.RidgeClassifierCV) and its arguments, got {node!r}"
        )
    from hydra.utils import get_class

    target = node["_target_"]
    try:
        cls = get_class(target)
    except Exception as err:  # Hydra wraps the ImportError or AttributeError
        cause = err.__cause__ or err
        reason = str(cause).splitlines()[0] if str(cause) else type(cause).__name__
        raise ValueError(f"{key}: _target_ {target!r} does not import ({reason})") from None
    if not callable(getattr(cls, "fit", None)) or not callable(getattr(cls, "get_params", None)):
        raise ValueError(f"{key}: _target_ {target!r} is not a scikit-learn-style estimator")
    return cls


def _instantiate(node: Mapping[str, Any], key: str, seed: int) -> Any:
    """A fresh estimator of ``node`` whose ``random_state`` parameters left unset are ``seed``."""
    from hydra.utils import instantiate

    try:
        estimator = instantiate(dict(node), _convert_="all")
    except Exception as err:
        cause = err.__cause__ or err
        reason = str(cause).splitlines()[0] if str(cause) else type(cause).__name__
        raise ValueError(f"{key}: {node['_target_']} rejects its arguments ({reason})") from None
    unset = {
        k: seed
        for k, v in estimator.get_params(deep=True).items()
        if (k == "random_state" or k.endswith("__random_state")) and v is None
    }
    return estimator.set_params(**unset) if unset else estimator


def _package(cls: type) -> str:
    return cls.__module__.split(".")[0]


@MODELS.register("estimator")
class EstimatorModel(Model):
    """A scikit-learn-compatible ``transformer`` (optional) and ``classifier``, named in YAML.

    With a transformer, its output is the representation combined instances concatenate (T4)
    and the head is the classifier alone on them; under ``combine_instances=concat`` only the
    transformer is fitted for the adjective (``fit_representation``): the head's classifier
    is the one that scores.
    """

    reads = ()  # no schedule, no loss: its YAML takes no other group's values
    speed_params = ("transformer.n_jobs", "classifier.n_jobs")  # threads, not what is learned
    storable = True
    onnx_refusal = "it is a scikit-learn estimator, not a torch network"

    def __init__(
        self,
        *,
        classifier: Mapping[str, Any],
        transformer: Mapping[str, Any] | None = None,
        layout: str = "series",
        storage: str = "skops",
        seed: int = 0,
    ) -> None:
        if layout not in LAYOUTS:
            raise ValueError(f"layout: must be one of {', '.join(LAYOUTS)}, got {layout!r}")
        if storage not in STORAGES:
            raise ValueError(f"storage: must be one of {', '.join(STORAGES)}, got {storage!r}")
        self.classifier = classifier
        self.transformer = transformer
        self.layout = layout
        self.storage = storage
        self.seed = seed
        self.classifier_class = _target_class(classifier, "classifier")
        self.transformer_class = (
            None if transformer is None else _target_class(transformer, "transformer")
        )
        # A transformer is fitted, so it is a representation the model learns.
        self.learns_representation = transformer is not None
        self.transformer_: Any = None
        self.classifier_: Any = None
        self._fitted_rows: tuple[np.ndarray, np.ndarray] | None = None  # (X, its transform)

    def _rows(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X)
        return X.reshape(len(X), -1) if self.layout == "flat" else X

    def check_input(self, spec: InstanceSpec) -> None:
        """The layout suits the rows, both estimators take their arguments, and the
        classifier's scores rank: fitted on toy rows, its probabilities are not one-hot."""
        if self.layout == "series" and len(spec.shape) != 2:
            raise ValueError(
                f"layout: series gives the estimators (n, channels, time) arrays, but the rows "
                f"are {spec.describe()}; set model.layout=flat"
            )
        if self.transformer is not None:
            _instantiate(self.transformer, "transformer", self.seed)
        classifier = _instantiate(self.classifier, "classifier", self.seed)
        target = self.classifier["_target_"]
        if hasattr(classifier, "decision_function"):
            return
        if not hasattr(classifier, "predict_proba"):
            raise ValueError(
                f"classifier: {target} has neither decision_function nor predict_proba, so its "
                "predictions cannot rank units for an AUC"
            )
        if self.transformer is not None:
            shape: tuple[int, ...] = (8,)  # features of a size only fitting tells
        else:
            shape = tuple(PROBE_STEPS if d is None else d for d in spec.shape)
        rng = np.random.default_rng(0)
        X = self._rows(rng.standard_normal((2 * PROBE_ROWS, *shape)).astype(np.float32))
        y = np.arange(PROBE_ROWS) % 2
        proba = classifier.fit(X[:PROBE_ROWS], y).predict_proba(X[PROBE_ROWS:])
        if np.isin(proba, (0.0, 1.0)).all():
            raise ValueError(
                f"classifier: {target}'s predict_proba is one-hot (only 0 and 1 on new rows), so "
                "its scores cannot rank units for an AUC; name a classifier with "
                "decision_function or graded probabilities (e.g. "
                "sklearn.linear_model.RidgeClassifierCV)"
            )

    def fit_representation(
        self, train: Instances, on_epoch: EpochCallback | None = None
    ) -> History:
        """Only the transformer: the head's classifier scores the combined instances."""
        self._fit_transformer(train)
        return {}

    def _fit_transformer(self, train: Instances) -> None:
        self.input_shape_ = tuple(int(n) for n in train.X.shape[1:])
        self.classifier_ = None
        self.transformer_ = None
        if self.transformer is not None:
            self.transformer_ = _instantiate(self.transformer, "transformer", self.seed)
            X = self._rows(train.X)
            features = np.asarray(self.transformer_.fit_transform(X, train.y), dtype=np.float32)
            self._fitted_rows = (train.X, features.reshape(len(X), -1))

    def fit(self, train: Instances, on_epoch: EpochCallback | None = None) -> History:
        self._fit_transformer(train)
        self.classifier_ = _instantiate(self.classifier, "classifier", self.seed)
        self.classifier_.fit(self._features(train.X), train.y)
        return {}

    def _features(self, X: np.ndarray) -> np.ndarray:
        """What the classifier takes: the rows in ``layout``, through the transformer if any."""
        if self.transformer is None:
            return self._rows(X)
        return self.transform(X)

    def transform(self, X: np.ndarray) -> np.ndarray:
        """The transformer's features (n, D), those of the training rows kept from fitting;
        flattened rows without a transformer."""
        if self.transformer is None:
            return np.asarray(X).reshape(len(X), -1)
        if self.transformer_ is None:
            raise RuntimeError("EstimatorModel is not fitted: call fit first")
        if self._fitted_rows is not None and self._fitted_rows[0] is X:
            return self._fitted_rows[1]
        features = np.asarray(self.transformer_.transform(self._rows(X)), dtype=np.float32)
        return features.reshape(len(X), -1)

    def decision_function(self, X: np.ndarray) -> np.ndarray:
        if self.classifier_ is None:
            raise RuntimeError(
                "EstimatorModel has no fitted classifier: fit it (fit_representation fits only "
                "the transformer, for a head)"
            )
        features = self._features(X)
        if hasattr(self.classifier_, "decision_function"):
            scores = np.asarray(self.classifier_.decision_function(features), dtype=np.float64)
            return scores.reshape(len(features))
        positive = list(self.classifier_.classes_).index(1)
        return np.asarray(self.classifier_.predict_proba(features)[:, positive], dtype=np.float64)

    def head(self) -> Model:
        """The same classifier, seed and storage on combined features (flat rows)."""
        return EstimatorModel(
            classifier=self.classifier, layout="flat", storage=self.storage, seed=self.seed
        )

    def state(self) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
        """The fitted estimators as one skops (or, opted in, pickle) file's bytes."""
        fitted = {"transformer": self.transformer_, "classifier": self.classifier_}
        if self.storage == "pickle":
            data = pickle.dumps(fitted)
        else:
            import skops.io

            data = skops.io.dumps(fitted)
        return {}, {"estimators": np.frombuffer(data, dtype=np.uint8)}

    def restore(
        self,
        input_shape: tuple[int, ...],
        tensors: Mapping[str, Any],
        arrays: Mapping[str, np.ndarray],
    ) -> Self:
        if "estimators" not in arrays:
            raise ValueError("arrays.npz lacks 'estimators' (the fitted estimators' file)")
        data = np.asarray(arrays["estimators"], dtype=np.uint8).tobytes()
        if self.storage == "pickle":
            if os.environ.get(TRUST_PICKLE) != "1":
                raise ValueError(
                    "stored with model.storage=pickle, and unpickling runs the code the file "
                    f"names: set {TRUST_PICKLE}=1 to load it, only for a file you trust"
                )
            fitted = pickle.loads(data)  # noqa: S301 - the user's explicit opt-in above
        else:
            fitted = self._load_skops(data)
        if not isinstance(fitted, dict) or set(fitted) != {"transformer", "classifier"}:
            raise ValueError("the stored estimators are not a transformer and a classifier")
        self.transformer_, self.classifier_ = fitted["transformer"], fitted["classifier"]
        if (self.transformer_ is None) != (self.transformer is None):
            raise ValueError("the stored transformer does not match model.transformer")
        self.input_shape_ = tuple(input_shape)
        return self

    def _load_skops(self, data: bytes) -> Any:
        """The skops file's objects, trusting only the types of the packages the config names
        (and scikit-learn's, numpy's, scipy's); ValueError listing any other type."""
        import skops.io

        classes = [c for c in (self.transformer_class, self.classifier_class) if c is not None]
        packages = {*TRUSTED_PACKAGES, *(_package(c) for c in classes)}
        try:
            untrusted = skops.io.get_untrusted_types(data=data)
        except Exception as err:
            raise ValueError(f"not a readable skops file ({err})") from None
        refused = [t for t in untrusted if t.split(".")[0] not in packages]
        if refused:
            raise ValueError(
                f"the skops file holds types outside the packages its config names "
                f"({', '.join(sorted(packages))}): {', '.join(refused)}; not loaded"
            )
        return skops.io.loads(data, trusted=untrusted)
