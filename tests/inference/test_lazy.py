"""Lazy package exports (inference/lazy.py): every exported name resolves to the object of its submodule."""
from __future__ import annotations

import importlib
import inspect

import pytest

PACKAGES = ["inference.clipio", "inference.detection", "inference.events", "inference.interchange",
            "inference.pipeline", "inference.reconstruct"]


@pytest.mark.parametrize("package", PACKAGES)
def test_every_exported_name_resolves(package):
    mod = importlib.import_module(package)
    assert mod.__all__, package
    for name in mod.__all__:
        value = getattr(mod, name)
        assert not inspect.ismodule(value), f"{package}.{name} is a module, not the exported object"
        source = mod._EXPORTS.get(name)
        if source is not None:
            assert value is getattr(importlib.import_module(source, package), name)
    assert set(mod._EXPORTS) <= set(dir(mod))
    with pytest.raises(AttributeError, match="no_such_name"):
        _ = mod.no_such_name


def test_names_like_their_submodule_stay_functions():
    """Importing ``inference.pipeline.prepare`` (the module) must not shadow the exported ``prepare``."""
    importlib.import_module("inference.pipeline.prepare")
    importlib.import_module("inference.events.decode")
    from inference.events import decode
    from inference.pipeline import prepare, score

    assert callable(prepare) and callable(score) and callable(decode)
    assert not any(inspect.ismodule(f) for f in (prepare, score, decode))
