"""One registry type for every choice by name: trackers, view filters, mapping back ends,
window strategies, plane-sampling backends, sweep backends.

A :class:`Registry` maps a name (the value a config key such as ``tracking.method``
takes) to an :class:`Entry`: the factory that builds the implementation, the config
section it is built from (documentation and checks), and an optional ``check(device)``
that refuses a device the implementation cannot run on, before anything is written.

Built-in entries are registered where their implementation lives; code outside eslam
registers its own with :meth:`Registry.register` (and can take it back out with
:meth:`Registry.unregister`). A test holds each config ``Literal`` equal to the
built-in names of its registry.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from eslam.errors import ConfigError

T = TypeVar("T")


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One implementation behind a name.

    Attributes:
        name: the name a config key gives.
        factory: builds the implementation (its arguments are the registry's convention,
            named in the registry's doc).
        config: the config section the factory reads (None when it reads none).
        check: raises :class:`~eslam.errors.ConfigError` for a device the implementation
            cannot run on (None: runs anywhere).
    """

    name: str
    factory: Callable[..., T]
    config: type | None = None
    check: Callable[[Any], None] | None = None


class Registry(Generic[T]):
    """Names -> :class:`Entry` for one kind of component (module doc).

    Args:
        kind: what the entries are, for messages ("tracker").
        key: the config key that names one ("tracking.method"), for messages.
    """

    def __init__(self, kind: str, key: str) -> None:
        self.kind = kind
        self.key = key
        self._entries: dict[str, Entry[T]] = {}

    def register(
        self,
        name: str,
        factory: Callable[..., T],
        *,
        config: type | None = None,
        check: Callable[[Any], None] | None = None,
    ) -> Entry[T]:
        """Add ``name``; raises ValueError when it is taken (unregister it first)."""
        if name in self._entries:
            raise ValueError(f"{self.kind} '{name}' is registered already")
        entry = Entry(name, factory, config, check)
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Take ``name`` out (KeyError when it is not registered)."""
        del self._entries[name]

    def entry(self, name: str) -> Entry[T]:
        """The entry of ``name``.

        Raises:
            ConfigError: no such name (the message lists the choices).
        """
        try:
            return self._entries[name]
        except KeyError:
            choices = ", ".join(sorted(self._entries))
            raise ConfigError(f"unknown {self.key} '{name}' (choose one of: {choices})") from None

    def make(self, name: str, *args: Any, **kwargs: Any) -> T:
        """Build the implementation ``name`` with the registry's factory arguments."""
        return self.entry(name).factory(*args, **kwargs)

    def check(self, name: str, device: Any) -> None:
        """Refuse ``device`` for ``name`` (its entry's check; nothing when it has none)."""
        entry = self.entry(name)
        if entry.check is not None:
            entry.check(device)

    def names(self) -> tuple[str, ...]:
        """The registered names, in registration order."""
        return tuple(self._entries)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)
