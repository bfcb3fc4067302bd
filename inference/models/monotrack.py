"""MonoTrack's shuttle detector as re-implemented by WASB-SBDT (``src/models/monotrack.py`` with
``halve_channel: True``), weight-compatible with its public ``monotrack_*_best.pth.tar`` checkpoints.

This is *not* the layout of MonoTrack's released Keras model (see docs/models.md, "Architectures"). A
residual U-Net; convolutions are 3×3 with bias, then BN, then ReLU. Channels @ resolution for a 288×512
input::

    inc     Neck: conv1 9 -> 32, conv2 32 -> 32, out = conv1 + conv2    @ 288×512
    down1   pool, ResBlock(2 convs) -> 64      @ 144×256
    down2   pool, ResBlock(3 convs) -> 128     @ 72×128
    down3   pool, ResBlock(3 convs) -> 256     @ 36×64
    up1     ConvT 2×2 256 -> 128, cat [down2, up] = 256, ResBlock(3) -> 128   @ 72×128
    up2     ConvT 128 -> 64,  cat [down1, up] = 128, ResBlock(2) -> 64        @ 144×256
    up3     ConvT 64 -> 32,   cat [inc, up]   = 64,  ResBlock(2) -> 32        @ 288×512
    outc    1×1 32 -> frames_out (logits)
"""
from __future__ import annotations

from collections import OrderedDict

import torch
from torch import nn

from .layers import Down, OutConv, Up, check_input, conv_bn_relu


class Neck(nn.Module):
    """Two conv-BN-ReLU layers whose outputs are summed: ``(B, in, H, W) -> (B, out, H, W)``.

    Keys: ``conv1.{0,1}``, ``conv2.{0,1}`` (conv, BN).
    """

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.conv1 = nn.Sequential(*conv_bn_relu(in_channels, out_channels, bias=True))
        self.conv2 = nn.Sequential(*conv_bn_relu(out_channels, out_channels, bias=True))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out1 = self.conv1(x)
        return out1 + self.conv2(out1)


class ResBlock(nn.Module):
    """``num_convs`` × conv-BN-ReLU plus a 1×1 conv shortcut, added without a final activation.

    ``(B, in, H, W) -> (B, out, H, W)``. Keys: ``convs.{conv0,bn0,conv1,bn1,…}`` and ``conv0`` (shortcut).
    """

    def __init__(self, in_channels: int, out_channels: int, num_convs: int):
        super().__init__()
        self.conv0 = nn.Conv2d(in_channels, out_channels, kernel_size=1)
        layers: OrderedDict[str, nn.Module] = OrderedDict()
        for i in range(num_convs):
            conv, bn, relu = conv_bn_relu(in_channels if i == 0 else out_channels, out_channels, bias=True)
            layers.update({f"conv{i}": conv, f"bn{i}": bn, f"relu{i}": relu})
        self.convs = nn.Sequential(layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.convs(x) + self.conv0(x)


def up_block(deep_channels: int, skip_channels: int, out_channels: int, num_convs: int) -> Up:
    """2×2 stride-2 transposed conv halving ``deep_channels``, concat with the skip, then a ResBlock."""
    up = nn.ConvTranspose2d(deep_channels, deep_channels // 2, kernel_size=2, stride=2)
    return Up(up, ResBlock(deep_channels // 2 + skip_channels, out_channels, num_convs))


class MonoTrack(nn.Module):
    """WASB-SBDT's MonoTrack residual U-Net.

    Args:
        frames_in: consecutive RGB frames stacked on channels (input has ``3 * frames_in`` channels).
        frames_out: heatmaps predicted, one per frame.

    Input ``(B, 3·frames_in, H, W)`` float, H and W multiples of 8 (default 288×512). Output
    ``(B, frames_out, H, W)`` logits: apply a sigmoid for heatmaps. 2,903,171 parameters for 3 in / 3 out.
    """

    def __init__(self, frames_in: int = 3, frames_out: int = 3):
        super().__init__()
        self.frames_in = frames_in
        self.frames_out = frames_out
        self.inc = Neck(3 * frames_in, 32)
        self.down1 = Down(ResBlock(32, 64, num_convs=2))
        self.down2 = Down(ResBlock(64, 128, num_convs=3))
        self.down3 = Down(ResBlock(128, 256, num_convs=3))
        self.up1 = up_block(256, 128, 128, num_convs=3)
        self.up2 = up_block(128, 64, 64, num_convs=2)
        self.up3 = up_block(64, 32, 32, num_convs=2)
        self.outc = OutConv(32, frames_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 3·frames_in, H, W) -> (B, frames_out, H, W)`` logits."""
        check_input(x, 3 * self.frames_in, "MonoTrack")
        x1 = self.inc(x)
        x2 = self.down1(x1)
        x3 = self.down2(x2)
        x = self.down3(x3)
        x = self.up1(x, x3)
        x = self.up2(x, x2)
        x = self.up3(x, x1)
        return self.outc(x)
