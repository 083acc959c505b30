"""How an SGD-trained model is trained (T2, T3), and its T4 head: one value, not eleven keywords.

``Schedule`` is the ``schedule`` config node (``conf/schedule/``) as a frozen value: the model
YAMLs carry it whole (``schedule: ${schedule}``) and ``SGDModel`` takes it as one constructor
argument. ``head`` is how ``SGDModel.head()`` retrains the classification layer on combined
instances (T4, the node's ``head``); it changes no learned representation, so the store leaves it
out of the training key (``keys.MODEL_UNKEYED``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

STEPS = ("epochs", "finetune_epochs", "batch_size", "lr", "momentum")  # all but the head


def _finite(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _whole(value: object, least: int) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= least


class ScheduleError(ValueError):
    """A bad schedule value; ``key`` is its dotted place in the node (``epochs``, ``head.lr``)."""

    def __init__(self, key: str, message: str) -> None:
        super().__init__(f"schedule{'.' if key else ''}{key}: {message}")
        self.key = key
        self.message = message

    def __reduce__(self) -> tuple[type, tuple[str, str]]:  # pickled whole (worker processes)
        return type(self), (self.key, self.message)


@dataclass(frozen=True)
class Schedule:
    """Two-stage minibatch SGD with momentum (T2, T3) and the head's own schedule (T4).

    Defaults are the paper's (``conf/schedule/paper.yaml`` without its ``head``). ``head`` None:
    the head trains like the model.
    """

    epochs: int = 200  # stage 1 (T3)
    finetune_epochs: int = 100  # stage 2, the classification layer alone (T2; count ours)
    batch_size: int = 1000  # T3
    lr: float = 0.01  # T3
    momentum: float = 0.9  # T3
    head: Schedule | None = None

    def __post_init__(self) -> None:
        checks = (
            ("epochs", _whole(self.epochs, 1), "an int >= 1"),
            ("finetune_epochs", _whole(self.finetune_epochs, 0), "an int >= 0"),
            ("batch_size", _whole(self.batch_size, 1), "an int >= 1"),
            ("lr", _finite(self.lr) and self.lr > 0, "> 0 and finite"),
            ("momentum", _finite(self.momentum) and 0 <= self.momentum < 1, "in [0, 1)"),
        )
        for key, ok, allowed in checks:
            if not ok:
                raise ScheduleError(key, f"{key} must be {allowed}, got {getattr(self, key)!r}")
        if self.head is not None and self.head.head is not None:
            raise ScheduleError("head.head", "a head has no head of its own")

    @classmethod
    def of(cls, node: Schedule | Mapping[str, Any] | None) -> Schedule:
        """A ``Schedule`` from the config node (or a stored model's JSON); None: the defaults.

        A key the node lacks takes the default; one ``head`` lacks takes the model's own value.
        Raises ``ScheduleError`` naming the first unknown or bad key."""
        if node is None:
            return cls()
        if isinstance(node, Schedule):
            return node
        own = _mapping(node, "")
        head = own.pop("head", None)
        schedule = cls(**own)
        if head is None:
            return schedule
        given = _mapping(head, "head.")
        try:
            trained = cls(**{k: getattr(schedule, k) for k in STEPS} | given)
        except ScheduleError as err:
            raise ScheduleError(f"head.{err.key}", err.message) from None
        return cls(**own, head=trained)

    def for_head(self) -> Schedule:
        """How the T4 head trains: ``head``, else this schedule (without a head of its own)."""
        if self.head is not None:
            return self.head
        return Schedule(**{k: getattr(self, k) for k in STEPS})


def _mapping(node: Any, where: str) -> dict[str, Any]:
    """The node's keys, checked; ``head: null`` (how a stored Schedule writes "no head") dropped."""
    known = [f.name for f in fields(Schedule) if where == "" or f.name != "head"]
    if not isinstance(node, Mapping):
        raise ScheduleError(where.rstrip("."), f"expected a mapping of {', '.join(known)}")
    given = {str(k): v for k, v in node.items() if not (k == "head" and v is None)}
    unknown = sorted(set(given) - set(known))
    if unknown:
        raise ScheduleError(f"{where}{unknown[0]}", f"unknown key; allowed: {', '.join(known)}")
    return given
