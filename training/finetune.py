"""Fine-tuning helpers shared by the detector and hit-event modules: freezing layers by name.

``freeze`` takes prefixes of the network's parameter names (``conv1``, ``layer1``, ``stage2`` for WASB;
``gru`` for HitNet): their weights stop learning and their batch-norm layers keep the statistics they
were trained with (kept in eval mode while the rest trains).

Example:
    >>> frozen = freeze(net, ["conv1", "bn1", "conv2", "bn2", "layer1"])   # WASB's stem
    >>> hold_frozen_norms(net, frozen)                                       # after every net.train()
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn


def _matches(name: str, prefix: str) -> bool:
    return name == prefix or name.startswith(prefix + ".")


def freeze(net: nn.Module, prefixes: Sequence[str]) -> list[str]:
    """Stop the gradients of every parameter under ``prefixes``; returns the frozen module names.

    Raises ``ValueError`` for a prefix that names nothing, listing the network's top-level modules.
    """
    prefixes = [str(p).strip(".") for p in (prefixes or [])]
    if not prefixes:
        return []
    names = [n for n, _ in net.named_modules() if n]
    for prefix in prefixes:
        if not any(_matches(n, prefix) for n in names):
            top = sorted({n.split(".")[0] for n in names})
            raise ValueError(f"freeze: {prefix!r} names no layer of {type(net).__name__}; its layers: {', '.join(top)}")
    for name, p in net.named_parameters():
        if any(_matches(name.rsplit(".", 1)[0], prefix) or _matches(name, prefix) for prefix in prefixes):
            p.requires_grad_(False)
    return prefixes


def hold_frozen_norms(net: nn.Module, prefixes: Sequence[str]) -> int:
    """Put the batch-norm layers under ``prefixes`` in eval mode (their running statistics stay); returns
    how many. Call after ``net.train()``."""
    count = 0
    for name, m in net.named_modules():
        if isinstance(m, nn.modules.batchnorm._BatchNorm) and any(_matches(name, p) for p in prefixes):
            m.eval()
            count += 1
    return count


def unused_parameters(net: nn.Module, example: torch.Tensor) -> list[str]:
    """Names of the learnable parameters that get no gradient from ``net(example)`` (e.g. WASB's
    ``stage4.0.fuse_layers.{1,2,3}``: kept for checkpoint compatibility, never computed). Run in eval
    mode, so batch-norm statistics are untouched."""
    was = net.training
    named = [(n, p) for n, p in net.named_parameters() if p.requires_grad]
    net.eval()
    try:
        out = net(example)
        grads = torch.autograd.grad(out.float().sum(), [p for _, p in named], allow_unused=True)
    finally:
        net.train(was)
    return [n for (n, _), g in zip(named, grads) if g is None]


def freeze_unused(net: nn.Module, example: torch.Tensor) -> list[str]:
    """Freeze (``requires_grad=False``) the parameters :func:`unused_parameters` finds; they stay in the
    state_dict, so checkpoints keep their layout. DDP then needs no ``find_unused_parameters``."""
    names = unused_parameters(net, example)
    params = dict(net.named_parameters())
    for name in names:
        params[name].requires_grad_(False)
    return names


def trainable(module: nn.Module):
    """The parameters that still learn (for the optimiser)."""
    return [p for p in module.parameters() if p.requires_grad]
