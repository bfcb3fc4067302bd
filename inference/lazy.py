"""Lazy package exports (PEP 562), so that importing a package for its CLI does not load torch or scipy.

A package ``__init__`` lists what it re-exports and from which submodule; a name is imported on first use::

    __getattr__, __dir__ = lazy_exports(__name__, {"EventDetector": ".detector", ...})

``from inference.events import EventDetector`` works as before; ``import inference.events`` alone is cheap.
"""
from __future__ import annotations

import importlib
from collections.abc import Callable


def lazy_exports(package: str, exports: dict[str, str]) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``; ``exports`` maps a name to its (relative) submodule."""

    def __getattr__(name: str) -> object:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module, package), name)
        globals_ = importlib.import_module(package).__dict__
        globals_[name] = value  # later look-ups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(importlib.import_module(package).__dict__) | set(exports))

    return __getattr__, __dir__
