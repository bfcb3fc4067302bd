"""TrackNetV2 as re-implemented in PyTorch by WASB-SBDT (``src/models/unet2d.py``), weight-compatible with
its public ``tracknetv2_*_best.pth.tar`` checkpoints.

A VGG-style U-Net; every convolution is 3×3 with bias, followed by ReLU and *then* BatchNorm (the order of
the Keras original, but with BN over channels). Channels @ resolution for a 288×512 input::

    inc     2 convs  9  -> 64            @ 288×512
    down1   pool, 2 convs -> 128         @ 144×256
    down2   pool, 3 convs -> 256         @ 72×128
    down3   pool, 3 convs -> 512         @ 36×64
    up1     nearest ×2, cat [down2, up] = 768, 3 convs -> 256   @ 72×128
    up2     nearest ×2, cat [down1, up] = 384, 2 convs -> 128   @ 144×256
    up3     nearest ×2, cat [inc, up]   = 192, 2 convs -> 64    @ 288×512
    outc    1×1 64 -> frames_out (logits)
"""
from __future__ import annotations

import torch
from torch import nn

from .layers import Down, OutConv, Up, check_input, conv_bn_relu


def conv_relu_bn_stack(in_channels: int, out_channels: int, num_convs: int) -> nn.Sequential:
    """``num_convs`` × [3×3 conv (bias), ReLU, BN]: ``(B, in, H, W) -> (B, out, H, W)``.

    Keys: ``{3i}.weight/bias`` (conv) and ``{3i+2}.*`` (BN) for conv ``i``.
    """
    layers: list[nn.Module] = []
    for i in range(num_convs):
        layers += conv_bn_relu(in_channels if i == 0 else out_channels, out_channels, bias=True, relu_before_bn=True)
    return nn.Sequential(*layers)


class DoubleConv(nn.Module):
    """Two conv-ReLU-BN layers (keys ``double_conv.*``): ``(B, in, H, W) -> (B, out, H, W)``."""

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.double_conv = conv_relu_bn_stack(in_channels, out_channels, 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.double_conv(x)


class TripleConv(nn.Module):
    """Three conv-ReLU-BN layers (keys ``triple_conv.*``): ``(B, in, H, W) -> (B, out, H, W)``."""

    def __init__(self, in_channels: int, out_channels: int):
        super().__init__()
        self.triple_conv = conv_relu_bn_stack(in_channels, out_channels, 3)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.triple_conv(x)


def nearest_up() -> nn.Upsample:
    """Parameter-free nearest-neighbour ×2 upsampling."""
    return nn.Upsample(scale_factor=2, mode="nearest")


class TrackNetV2(nn.Module):
    """WASB-SBDT's TrackNetV2 U-Net.

    Args:
        frames_in: consecutive RGB frames stacked on channels (input has ``3 * frames_in`` channels).
        frames_out: heatmaps predicted, one per frame.

    Input ``(B, 3·frames_in, H, W)`` float, H and W multiples of 8 (default 288×512). Output
    ``(B, frames_out, H, W)`` logits: apply a sigmoid for heatmaps. 11,334,147 parameters for 3 in / 3 out.
    """

    def __init__(self, frames_in: int = 3, frames_out: int = 3):
        super().__init__()
        self.frames_in = frames_in
        self.frames_out = frames_out
        self.inc = DoubleConv(3 * frames_in, 64)
        self.down1 = Down(DoubleConv(64, 128))
        self.down2 = Down(TripleConv(128, 256))
        self.down3 = Down(TripleConv(256, 512))
        self.up1 = Up(nearest_up(), TripleConv(512 + 256, 256))
        self.up2 = Up(nearest_up(), DoubleConv(256 + 128, 128))
        self.up3 = Up(nearest_up(), DoubleConv(128 + 64, 64))
        self.outc = OutConv(64, frames_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 3·frames_in, H, W) -> (B, frames_out, H, W)`` logits."""
        check_input(x, 3 * self.frames_in, "TrackNetV2")
        x1 = self.inc(x)
        x2 = self.down1(x1)
        x3 = self.down2(x2)
        x = self.down3(x3)
        x = self.up1(x, x3)
        x = self.up2(x, x2)
        x = self.up3(x, x1)
        return self.outc(x)
