"""One registry pattern for every component kind (models, losses, splits, modalities, ...).

A registry name is also the Hydra config-group option name, so ``model=haptic_cnn`` on the command
line and ``MODELS["haptic_cnn"]`` in code are the same word.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, Generic, TypeVar

T = TypeVar("T")


class Registry(Generic[T]):
    """Name -> factory map for one component kind; rejects duplicates and wrong base classes."""

    def __init__(self, kind: str, base: type | None = None) -> None:
        self.kind = kind
        self.base = base
        self._entries: dict[str, Callable[..., T]] = {}

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

    def __getitem__(self, name: str) -> Callable[..., T]:
        try:
            return self._entries[name]
        except KeyError:
            known = ", ".join(sorted(self._entries)) or "(none)"
            raise KeyError(f"unknown {self.kind} {name!r}; known {self.kind}s: {known}") from None

    def build(self, name: str, /, **kwargs: Any) -> T:
        return self[name](**kwargs)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self._entries))

    def names(self) -> list[str]:
        return sorted(self._entries)
