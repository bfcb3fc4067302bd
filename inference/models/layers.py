"""Building blocks shared by the ball detectors.

The module *names* produced here are part of the checkpoint format (the WASB-SBDT state_dict keys), so the
helpers return plain layer lists and leave the naming to the caller: an ``nn.Sequential`` numbers them
``0, 1, 2, …``; an ``OrderedDict`` can name them ``conv0, bn0, relu0, …``.

Shapes use ``B`` batch, ``C`` channels, ``H × W`` the spatial size at the block's resolution.
"""
from __future__ import annotations

import torch
from torch import nn

#: Every detector halves the resolution three times, so H and W must be multiples of this.
SIZE_MULTIPLE = 8


def conv_bn_relu(
    in_channels: int,
    out_channels: int,
    *,
    kernel_size: int = 3,
    stride: int = 1,
    bias: bool = False,
    relu: bool = True,
    relu_before_bn: bool = False,
) -> list[nn.Module]:
    """``[Conv2d, BatchNorm2d, ReLU]`` (or ``[Conv2d, ReLU, BatchNorm2d]``, or ``[Conv2d, BatchNorm2d]``).

    The convolution is "same"-padded: ``(B, in, H, W) -> (B, out, H / stride, W / stride)``. BN momentum is
    PyTorch's default, 0.1, as in all three WASB-SBDT models.
    """
    conv = nn.Conv2d(in_channels, out_channels, kernel_size, stride=stride, padding=kernel_size // 2, bias=bias)
    bn = nn.BatchNorm2d(out_channels, momentum=0.1)
    if not relu:
        return [conv, bn]
    act = nn.ReLU(inplace=True)
    return [conv, act, bn] if relu_before_bn else [conv, bn, act]


class Down(nn.Module):
    """Max-pool by 2, then ``block``: ``(B, C, H, W) -> (B, C', H/2, W/2)``. Keys: ``maxpool_conv.1.*``."""

    def __init__(self, block: nn.Module):
        super().__init__()
        self.maxpool_conv = nn.Sequential(nn.MaxPool2d(2), block)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.maxpool_conv(x)


class Up(nn.Module):
    """Upsample the deeper map by 2, concatenate ``[skip, upsampled]`` on channels, then ``conv``.

    ``x: (B, C_deep, H/2, W/2)``, ``skip: (B, C_skip, H, W)`` -> ``(B, C_out, H, W)``. ``up`` is a
    parameter-free ``nn.Upsample`` (TrackNetV2) or a 2×2 transposed convolution (MonoTrack).
    """

    def __init__(self, up: nn.Module, conv: nn.Module):
        super().__init__()
        self.up = up
        self.conv = conv

    def forward(self, x: torch.Tensor, skip: torch.Tensor) -> torch.Tensor:
        return self.conv(torch.cat([skip, self.up(x)], dim=1))


class OutConv(nn.Module):
    """The 1×1 head with bias: ``(B, C, H, W) -> (B, frames_out, H, W)`` logits. Key: ``conv``."""

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.conv = nn.Conv2d(in_channels, out_channels, kernel_size=1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(x)


def check_input(x: torch.Tensor, in_channels: int, model: str) -> None:
    """Raise ``ValueError`` unless ``x`` is ``(B, in_channels, H, W)`` with H and W multiples of 8."""
    if x.dim() != 4 or x.shape[1] != in_channels:
        raise ValueError(
            f"{model} expects input (B, {in_channels}, H, W) (3 RGB channels × frames_in), got {tuple(x.shape)}"
        )
    h, w = x.shape[-2:]
    if h % SIZE_MULTIPLE or w % SIZE_MULTIPLE:
        raise ValueError(f"{model} needs H and W divisible by {SIZE_MULTIPLE}, got {h}×{w} (default 288×512)")
