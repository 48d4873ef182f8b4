"""Deprecations: renamed public fields keep their old names until `REMOVAL_VERSION`, each use
warning (DeprecationWarning); the old name's docstring and CHANGELOG.md ("Deprecated") name the
release that removes it."""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, TypeVar

T = TypeVar("T", bound=type)

REMOVAL_VERSION = "0.5.0"
"""The release that removes every name and section deprecated now: the next minor after the
package's version (CHANGELOG.md, "Deprecated")."""


def renamed_fields(**old_to_new: str) -> Callable[[T], T]:
    """A class decorator for a dataclass whose fields were renamed (old name = new name): the
    old names are accepted as keywords of the constructor and readable as attributes, each use
    warning (DeprecationWarning). Given both, the old name's value wins: that is what
    dataclasses.replace(obj, old=...) means (it passes every field by its new name too)."""

    def wrap(cls: T) -> T:
        init = cls.__init__  # type: ignore[misc]

        @functools.wraps(init)
        def init_with_old_names(self: Any, *args: Any, **kwargs: Any) -> None:
            for old, new in old_to_new.items():
                if old in kwargs:
                    _warn(cls.__name__, old, new)
                    kwargs[new] = kwargs.pop(old)
            init(self, *args, **kwargs)

        cls.__init__ = init_with_old_names  # type: ignore[misc]
        for old, new in old_to_new.items():
            setattr(cls, old, property(_reader(cls.__name__, old, new), doc=_doc(new)))
        return cls

    return wrap


def _doc(new: str) -> str:
    return f"Deprecated, removed in {REMOVAL_VERSION}: {new}."


def _reader(owner: str, old: str, new: str) -> Callable[[Any], Any]:
    def read(self: Any) -> Any:
        _warn(owner, old, new, stacklevel=3)
        return getattr(self, new)

    return read


def _warn(owner: str, old: str, new: str, stacklevel: int = 3) -> None:
    warnings.warn(
        f"{owner}.{old} is deprecated: use {owner}.{new}", DeprecationWarning, stacklevel=stacklevel
    )
