"""NCHW batch norms inside channels-last training (`edge.train.layout`, `--nchw-bn-channels`)."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch
from torch import nn

from edge.errors import ConfigError
from edge.train.layout import NCHWBatchNorm2d, nchw_batch_norms
from edge.train.loop import TrainConfig

CL = torch.channels_last


def _net() -> nn.Sequential:
    torch.manual_seed(0)
    return nn.Sequential(nn.Conv2d(3, 4, 3, padding=1), nn.BatchNorm2d(4), nn.ReLU(),
                         nn.Conv2d(4, 16, 3, padding=1), nn.BatchNorm2d(16)).to(memory_format=CL)


def test_only_the_small_batch_norms_change_and_keep_their_state() -> None:
    net = _net()
    keys, ids = list(net.state_dict()), [id(p) for p in net.parameters()]
    assert nchw_batch_norms(net, 8) == 1
    assert type(net[1]) is NCHWBatchNorm2d and type(net[4]) is nn.BatchNorm2d
    assert list(net.state_dict()) == keys and [id(p) for p in net.parameters()] == ids
    assert nchw_batch_norms(copy.deepcopy(net), 0) == 0


def test_training_matches_the_plain_batch_norm_to_rounding_and_stays_channels_last() -> None:
    plain, fast = _net(), _net()
    nchw_batch_norms(fast, 8)
    x = torch.randn(4, 3, 24, 32, generator=torch.Generator().manual_seed(1)).contiguous(memory_format=CL)
    outs = []
    for net in (plain, fast):
        y = net(x)
        y.square().mean().backward()
        outs.append((y, net[0].weight.grad, net[1].running_var))
    (y0, g0, v0), (y1, g1, v1) = outs
    assert y1.is_contiguous(memory_format=CL)
    assert torch.allclose(y0, y1, atol=1e-5) and torch.allclose(g0, g1, rtol=1e-4, atol=1e-6)
    assert torch.allclose(v0, v1, rtol=1e-5)
    fast.load_state_dict(plain.state_dict())  # outside training it is the plain batch norm, bit for bit
    fast.eval()
    plain.eval()
    with torch.no_grad():
        assert torch.equal(plain(x), fast(x))


@pytest.mark.parametrize("kw, needle", [({"nchw_bn": -1}, "nchw batch-norm"), ({"nchw_bn": 2.5}, "nchw batch-norm"),
                                        ({"nchw_bn": True}, "nchw batch-norm"),
                                        ({"nchw_bn": 8, "memory_format": "contiguous"}, "channels-last training only")])
def test_bad_values_are_refused(kw, needle) -> None:
    with pytest.raises(ConfigError, match=needle):
        TrainConfig(**kw)


def test_a_run_with_it_follows_the_plain_run_and_stores_plain_weights(tmp_path) -> None:
    from edge.meta import ModelMeta
    from edge.train.checkpoint import load_checkpoint
    from edge.train.data import FrameSet
    from edge.train.loop import train

    rng = np.random.default_rng(0)
    depth = (0.35 + rng.normal(0, 0.001, (8, 40, 48))).astype(np.float32)
    label = np.zeros((8, 40, 48), np.uint8)
    for i in range(8):
        y, x = rng.integers(0, 28, 2)
        label[i, y : y + 12, x : x + 12] = 1
    depth[label == 1] -= 0.03
    fs = FrameSet(depth, label)
    meta = ModelMeta(encoder="vgg11", width=0.125, batch_norm=True)
    runs = {}
    for n in (0, 8):
        cfg = TrainConfig(epochs=2, batch_size=2, seed=0, threads=1, boundary=2.0, nchw_bn=n)
        runs[n] = train(meta, fs.subset(np.arange(6)), fs.subset(np.arange(6, 8)), tmp_path / str(n), cfg)
    plain, fast = (runs[n].history[-1] for n in (0, 8))
    assert fast["train_loss"] == pytest.approx(plain["train_loss"], rel=1e-3)
    assert fast["val_loss"] == pytest.approx(plain["val_loss"], rel=1e-3)
    model, m, _ = load_checkpoint(runs[8].best_path)  # plain modules: inference never sees the option
    assert m.training["config"]["nchw_bn"] == 8
    assert not any(isinstance(x, NCHWBatchNorm2d) for x in model.modules())
