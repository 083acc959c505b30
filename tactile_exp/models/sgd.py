"""The two-stage SGD schedule (T2, T3) and the linear "loss layer" it ends in.

``SGDModel`` is a body (input -> features) followed by one linear classification layer, trained
in two stages:

1. the whole network with ``pretrain_loss`` (``loss`` when ``pretrain_loss`` is None) for
   ``epochs`` epochs;
2. when ``pretrain_loss`` is set, the classification layer alone is fine-tuned with ``loss`` for
   ``finetune_epochs`` epochs on the frozen body's features. The paper ("after learning the
   weights for the convolutional layers, fine-tuning with hinge-loss") leaves open whether the
   body moves in stage 2; we keep it frozen, as the combined-instance heads (T4) do, which also
   lets stage 2 run on features computed once.

``head()`` gives the ``linear`` model (``models/linear.py``) for combined instances, trained by
its own schedule (``Schedule.head``, the ``schedule.head`` config node): combined units are ~10x
fewer than instances.

``impl`` picks the kernels: ``compiled`` trains the classification layer alone (stage 2, and
stage 1 of a model without a body) by ``linear_sgd`` and a subclass's body by its own compiled
kernels, CPU only; ``torch`` runs everything through autograd; ``auto`` is compiled on CPU and
torch on a GPU. Both give the same numbers to float rounding.

Stage 2 moves the layer only where stage 1 left a training margin below 1 (hinge's gradient is
zero elsewhere, and T3 has no weight decay). On linearly separable training rows (the T4 heads:
a few hundred combined units, 24,320 or more columns) logistic loss drives every margin past 1,
so hinge fine-tuning is a no-op and ``loss=hinge`` scores equal ``loss=logistic``'s bit for bit:
``fit`` then warns (``FinetuneWarning``).
"""

from __future__ import annotations

import warnings
from abc import abstractmethod
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from typing import Any

import numpy as np
import torch
from torch import nn

from tactile_exp.data.layout import Instances
from tactile_exp.models.base import EpochCallback, History, Model
from tactile_exp.models.losses import LOSSES
from tactile_exp.models.registry import MODELS
from tactile_exp.models.schedule import Schedule
from tactile_exp.models.scratch import on_huge_pages
from tactile_exp.train import (
    Step,
    autograd_step,
    caffe_xavier_,
    resolve_device,
    seed_everything,
    sgd_epochs,
    validate_losses,
)

# Rows per body call when scoring or computing features (ours): the compiled ConvNet's
# whole-batch activations take ~27 MB at 256 rows (~90 MB at 1024, kept in the scratch pool for
# the rest of the job); each row's features do not depend on the batch it is in.
INFERENCE_BATCH = 256
IMPLS = ("auto", "compiled", "torch")


def _in_blocks(n: int, block: Callable[[int, int], torch.Tensor]) -> torch.Tensor:
    """``block(start, end)`` over ``n`` rows, ``INFERENCE_BATCH`` at a time, written into one
    tensor (not parts concatenated: a second copy of them all). Scoring preprocesses a block at a
    time too: the linear head's standardised copy of its input is as large as the input. A last
    block of one row joins the one before: torch computes a lone row's product another way, so
    its last bits would differ from the same row's in a block."""
    starts = list(range(0, n, INFERENCE_BATCH))
    if len(starts) > 1 and n - starts[-1] == 1:
        starts.pop()
    if len(starts) <= 1:
        return block(0, n)
    ends = [*starts[1:], n]
    first = block(0, ends[0])
    out = first.new_empty((n, *first.shape[1:]))
    out[: ends[0]] = first
    for start, end in zip(starts[1:], ends[1:], strict=True):
        out[start:end] = block(start, end)
    return out


class FinetuneWarning(UserWarning):
    """Stage 2 left the classification layer as stage 1 made it."""


# (model, loss, pretrain loss) already warned about in this process: once, not once per adjective
# (the warnings module's own "once" forgets after any catch_warnings() block; the engine has some).
FINETUNE_WARNED: set[tuple[str, str, str | None]] = set()


class SGDModel(Model):
    """A body plus a linear classification layer, trained by the two-stage SGD schedule."""

    # The modules of the body's compiled kernels (``Model.kernels``), beside ``linear_sgd``.
    body_kernels: tuple[str, ...] = ()

    storable = True
    onnx_refusal = None  # its body and classification layer are plain torch modules
    # Capability, declared: whether head() standardises the combined features (LinearModel)
    head_standardize: bool = True

    def __init__(
        self,
        *,
        schedule: Schedule | Mapping[str, Any] | None = None,
        loss: str = "hinge",
        pretrain_loss: str | None = "logistic",
        impl: str = "auto",
        seed: int = 0,
        device: str = "auto",
    ) -> None:
        """``schedule``: how both stages train, and in its ``head`` how ``head()`` trains the
        classification layer on combined instances (T4); a mapping is the ``schedule`` config
        node (``Schedule.of``), None the paper's schedule."""
        self.schedule = Schedule.of(schedule)
        validate_losses(loss=loss, pretrain_loss=pretrain_loss, known_losses=LOSSES.names())
        self.device_ = resolve_device(device)
        self.device = device
        if impl not in IMPLS:
            raise ValueError(f"impl must be one of {', '.join(IMPLS)}, got {impl!r}")
        if impl == "compiled" and self.device_.type != "cpu":
            raise ValueError(f"impl='compiled' runs on CPU only; device is {self.device_}")
        if impl == "compiled":  # refused now, not when a layer-only stage or the head starts
            from tactile_exp.models.linear_sgd import check_loss  # numba: lazy

            for name in {loss, pretrain_loss or loss}:
                check_loss(name)
        self.impl = impl
        self.loss = loss
        self.pretrain_loss = pretrain_loss
        self.seed = seed
        self.body_: nn.Module | None = None
        self.classifier_: nn.Linear | None = None

    @property
    def runs_compiled(self) -> bool:
        """Whether training runs the compiled CPU kernels: ``impl`` compiled, or auto on CPU."""
        return self.impl == "compiled" or (self.impl == "auto" and self.device_.type == "cpu")

    def kernels(self) -> tuple[str, ...]:
        """The classification layer's compiled SGD (``linear_sgd``) and the body's kernel
        modules (``body_kernels``), where they run."""
        return ("tactile_exp.models.linear_sgd", *self.body_kernels) if self.runs_compiled else ()

    @abstractmethod
    def _build_body(self, input_shape: tuple[int, ...]) -> tuple[nn.Module, int]:
        """A fresh body for rows of ``input_shape`` and the width of its features."""

    def _check_input(self, X: np.ndarray) -> None:
        """Raise ValueError when training rows do not suit this model."""

    def _fit_preprocessing(self, X: np.ndarray) -> None:
        """Learn input statistics from the training rows (nothing by default)."""

    def _preprocess(self, X: np.ndarray) -> np.ndarray:
        return X

    def _train_scores(
        self, body: nn.Module, classifier: nn.Linear
    ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
        """Stage 1's forward, (X, batch's row index) -> scores; a body with a fused path
        overrides it."""
        return lambda X, index: classifier(body(X[index])).squeeze(1)

    def _train_step(self, body: nn.Module, classifier: nn.Linear, loss: str) -> Step:
        """Stage 1's step on a batch (``train.sgd_epochs``): ``loss`` on ``_train_scores``
        through autograd; a body that computes the loss and its gradients in one pass overrides
        it."""
        scores, loss_fn = self._train_scores(body, classifier), LOSSES[loss]
        return autograd_step(lambda X, y, index: loss_fn(scores(X, index), y[index]))

    def _tensor(self, X: np.ndarray, *, training: bool = False) -> torch.Tensor:
        """``X`` preprocessed, as the body takes it; a training set on the CPU is copied onto
        huge pages, as its batches are read row by row at random (``scratch.on_huge_pages``),
        where scoring reads rows in order."""
        if self.body_ is None or self.classifier_ is None:
            raise RuntimeError(f"{type(self).__name__} is not fitted; call fit first")
        X = np.asarray(X)
        if X.shape[1:] != self.input_shape_:
            raise ValueError(
                f"{type(self).__name__}: X rows have shape {X.shape[1:]}, "
                f"the model was fitted on rows of shape {self.input_shape_}"
            )
        X = self._preprocess(X)
        if training and self.device_.type == "cpu":
            return torch.from_numpy(on_huge_pages(X))
        return torch.as_tensor(np.ascontiguousarray(X, dtype=np.float32), device=self.device_)

    @contextmanager
    def _torch_threads(self) -> Iterator[None]:
        """torch's own ops on one thread while the compiled kernels train or score (CPU).

        The kernels sum in a fixed order whatever numba's thread count, but the torch layers
        around them (the LSTM's FC layers, a classification layer's matrix products) sum in an
        order that depends on torch's thread count, and 200 epochs of SGD turn that rounding into
        different AUCs (row G: 0.900 or 0.842 for one adjective). Jobs under Hydra's joblib
        launcher get one thread each (loky sets OMP_NUM_THREADS), a plain job every core: one
        thread here makes them equal. Those ops are small beside the kernels'."""
        threads = torch.get_num_threads()
        if not self.runs_compiled or threads == 1:
            yield
            return
        torch.set_num_threads(1)
        try:
            yield
        finally:
            torch.set_num_threads(threads)

    def fit(self, train: Instances, on_epoch: EpochCallback | None = None) -> History:
        with self._torch_threads():
            return self._fit(train, on_epoch)

    def _fit(self, train: Instances, on_epoch: EpochCallback | None) -> History:
        X = np.asarray(train.X)
        if len(X) == 0:
            raise ValueError(f"{type(self).__name__}.fit: no training instances")
        self._check_input(X)
        generator = seed_everything(self.seed)
        self._fit_preprocessing(X)
        body, width = self._build_body(X.shape[1:])
        classifier = nn.Linear(width, 1)
        caffe_xavier_(classifier.weight, width)
        nn.init.zeros_(classifier.bias)
        self.body_ = body.to(self.device_)
        self.classifier_ = classifier.to(self.device_)
        self.input_shape_ = X.shape[1:]
        Xt = self._tensor(X, training=True)
        yt = torch.as_tensor(np.asarray(train.y), dtype=torch.float32, device=self.device_)

        schedule = self.schedule
        finetune = self.pretrain_loss is not None and schedule.finetune_epochs > 0
        n_epochs = schedule.epochs + (schedule.finetune_epochs if finetune else 0)
        done = 0

        def reporter(metric: str) -> Callable[[float], None]:
            def report(value: float) -> None:
                nonlocal done
                done += 1
                if on_epoch is not None:
                    on_epoch(done, n_epochs, {metric: value})

            return report

        body_, classifier_ = self.body_, self.classifier_
        common = dict(
            batch_size=schedule.batch_size,
            lr=schedule.lr,
            momentum=schedule.momentum,
            generator=generator,
        )
        body_.train()
        stage1_loss, report = self.pretrain_loss or self.loss, reporter("train_loss")
        if isinstance(body_, nn.Identity):  # no body: stage 1 trains the layer alone too
            train_loss = self._layer_epochs(
                Xt, yt, loss=stage1_loss, epochs=schedule.epochs, report=report, **common
            )
        else:
            train_loss = sgd_epochs(
                self._train_step(body_, classifier_, stage1_loss),
                [*body_.parameters(), *classifier_.parameters()],
                Xt,
                yt,
                epochs=schedule.epochs,
                report=report,
                **common,
            )
        history: History = {"train_loss": train_loss}
        if finetune:
            before = [p.detach().clone() for p in classifier_.parameters()]
            history["finetune_loss"] = self._layer_epochs(
                Xt if isinstance(body_, nn.Identity) else self._features(Xt),
                yt,
                loss=self.loss,
                epochs=schedule.finetune_epochs,
                report=reporter("finetune_loss"),
                **common,
            )
            noted = (type(self).__name__, self.loss, self.pretrain_loss)
            if noted not in FINETUNE_WARNED and all(
                map(torch.equal, before, classifier_.parameters())
            ):
                FINETUNE_WARNED.add(noted)
                warnings.warn(
                    f"{type(self).__name__}: {self.loss} fine-tuning left the classification "
                    f"layer unchanged: its gradient was zero on every training row after the "
                    f"{self.pretrain_loss} stage (linearly separable rows, every margin >= 1), "
                    f"so the scores equal loss={self.pretrain_loss}'s",
                    FinetuneWarning,
                    stacklevel=3,  # the caller of fit (past _fit)
                )
        return history

    def _layer_epochs(
        self, F: torch.Tensor, y: torch.Tensor, *, loss: str, **schedule: Any
    ) -> list[float]:
        """SGD epochs of the classification layer alone on fixed features ``F``: compiled
        (``linear_sgd``) unless ``impl`` or the device says torch; ``auto`` also takes torch's
        path for a registered loss the compiled loop does not compute."""
        if self.runs_compiled:
            from tactile_exp.models import linear_sgd  # numba: lazy

            if self.impl == "compiled" or loss in linear_sgd.LOSSES:
                return linear_sgd.linear_sgd_epochs(self.classifier_, F, y, loss=loss, **schedule)
        loss_fn, layer = LOSSES[loss], self.classifier_
        return sgd_epochs(
            autograd_step(
                lambda features, y, index: loss_fn(layer(features[index]).squeeze(1), y[index])
            ),
            list(self.classifier_.parameters()),
            F,
            y,
            **schedule,
        )

    @torch.no_grad()
    def _features(self, X: torch.Tensor) -> torch.Tensor:
        """The body's features of preprocessed ``X``, a block of rows a call (``_in_blocks``)."""
        self.body_.eval()
        if len(X) == 0:
            return X.new_empty((0, self.classifier_.in_features))
        return _in_blocks(len(X), lambda start, end: self.body_(X[start:end]))

    def transform(self, X: np.ndarray) -> np.ndarray:
        """The body's features for each row of ``X``: (n, D) float32."""
        X = np.asarray(X)
        with self._torch_threads():
            features = _in_blocks(len(X), lambda a, b: self._features(self._tensor(X[a:b])))
        return features.cpu().numpy()

    @torch.no_grad()
    def decision_function(self, X: np.ndarray) -> np.ndarray:
        X = np.asarray(X)
        with self._torch_threads():
            scores = _in_blocks(
                len(X), lambda a, b: self.classifier_(self._features(self._tensor(X[a:b])))
            )
        return scores.squeeze(1).double().cpu().numpy()

    def _state_arrays(self) -> dict[str, np.ndarray]:
        """Fitted input statistics kept beside the weights (none by default)."""
        return {}

    def _set_state_arrays(self, arrays: Mapping[str, np.ndarray]) -> None:
        """Restore what ``_state_arrays`` gave."""

    def state(self) -> tuple[dict[str, torch.Tensor], dict[str, np.ndarray]]:
        """The fitted model as tensors (body, classifier) and arrays: what ``restore`` takes."""
        if self.body_ is None or self.classifier_ is None:
            raise RuntimeError(f"{type(self).__name__} is not fitted; nothing to save")
        tensors = {f"body.{k}": v.detach().cpu() for k, v in self.body_.state_dict().items()}
        tensors.update(
            {f"classifier.{k}": v.detach().cpu() for k, v in self.classifier_.state_dict().items()}
        )
        return tensors, self._state_arrays()

    def restore(
        self,
        input_shape: tuple[int, ...],
        tensors: Mapping[str, torch.Tensor],
        arrays: Mapping[str, np.ndarray],
    ) -> SGDModel:
        """Rebuild the fitted model from ``state()``'s output for rows of ``input_shape``.

        Raises ValueError when a tensor is missing, unexpected or of the wrong shape."""
        self._set_state_arrays(arrays)
        body, width = self._build_body(tuple(input_shape))
        classifier = nn.Linear(width, 1)
        for prefix, module in (("body.", body), ("classifier.", classifier)):
            part = {k[len(prefix) :]: v for k, v in tensors.items() if k.startswith(prefix)}
            try:
                module.load_state_dict(part, strict=True)
            except RuntimeError as err:
                raise ValueError(f"{prefix.rstrip('.')} weights do not fit: {err}") from None
        self.body_ = body.to(self.device_)
        self.classifier_ = classifier.to(self.device_)
        self.input_shape_ = tuple(input_shape)
        return self

    def head(self) -> Model:
        """A fresh ``linear`` model with the head's schedule, for combined features (T4)."""
        return MODELS.build(
            "linear",
            standardize=self.head_standardize,
            schedule=self.schedule.for_head(),
            loss=self.loss,
            pretrain_loss=self.pretrain_loss,
            impl=self.impl,
            seed=self.seed,
            device=self.device,
        )
