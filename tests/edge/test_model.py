"""FCN-8s model: the paper's parameter counts, the encoder contract, weights and checkpoints."""

from __future__ import annotations

import pytest
import torch

from edge.errors import ConfigError, ModelError
from edge.meta import ModelMeta
from edge.train import encoders
from edge.train.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
from edge.train.encoders import VGG_CFGS, VGGEncoder, create_encoder, list_encoders, register_encoder
from edge.train.model import FCN8s, build_model, count_parameters, freeze_encoder, load_vgg_weights

TINY_WIDTH = 0.0625
STRIDES = {"conv1": 1, "pool1": 2, "pool2": 4, "pool3": 8, "pool4": 16, "pool5": 32}


def tiny(encoder: str = "vgg11", **kw) -> FCN8s:
    torch.manual_seed(0)
    meta = ModelMeta(encoder=encoder, width=kw.pop("width", TINY_WIDTH), **kw)
    return build_model(meta).eval()


def test_vgg16_parameter_counts_match_the_paper():
    model = build_model(ModelMeta(encoder="vgg16", width=1.0, in_channels=3))
    assert count_parameters(model) == 18_643_713
    freeze_encoder(model)
    assert count_parameters(model, trainable_only=True) == 3_929_025
    assert count_parameters(model) == 18_643_713


@pytest.mark.parametrize("name", list_encoders())
@pytest.mark.parametrize("size", [(192, 224), (64, 96), (32, 32)])
def test_output_size_equals_input_size(name, size):
    model = tiny(name, in_channels=1)
    x = torch.randn(2, 1, *size)
    with torch.inference_mode():
        y = model(x)
    assert y.shape == (2, 1, *size)
    assert torch.isfinite(y).all()


@pytest.mark.parametrize("channels", [1, 3])
def test_three_and_one_channel_and_extra_skip(channels):
    for extra in (False, True):
        model = tiny("vgg16", in_channels=channels, extra_skip=extra)
        with torch.inference_mode():
            assert model(torch.randn(1, channels, 192, 224)).shape == (1, 1, 192, 224)


def test_extra_skip_changes_the_output_not_the_parameters():
    a, b = tiny("vgg11", extra_skip=False), tiny("vgg11", extra_skip=True)
    assert count_parameters(a) == count_parameters(b)
    b.load_state_dict(a.state_dict())
    x = torch.randn(1, 3, 64, 64)
    with torch.inference_mode():
        assert not torch.allclose(a(x), b(x))


@pytest.mark.parametrize("size", [(171, 224), (100, 64)])
def test_non_multiple_of_32_raises_naming_the_padded_size(size):
    model = tiny("vgg11", in_channels=1)
    hp, wp = (-(-size[0] // 32) * 32, -(-size[1] // 32) * 32)
    with pytest.raises(ModelError, match=rf"pad to \({hp}, {wp}\)"):
        model(torch.zeros(1, 1, *size))


def test_full_skip_adds_one_projection_and_reaches_the_output():
    a, b = tiny("vgg11", extra_skip=True), tiny("vgg11", extra_skip=True, full_skip=True)
    c1, dec = a.encoder.out_channels["conv1"], a.classifier.in_channels
    assert count_parameters(b) - count_parameters(a) == c1 * dec + dec  # a 1x1 conv with bias
    b.load_state_dict(a.state_dict(), strict=False)
    x = torch.randn(1, 3, 64, 64)
    with torch.inference_mode():
        assert b(x).shape == (1, 1, 64, 64)
        assert not torch.allclose(a(x), b(x))
        b.full_proj.weight.zero_()
        b.full_proj.bias.zero_()
        assert torch.allclose(a(x), b(x))  # with the projection at zero it is the plain model


def test_full_skip_metadata_is_left_out_when_off():
    assert "full_skip" not in ModelMeta().to_dict()  # older models keep their metadata byte for byte
    m = ModelMeta(encoder="vgg11", full_skip=True)
    assert ModelMeta.from_json(m.to_json()).full_skip is True
    with pytest.raises(ModelError, match="full_skip"):
        ModelMeta(full_skip="yes")


@pytest.mark.parametrize("name", list_encoders())
def test_encoder_contract(name):
    enc = create_encoder(name, in_channels=1, width=0.125)
    assert isinstance(enc.features, torch.nn.Sequential)
    with torch.inference_mode():
        out = enc(torch.randn(1, 1, 64, 96))
    assert list(out) == ["conv1", "pool1", "pool2", "pool3", "pool4", "pool5"]  # highest resolution first
    assert set(enc.out_channels) == set(out)
    for key, t in out.items():
        s = STRIDES[key]
        assert t.shape == (1, enc.out_channels[key], 64 // s, 96 // s), key
    assert ("_bn" in name) == any(isinstance(m, torch.nn.BatchNorm2d) for m in enc.modules())


def test_full_width_channels_follow_torchvision():
    enc = create_encoder("vgg16", in_channels=3, width=1.0)
    assert enc.out_channels == {"conv1": 64, "pool1": 64, "pool2": 128, "pool3": 256, "pool4": 512, "pool5": 512}
    assert len(enc.features) == 31  # VGG16 `features`: the paper's first 31 layers


def test_registry_refuses_duplicates_and_lists_names(monkeypatch):
    with pytest.raises(ConfigError, match="already registered"):
        register_encoder("vgg16")(lambda **kw: None)
    with pytest.raises(ConfigError) as exc:
        create_encoder("resnet50")
    for name in ("vgg11", "vgg16", "vgg19", "vgg16_bn"):
        assert name in str(exc.value)
    with pytest.raises(ConfigError, match="width"):
        create_encoder("vgg11", width=0)
    # a new name registers (on a copy of the registry, so other tests are unaffected)
    monkeypatch.setattr(encoders, "_REGISTRY", dict(encoders._REGISTRY))
    register_encoder("vgg11_custom")(lambda *, in_channels=3, width=1.0: VGGEncoder(VGG_CFGS["vgg11"], in_channels, width))
    assert "vgg11_custom" in list_encoders()
    assert isinstance(create_encoder("vgg11_custom", width=0.125), VGGEncoder)


def test_unknown_encoder_in_metadata_is_a_clear_error():
    with pytest.raises(ConfigError, match="unknown encoder 'vgg99'"):
        build_model(ModelMeta(encoder="vgg99"))


@pytest.fixture(scope="module")
def vgg11_weights(tmp_path_factory):
    """A torchvision-format VGG11 state_dict ("features.N.weight"), random, saved like torchvision's."""
    torch.manual_seed(1)
    enc = VGGEncoder(VGG_CFGS["vgg11"], in_channels=3, width=1.0)
    sd = {f"features.{k}": v for k, v in enc.features.state_dict().items()}
    sd["classifier.0.weight"] = torch.zeros(2, 2)  # torchvision files carry a classifier too
    p = tmp_path_factory.mktemp("w") / "vgg11.pth"
    torch.save(sd, p)
    return p, sd


def test_load_vgg_weights_three_channels(vgg11_weights):
    path, sd = vgg11_weights
    model = build_model(ModelMeta(encoder="vgg11", width=1.0, in_channels=3))
    load_vgg_weights(model, str(path))
    own = model.encoder.features.state_dict()
    for k, v in own.items():
        assert torch.equal(v, sd[f"features.{k}"]), k


def test_load_vgg_weights_one_channel_sums_rgb(vgg11_weights):
    path, sd = vgg11_weights
    model = build_model(ModelMeta(encoder="vgg11", width=1.0, in_channels=1))
    load_vgg_weights(model, str(path))
    w0 = model.encoder.features[0].weight
    assert w0.shape == (64, 1, 3, 3)
    assert torch.allclose(w0, sd["features.0.weight"].sum(dim=1, keepdim=True))
    # a grey image replicated to RGB gives the same first-layer response as the summed kernel
    grey = torch.randn(1, 1, 32, 32)
    conv3 = torch.nn.functional.conv2d(grey.repeat(1, 3, 1, 1), sd["features.0.weight"], sd["features.0.bias"], padding=1)
    with torch.inference_mode():
        assert torch.allclose(model.encoder.features[0](grey), conv3, atol=1e-5)


def test_load_vgg_weights_rejects_mismatch_and_junk(vgg11_weights, tmp_path):
    path, _ = vgg11_weights
    with pytest.raises(ModelError, match="does not fit"):
        load_vgg_weights(build_model(ModelMeta(encoder="vgg16", width=1.0)), str(path))
    with pytest.raises(ModelError, match="does not fit"):
        load_vgg_weights(tiny("vgg11"), str(path))
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"\x00garbage")
    with pytest.raises(ModelError, match="not a readable"):
        load_vgg_weights(tiny("vgg11"), str(junk))
    nofeat = tmp_path / "nofeat.pth"
    torch.save({"fc.weight": torch.zeros(1)}, nofeat)
    with pytest.raises(ModelError, match="features"):
        load_vgg_weights(tiny("vgg11"), str(nofeat))
    with pytest.raises(ModelError, match="no such"):
        load_vgg_weights(tiny("vgg11"), str(tmp_path / "missing.pth"))


def test_checkpoint_round_trip(tmp_path):
    meta = ModelMeta(encoder="vgg11", width=TINY_WIDTH, batch_norm=True, in_channels=1, threshold=0.7)
    model = tiny("vgg11", batch_norm=True, in_channels=1)
    p = save_checkpoint(tmp_path / "m.pt", model, meta, epoch=3)
    loaded, lmeta, blob = load_checkpoint(p)
    assert lmeta.threshold == 0.7 and lmeta.params == count_parameters(model) and blob["epoch"] == 3
    x = torch.randn(1, 1, 64, 64)
    with torch.inference_mode():
        assert torch.equal(loaded(x), model(x))
    assert not list(tmp_path.glob(".*tmp"))  # atomic write leaves no temp file


def test_corrupt_checkpoint_is_a_clear_model_error(tmp_path):
    meta = ModelMeta(encoder="vgg11", width=TINY_WIDTH, in_channels=1)
    good = save_checkpoint(tmp_path / "good.pt", tiny("vgg11", in_channels=1), meta)
    data = good.read_bytes()
    bad = tmp_path / "truncated.pt"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(ModelError, match="not a readable depthseg checkpoint"):
        load_checkpoint(bad)
    other = tmp_path / "other.pt"
    torch.save({"weights": 1}, other)
    with pytest.raises(ModelError, match="not a depthseg checkpoint"):
        read_checkpoint(other)
    wrong = tmp_path / "wrong.pt"
    blob = torch.load(good, weights_only=False)
    blob["meta"]["encoder"] = "vgg16"
    torch.save(blob, wrong)
    with pytest.raises(ModelError, match="do not match"):
        load_checkpoint(wrong)
    with pytest.raises(ModelError, match="no such model file"):
        load_checkpoint(tmp_path / "missing.pt")
