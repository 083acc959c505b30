"""The model contract, runnable on any model: ``check_model(name, config_dir=...)`` is what
every built-in model passes (scikit-learn's ``check_estimator`` idea), for a model kept outside
the package (its module and YAML) as for ours.

Built from its own YAML on the tiny schedule, the model must: hold its constructor's keywords
under their own names (``get_params``, ``clone``), declare what the engine reads with the
declared types, fit toy rows of a kind it takes and give one finite score per row, give the
same scores when fitted again with the same seed, give a head that fits combined instances, fit
for a head alone the representation ``fit`` fits, and, when storable, come back from its stored
folder (and its head from its own) with the same scores. A broken promise raises
``AssertionError`` naming it.
"""

from __future__ import annotations

import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tactile_exp.data.layout import INSTANCE_KINDS, Instances, InstanceSpec

CONF = Path(__file__).resolve().parents[1] / "conf"  # the project's config groups
EXAMPLE_ROWS = {"signals": (32, 40), "features": (832,)}  # toy rows of each kind a model takes
ANY_ROWS = (4, 32)  # toy (channels, time) rows for a model that takes any rows
KIND_MODALITY = {"signals": "haptic", "features": "visual"}  # a modality giving each kind
TOY_ROWS = 60


def _require(condition: bool, promise: str) -> None:
    if not condition:
        raise AssertionError(promise)


def toy_instances(shape: tuple[int, ...], n: int = TOY_ROWS) -> Instances:
    """``n`` rows of ``shape``, positives shifted by 0.5; consecutive pairs share a label and
    each four an object (so pairs combine into units of one label)."""
    rng = np.random.default_rng(0)
    y = (np.arange(n) // 2 % 2).astype(np.int64)
    X = rng.standard_normal((n, *shape)).astype(np.float32)
    X[y == 1] += 0.5
    return Instances(X, y, np.array([f"t{i}" for i in range(n)], dtype=object), np.arange(n) // 4)


def model_params(
    name: str, *, config_dir: str | Path | None = None, overrides: Sequence[str] = ()
) -> dict[str, Any]:
    """The parameters option ``name`` of the ``model`` group gives, on the tiny schedule, as a
    job resolves and checks them (``config_dir``: a folder beside the project's ``conf/`` with
    ``model/<name>.yaml``, as ``--config-dir`` gives it)."""
    from hydra import compose, initialize_config_dir

    from tactile_exp.config import settings_from_config
    from tactile_exp.models.registry import MODELS

    extra = [f"hydra.searchpath=[file://{Path(config_dir).resolve()}]"] if config_dir else []
    base = [*extra, f"model={name}", "schedule=tiny", "device=cpu"]
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        registered = compose("config", overrides=base).model.name
        accepts = MODELS[registered].accepts if registered in MODELS else ()
        modality = [f"modality={KIND_MODALITY[accepts[0]]}"] if accepts else []
        cfg = compose("config", overrides=[*base, *modality, *overrides])
    model = settings_from_config(cfg).model
    return {"name": model.name, **model.params}


def check_model(
    name: str,
    *,
    config_dir: str | Path | None = None,
    overrides: Sequence[str] = (),
    rows: tuple[int, ...] | None = None,
) -> None:
    """Run the model contract on option ``name`` of the ``model`` group (``model_params``);
    ``rows``: the shape of a toy row (default: by the kind it takes, (channels, time) signals
    when it takes any)."""
    from tactile_exp import artifacts
    from tactile_exp.models.base import clone
    from tactile_exp.models.registry import MODELS
    from tactile_exp.models.schedule import Schedule

    params = model_params(name, config_dir=config_dir, overrides=overrides)
    registered = params.pop("name")
    cls = MODELS[registered]
    _require(isinstance(cls.storable, bool), "storable is a bool")
    _require(isinstance(cls.learns_representation, bool), "learns_representation is a bool")
    _require(
        isinstance(cls.accepts, tuple) and set(cls.accepts) <= set(INSTANCE_KINDS),
        f"accepts names kinds among {sorted(INSTANCE_KINDS)}",
    )
    _require(isinstance(cls.reads, tuple), "reads is a tuple of group names")
    _require(cls.input_shape_ is None, "input_shape_ is None on the class (set by fit)")

    model = MODELS.build(registered, **params)
    held = {**params}
    if isinstance(held.get("schedule"), dict):  # the schedule node, held as one Schedule value
        held["schedule"] = Schedule.of(held["schedule"])
    got = model.get_params()
    _require(
        all(k in got and got[k] == v for k, v in held.items()),
        "every constructor keyword is held under its own name",
    )
    _require(model.input_shape_ is None, "an unfitted model has no input_shape_")

    kind = cls.accepts[0] if cls.accepts else "signals"
    shape = rows or (EXAMPLE_ROWS[kind] if cls.accepts else ANY_ROWS)
    model.check_input(InstanceSpec(kind, shape))
    train = toy_instances(shape)
    history = model.fit(train)
    _require(all(len(v) >= 1 for v in history.values()), "fit returns curves of >= 1 value each")
    scores = model.decision_function(train.X)
    _require(
        scores.shape == (len(train),) and bool(np.isfinite(scores).all()),
        "decision_function gives one finite score per row",
    )
    if kind == "signals" and len(shape) == 2:
        model.check_steps(shape[-1])  # the steps it was just fitted on are fine

    twin = clone(model)
    _require(
        type(twin) is type(model) and twin.get_params() == model.get_params(),
        "clone gives an unfitted model with the same parameters",
    )
    twin.fit(train)
    _require(
        np.array_equal(twin.decision_function(train.X), scores),
        "fitted again with the same seed, it gives the same scores",
    )

    features = model.transform(train.X)
    _require(features.ndim == 2 and len(features) == len(train), "transform gives (n, D)")
    if model.representation_apart:
        alone = clone(model)
        alone.fit_representation(train)
        _require(
            np.array_equal(alone.transform(train.X), features),
            "fit_representation fits the representation fit fits",
        )
    pairs = features.reshape(len(train) // 2, -1)  # two instances combined per unit
    units = Instances(pairs, train.y[::2], train.trial[::2], train.object_id[::2])
    head = model.head()
    head.fit(units)
    _require(
        head.decision_function(pairs).shape == (len(units),),
        "the head scores each combined unit",
    )

    if not model.storable:
        try:
            model.state()
        except NotImplementedError:
            return
        raise AssertionError("a model that is not storable raises NotImplementedError in state()")
    _require(model.input_shape_ == shape, "fit sets input_shape_ to the shape of one row")
    # Rows other than the fitted ones (copies): a fitted model may keep its training rows'
    # transform (fit_transform's, which may differ from transform's in the last bits).
    for what, fitted, rows_x in (("model", model, train.X.copy()), ("head", head, pairs.copy())):
        if not fitted.storable:
            continue
        stored_name = artifacts.model_name(fitted)  # KeyError: not a registered model
        with tempfile.TemporaryDirectory(prefix="tactile_exp-check-") as tmp:
            artifacts.write_model(Path(tmp), stored_name, fitted)
            loaded = artifacts.read_model(Path(tmp), f"check_model: {what}")
        _require(type(loaded) is type(fitted), f"the stored {what} loads as its own class")
        _require(
            np.array_equal(loaded.decision_function(rows_x), fitted.decision_function(rows_x)),
            f"the stored {what} gives the same scores",
        )
