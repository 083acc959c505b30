"""One registry pattern for every component kind (models, losses, splits, modalities, ...).

A registry name is also the Hydra config-group option name, so ``model=haptic_cnn`` on the command
line and ``MODELS["haptic_cnn"]`` in code are the same word.

A registry lives in a small module of its own that implementation files import (timm's
``_registry.py`` idiom), and names the modules that fill it: they are imported on the first
lookup, so importing the registry (or a base class beside it) never drags in torch or numba,
and an import error in an implementation still surfaces, at the lookup, with its traceback.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any, Generic, TypeVar

T = TypeVar("T")


@dataclass(frozen=True)
class Component:
    """A config-group choice: registry name plus constructor keyword arguments."""

    name: str
    params: dict[str, Any] = field(default_factory=dict)


class Registry(Generic[T]):
    """Name -> factory map for one component kind; rejects duplicates and wrong base classes."""

    def __init__(self, kind: str, base: type | None = None, modules: Sequence[str] = ()) -> None:
        """``modules``: the implementation modules that register entries, imported on first use."""
        self.kind = kind
        self.base = base
        self.modules = tuple(modules)
        self._entries: dict[str, Callable[..., T]] = {}
        self._loaded = not self.modules

    def register(self, name: str) -> Callable[[Callable[..., T]], Callable[..., T]]:
        def add(factory: Callable[..., T]) -> Callable[..., T]:
            if name in self._entries:
                raise ValueError(f"{self.kind} registry already has an entry named {name!r}")
            if (
                self.base is not None
                and isinstance(factory, type)
                and not issubclass(factory, self.base)
            ):
                raise TypeError(
                    f"{self.kind} {name!r}: {factory.__name__} is not a {self.base.__name__}"
                )
            self._entries[name] = factory
            return factory

        return add

    @contextmanager
    def temporary(self, **entries: Callable[..., T]) -> Iterator[Registry[T]]:
        """The registry as it is now comes back when the block ends: what is registered inside
        it is forgotten then, and ``entries`` (registered on entry, each replacing the entry of
        its name) too. For a notebook or a test that tries a component out."""
        kept = dict(self._load())
        try:
            for name, factory in entries.items():
                self._entries.pop(name, None)
                self.register(name)(factory)
            yield self
        finally:
            self._entries.clear()
            self._entries.update(kept)

    def _load(self) -> dict[str, Callable[..., T]]:
        if not self._loaded:
            self._loaded = True  # set first: the modules register into this registry as they load
            for module in self.modules:
                importlib.import_module(module)
        return self._entries

    def __getitem__(self, name: str) -> Callable[..., T]:
        entries = self._load()
        try:
            return entries[name]
        except KeyError:
            known = ", ".join(sorted(entries)) or "(none)"
            raise KeyError(f"unknown {self.kind} {name!r}; known {self.kind}s: {known}") from None

    def build(self, name: str, /, **kwargs: Any) -> T:
        return self[name](**kwargs)

    def __contains__(self, name: object) -> bool:
        return name in self._load()

    def names(self) -> list[str]:
        return sorted(self._load())
