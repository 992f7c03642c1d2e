"""Detector network: parameter counts, output shapes, attention blocks, BatchNorm fusion."""
import os

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import pytest
import torch

from dockfactory.detector.attention import (
    ATTENTIONS,
    ECA,
    eca_kernel_size,
    make_attention,
)
from dockfactory.detector.model import (
    DEFAULT_ANCHORS_P2,
    ModelConfig,
    build_model,
    count_parameters,
)

# 2 classes, BatchNorm unfused. 'none' equals YOLOv5 v6's published unfused 80-class counts
# (n 1,872,157; s 7,235,389) minus the Detect convs' (sum of head channels + 3) x 234 weights;
# the attention blocks add SE 2 C^2/16, ECA k, CBAM 2 C^2/16 + 98, A2 3 (C C/4 + C/4) + C/4 C + C.
PARAMS = {
    "n": {"none": 1_766_623, "se": 1_774_815, "eca": 1_766_628, "cbam": 1_774_913, "a2": 1_832_607},
    "s": {"none": 7_025_023, "se": 7_057_791, "eca": 7_025_028, "cbam": 7_057_889, "a2": 7_288_063},
}


@pytest.mark.parametrize("scale", ["n", "s"])
@pytest.mark.parametrize("attention", ATTENTIONS)
def test_parameter_counts_and_shapes(scale, attention):
    model = build_model(ModelConfig(scale=scale, attention=attention))
    assert count_parameters(model) == PARAMS[scale][attention]
    h, w = 64, 96
    x = torch.rand(2, 3, h, w, generator=torch.Generator().manual_seed(0))
    model.train()
    raw = model(x)
    assert [tuple(r.shape) for r in raw] == [(2, 3, h // s, w // s, 7) for s in (8, 16, 32)]
    model.eval()
    with torch.inference_mode():
        y = model(x)
    n = 3 * sum((h // s) * (w // s) for s in (8, 16, 32))
    assert tuple(y.shape) == (2, n, 7)
    assert torch.isfinite(y).all()
    assert ((y[..., 4:] >= 0) & (y[..., 4:] <= 1)).all()


def test_published_sizes():
    assert round(PARAMS["n"]["none"] / 1e6, 2) == 1.77
    assert round(PARAMS["s"]["none"] / 1e6, 2) == 7.03


def test_p2_head_shapes():
    model = build_model(ModelConfig(scale="n", attention="se", p2=True, anchors=DEFAULT_ANCHORS_P2)).train()
    raw = model(torch.zeros(1, 3, 64, 64))
    assert [tuple(r.shape[2:4]) for r in raw] == [(16, 16), (8, 8), (4, 4), (2, 2)]


@pytest.mark.parametrize("attention", ATTENTIONS)
def test_attention_keeps_shape(attention):
    block = make_attention(attention, 64)
    x = torch.randn(2, 64, 5, 7, generator=torch.Generator().manual_seed(1))
    assert block(x).shape == x.shape


def test_eca_kernel_sizes():
    assert eca_kernel_size(256) == 5 and eca_kernel_size(512) == 5 and eca_kernel_size(64) == 3
    assert ECA(256).conv.kernel_size == (5,)


def test_fused_model_matches_unfused():
    model = build_model(ModelConfig(scale="n", attention="se"), seed=3)
    # give BatchNorm non-trivial statistics
    model.train()
    with torch.no_grad():
        for _ in range(2):
            model(torch.rand(2, 3, 64, 64, generator=torch.Generator().manual_seed(_)))
    model.eval()
    x = torch.rand(1, 3, 64, 64, generator=torch.Generator().manual_seed(9))
    with torch.inference_mode():
        ref = model(x)
        got = model.fuse()(x)
    assert torch.allclose(ref, got, atol=1e-3, rtol=1e-4)


def test_seeded_init_and_no_global_rng_change():
    state = torch.random.get_rng_state()
    a = build_model(ModelConfig(scale="n", attention="none"), seed=5)
    b = build_model(ModelConfig(scale="n", attention="none"), seed=5)
    assert torch.equal(torch.random.get_rng_state(), state)
    assert all(torch.equal(p, q) for p, q in zip(a.state_dict().values(), b.state_dict().values()))


@pytest.mark.parametrize("kwargs, word", [({"scale": "m"}, "scale"), ({"attention": "xx"}, "attention"),
                                          ({"anchors": ((1, 2),)}, "anchors"), ({"num_classes": 0}, "num_classes")])
def test_bad_config_raises(kwargs, word):
    with pytest.raises(ValueError, match=word):
        ModelConfig(**kwargs)


def test_bad_input_shape_raises():
    model = build_model(ModelConfig(scale="n", attention="none")).eval()
    with pytest.raises(ValueError, match="multiples of 32"):
        model(torch.zeros(1, 3, 50, 64))
    with pytest.raises(ValueError, match="B, 3, H, W"):
        model(torch.zeros(1, 1, 64, 64))
