"""Ball-detector architectures by name (the ``model.name`` config key)."""
from __future__ import annotations

from collections.abc import Callable

from torch import nn

from .monotrack import MonoTrack
from .tracknetv2 import TrackNetV2
from .wasb import WASB

_MODELS: dict[str, Callable[..., nn.Module]] = {
    "wasb": WASB,
    "tracknetv2": TrackNetV2,
    "monotrack": MonoTrack,
}

#: The valid names for :func:`build_model`.
MODEL_NAMES: tuple[str, ...] = tuple(_MODELS)


def build_model(name: str, frames_in: int = 3, frames_out: int = 3) -> nn.Module:
    """A freshly initialised detector: input ``(B, 3·frames_in, H, W)``, output ``(B, frames_out, H, W)`` logits.

    Raises ``ValueError`` for an unknown name, listing the valid ones.
    """
    try:
        cls = _MODELS[name]
    except (KeyError, TypeError):
        raise ValueError(f"unknown ball-detector model {name!r}; valid names: {', '.join(MODEL_NAMES)}") from None
    return cls(frames_in=frames_in, frames_out=frames_out)
