"""A small ResNet-style image encoder written here (no torchvision), the readout that turns a
feature map into a token, and colour jitter.

GroupNorm instead of BatchNorm, as in Diffusion Policy: batch statistics would differ between
the episode-ordered training batches and single-frame inference. Each camera's feature map is
pooled two ways: the channel mean (what is there) and spatial-softmax keypoints (where it is);
a small CNN's mean alone keeps too little position for manipulation. The same readout serves
the heads over a frozen backbone's feature maps (``backbone.py``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn


def _groups(channels: int) -> int:
    return min(8, channels // 4) or 1


class ResBlock(nn.Module):
    def __init__(self, c_in: int, c_out: int, stride: int):
        super().__init__()
        self.conv1 = nn.Conv2d(c_in, c_out, 3, stride, 1, bias=False)
        self.norm1 = nn.GroupNorm(_groups(c_out), c_out)
        self.conv2 = nn.Conv2d(c_out, c_out, 3, 1, 1, bias=False)
        self.norm2 = nn.GroupNorm(_groups(c_out), c_out)
        self.skip = (nn.Identity() if stride == 1 and c_in == c_out else
                     nn.Sequential(nn.Conv2d(c_in, c_out, 1, stride, bias=False),
                                   nn.GroupNorm(_groups(c_out), c_out)))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = F.relu(self.norm1(self.conv1(x)))
        return F.relu(self.norm2(self.conv2(y)) + self.skip(x))


class SpatialSoftmax(nn.Module):
    """(B, C, H, W) -> (B, 2K): expected image coordinates of K learned keypoint maps."""

    def __init__(self, channels: int, keypoints: int):
        super().__init__()
        self.proj = nn.Conv2d(channels, keypoints, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, _, h, w = x.shape
        attn = self.proj(x).flatten(2).softmax(-1)  # (B, K, HW)
        ys = torch.linspace(-1, 1, h, device=x.device, dtype=x.dtype)
        xs = torch.linspace(-1, 1, w, device=x.device, dtype=x.dtype)
        grid = torch.stack(torch.meshgrid(ys, xs, indexing="ij"), -1).reshape(h * w, 2)
        return (attn @ grid).reshape(b, -1)


class Readout(nn.Module):
    """The end of an encoder: a (B, C, h, w) feature map -> a d-dim token, [channel mean;
    spatial-softmax keypoints] through a linear layer and LayerNorm; or with ``pooled=False`` a
    1x1 convolution to a d-dim map (B, d, h, w). A subclass builds its trunk, then calls
    ``build_readout`` (its modules, ``keypoints`` and ``out``, are named and created after the
    trunk's, so the weights' names and initial values do not depend on this base)."""

    def build_readout(self, channels: int, dim: int, keypoints: int, pooled: bool) -> None:
        self.pooled = pooled
        if pooled:
            self.keypoints = SpatialSoftmax(channels, keypoints)
            self.out = nn.Sequential(nn.Linear(channels + 2 * keypoints, dim), nn.LayerNorm(dim))
        else:
            self.out = nn.Conv2d(channels, dim, 1)

    def readout(self, x: torch.Tensor) -> torch.Tensor:
        if not self.pooled:
            return self.out(x)
        return self.out(torch.cat([x.mean((2, 3)), self.keypoints(x)], -1))


class ImageEncoder(Readout):
    """uint8 images (B, 3, H, W) -> one d-dim token per image, or with ``pooled=False`` a d-dim
    feature map (B, d, H / 2^n, W / 2^n) for models that attend over image patches (ACT).

    ``channels`` are the stage widths; every stage halves the resolution (the stem too)."""

    def __init__(self, dim: int, channels: tuple[int, ...] = (32, 64, 128, 128), keypoints: int = 32,
                 pooled: bool = True):
        super().__init__()
        self.stem = nn.Sequential(nn.Conv2d(3, channels[0], 5, 2, 2, bias=False),
                                  nn.GroupNorm(_groups(channels[0]), channels[0]), nn.ReLU())
        stages, c = [], channels[0]
        for c_out in channels[1:]:
            stages.append(ResBlock(c, c_out, stride=2))
            c = c_out
        self.stages = nn.Sequential(*stages)
        self.build_readout(c, dim, keypoints, pooled)
        self.register_buffer("mean", torch.tensor([0.485, 0.456, 0.406]).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor([0.229, 0.224, 0.225]).view(1, 3, 1, 1))

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        # contiguous (NCHW) input: a permuted HWC frame reaches oneDNN's convolution as
        # channels-last, whose weight-gradient kernel corrupts the heap on multi-threaded CPU
        # (torch 2.13, seen as a double free in mkldnn_convolution_backward_weights)
        x = images.contiguous()
        x = x.float() / 255.0 if x.dtype == torch.uint8 else x
        return self.readout(self.stages(self.stem((x - self.mean) / self.std)))


class PerCamera(nn.ModuleList):
    """One module per camera (the cameras see different things): a list of per-camera inputs,
    in camera order, -> their outputs stacked (B, cameras, ...). A ModuleList, so its weights
    are named ``<name>.<camera index>.*``."""

    def forward(self, inputs: list[torch.Tensor]) -> torch.Tensor:
        return torch.stack([m(x) for m, x in zip(self, inputs, strict=True)], 1)


class CameraEncoders(PerCamera):
    """One ImageEncoder per camera: a list of uint8 (B, 3, H, W) images -> tokens
    (B, cameras, dim), or feature maps (B, cameras, dim, h, w) when not ``pooled``."""

    def __init__(self, cameras: int, dim: int, channels: tuple[int, ...], keypoints: int,
                 pooled: bool = True):
        super().__init__(ImageEncoder(dim, channels, keypoints, pooled) for _ in range(cameras))


def color_jitter(images: torch.Tensor, generator: torch.Generator | None, brightness: float = 0.1,
                 contrast: float = 0.1, saturation: float = 0.1) -> torch.Tensor:
    """Per-image random brightness, contrast and saturation factors in [1 - a, 1 + a] (the
    published (0.1, 0.1, 0.1, 0) jitter, without hue). uint8 in, uint8 out."""
    b = images.shape[0]
    x = images.float()

    def factor(a: float) -> torch.Tensor:
        u = torch.rand(b, 1, 1, 1, generator=generator, device="cpu").to(x.device)
        return 1 + a * (2 * u - 1)

    x = x * factor(brightness)
    mean = x.mean((1, 2, 3), keepdim=True)
    x = (x - mean) * factor(contrast) + mean
    gray = (0.299 * x[:, 0:1] + 0.587 * x[:, 1:2] + 0.114 * x[:, 2:3])
    x = (x - gray) * factor(saturation) + gray
    return x.clamp(0, 255).round().to(torch.uint8)
