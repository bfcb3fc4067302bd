"""Ball detectors: exact WASB-SBDT state_dict layouts, parameter counts, shapes, checkpoint formats and errors.

``wasb_sbdt_state_dicts.json`` lists every tensor (name, shape, dtype) of the public WASB-SBDT models,
instantiated from nttcom/WASB-SBDT @923462c with 9 input channels and 3 outputs.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest
import torch
from torch import nn

from inference.models import MODEL_NAMES, MonoTrack, TrackNetV2, WASB, build_model, load_weights, save_wasb_checkpoint

REFERENCE = json.loads(Path(__file__).with_name("wasb_sbdt_state_dicts.json").read_text())
PARAMETERS = {"wasb": 1_481_427, "tracknetv2": 11_334_147, "monotrack": 2_903_171}  # docs/models.md
TINY = (1, 9, 32, 64)


@pytest.fixture(scope="module")
def models() -> dict[str, nn.Module]:
    """One model per name, with random BN statistics so eval outputs depend on every buffer."""
    torch.manual_seed(0)
    built = {}
    for name in MODEL_NAMES:
        model = build_model(name)
        for m in model.modules():
            if isinstance(m, nn.BatchNorm2d):
                m.running_mean.uniform_(-0.1, 0.1)
                m.running_var.uniform_(0.5, 1.5)
        built[name] = model.eval()
    return built


def forward(model: nn.Module, x: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        return model.eval()(x)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_state_dict_equals_reference_tensor_by_tensor(models, name):
    ours = [[k, list(v.shape), str(v.dtype).removeprefix("torch.")] for k, v in models[name].state_dict().items()]
    assert ours == REFERENCE[name]["state_dict"]


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_parameter_counts(models, name):
    count = sum(p.numel() for p in models[name].parameters())
    assert count == PARAMETERS[name] == REFERENCE[name]["n_parameters"]


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_forward_shape_and_frame_counts(models, name):
    assert forward(models[name], torch.randn(TINY)).shape == (1, 3, 32, 64)
    five_to_one = build_model(name, frames_in=5, frames_out=1)
    assert forward(five_to_one, torch.randn(2, 15, 16, 24)).shape == (2, 1, 16, 24)


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_bad_input_is_rejected(models, name):
    with pytest.raises(ValueError, match=r"\(B, 9, H, W\)"):
        models[name](torch.randn(1, 3, 32, 64))
    with pytest.raises(ValueError, match="divisible by 8"):
        models[name](torch.randn(1, 9, 36, 64))


def test_registry():
    assert MODEL_NAMES == ("wasb", "tracknetv2", "monotrack")
    assert type(build_model("wasb")) is WASB
    assert type(build_model("tracknetv2")) is TrackNetV2
    assert type(build_model("monotrack")) is MonoTrack
    with pytest.raises(ValueError, match="valid names: wasb, tracknetv2, monotrack"):
        build_model("tracknetv3")


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_public_format_round_trip(models, name, tmp_path):
    path = save_wasb_checkpoint(models[name], tmp_path / f"{name}_tennis_best.pth.tar", epoch=7, train_loss=0.25)
    ckpt = torch.load(path, map_location="cpu", weights_only=True)
    assert set(ckpt) == {"model_state_dict", "epoch", "train_loss", "rally3d_detector"}
    assert not any(k.startswith("module.") for k in ckpt["model_state_dict"])

    fresh = build_model(name)
    info = load_weights(fresh, path)
    assert info["format"] == "wasb" and info["meta"] == {"epoch": 7, "train_loss": 0.25}
    assert info["input"].arch == name and info["input"].origin == "stored"
    assert info["missing_keys"] == info["unexpected_keys"] == []
    x = torch.randn(TINY)
    torch.testing.assert_close(forward(fresh, x), forward(models[name], x), rtol=0, atol=0)


def _checkpoint_variants(model: nn.Module) -> dict[str, object]:
    state = model.state_dict()
    return {
        "raw": state,
        "wasb": {"model_state_dict": state, "epoch": 3},
        "dataparallel": {"model_state_dict": nn.DataParallel(model).state_dict(), "epoch": 3},
        "lightning": {
            "state_dict": {**{f"model.{k}": v for k, v in state.items()}, "loss.pos_weight": torch.ones(1)},
            "epoch": 3,
            "global_step": 120,
        },
        "lightning_dataparallel": {"state_dict": {f"model.module.{k}": v for k, v in state.items()}},
    }


@pytest.mark.parametrize("variant", ["raw", "wasb", "dataparallel", "lightning", "lightning_dataparallel"])
@pytest.mark.parametrize("in_memory", [False, True], ids=["file", "mapping"])
def test_checkpoint_variants_load_strictly(models, variant, in_memory, tmp_path):
    source = _checkpoint_variants(models["wasb"])[variant]
    if not in_memory:
        torch.save(source, tmp_path / "ckpt.pth")
        source = tmp_path / "ckpt.pth"
    fresh = WASB()
    info = load_weights(fresh, source, strict=True)
    assert info["missing_keys"] == info["unexpected_keys"] == []
    if variant.startswith("lightning"):
        assert info["format"] == "lightning"
        assert info["ignored_keys"] == (["loss.pos_weight"] if variant == "lightning" else [])
    x = torch.randn(TINY)
    torch.testing.assert_close(forward(fresh, x), forward(models["wasb"], x), rtol=0, atol=0)


def test_load_into_dataparallel_model(models):
    wrapped = nn.DataParallel(WASB())
    load_weights(wrapped, {"model_state_dict": models["wasb"].state_dict()})
    x = torch.randn(TINY)
    torch.testing.assert_close(forward(wrapped.module, x), forward(models["wasb"], x), rtol=0, atol=0)


def test_wrong_architecture_names_first_mismatching_tensor(models, tmp_path):
    path = save_wasb_checkpoint(models["wasb"], tmp_path / "wasb_tennis_best.pth.tar")
    with pytest.raises(ValueError) as err:
        load_weights(TrackNetV2(), path)
    msg = str(err.value)
    assert "'inc.double_conv.0.weight': expected (64, 9, 3, 3), found missing" in msg
    assert "121 missing, 428 unexpected" in msg
    assert "model.net.name=wasb" in msg and "--model wasb" in msg
    assert len(msg) < 600


def test_one_reshaped_tensor_is_named(models):
    state = dict(models["monotrack"].state_dict())
    state["up2.up.weight"] = torch.zeros(128, 32, 2, 2)
    with pytest.raises(ValueError, match=r"'up2.up.weight': expected \(128, 64, 2, 2\), found \(128, 32, 2, 2\)"):
        load_weights(MonoTrack(), state)
    with pytest.raises(ValueError, match="up2.up.weight"):  # a shape mismatch fails even when not strict
        load_weights(MonoTrack(), state, strict=False)


def test_other_frame_counts_are_reported():
    with pytest.raises(ValueError, match=r"'conv1.weight': expected \(64, 9, 3, 3\), found \(64, 15, 3, 3\).*frames_in"):
        load_weights(WASB(), WASB(frames_in=5).state_dict())


def test_non_strict_reports_missing_keys(models):
    state = {k: v for k, v in models["wasb"].state_dict().items() if not k.startswith("final_layers")}
    with pytest.raises(ValueError, match=r"'final_layers.0.weight': expected \(3, 16, 1, 1\), found missing"):
        load_weights(WASB(), state)
    info = load_weights(WASB(), state, strict=False)
    assert info["missing_keys"] == ["final_layers.0.weight", "final_layers.0.bias"]


def test_missing_file_is_explained(tmp_path):
    path = tmp_path / "nowhere" / "wasb_tennis_best.pth.tar"
    with pytest.raises(FileNotFoundError) as err:
        load_weights(WASB(), path)
    assert str(path) in str(err.value)
    assert "never downloads" in str(err.value) and "init_weights=PATH" in str(err.value)


def test_not_a_checkpoint():
    with pytest.raises(ValueError, match="not a recognised checkpoint"):
        load_weights(WASB(), {"optimizer": {"lr": 1.0}})


def test_pickled_objects_need_consent(models, tmp_path):
    from inference.models import UntrustedCheckpointError

    path = tmp_path / "with_config.pth.tar"
    torch.save({"model_state_dict": models["wasb"].state_dict(), "cfg": argparse.Namespace(lr=1.0)}, path)
    with pytest.raises(UntrustedCheckpointError, match=r"argparse.Namespace.*--trust-checkpoint"):
        load_weights(WASB(), path)
    info = load_weights(WASB(), path, trust=True)
    assert info["format"] == "wasb"


def test_unreadable_file(tmp_path):
    path = tmp_path / "broken.pth.tar"
    path.write_text("not a checkpoint")
    with pytest.raises(ValueError, match="cannot read"):
        load_weights(WASB(), path)
    path.write_bytes(b"\x80\x02truncated")  # a truncated legacy pickle
    with pytest.raises(ValueError, match="cannot read"):
        load_weights(WASB(), path)


def test_shipped_weights_load_strictly():
    """The weights rally3d ships (inference/weights) load into WASB with strict=True."""
    from inference.detection.detect import SHIPPED
    from inference.models.checkpoint import load_weights
    from inference.models.registry import build_model

    path = SHIPPED["wasb"]
    if not path.is_file():
        pytest.skip("no shipped weights")
    info = load_weights(build_model("wasb"), path)
    assert not info["missing_keys"] and not info["unexpected_keys"]
