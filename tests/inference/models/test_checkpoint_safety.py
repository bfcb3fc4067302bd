"""Checkpoints are untrusted input: a pickle that would run code is refused unless the user opts in
(``--trust-checkpoint`` / ``trust=True``), the numpy allow-list loads, and every checkpoint says how its
input is normalised (stored by rally3d, WASB-SBDT's ImageNet convention for files that do not say)."""
from __future__ import annotations

import builtins
from pathlib import Path

import numpy as np
import pytest
import torch

from inference.detection.detect import BallDetectorRunner
from inference.detection.preprocess import normalize
from inference.models import (
    DetectorInput,
    UntrustedCheckpointError,
    build_model,
    load_detector,
    load_weights,
    save_wasb_checkpoint,
)
from inference.models.checkpoint import META_KEY, detector_input, read_checkpoint


class _CreatesFile:
    """Unpickling this object calls ``open(marker, "w")``: it creates a file on disk."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        return builtins.open, (self.marker, "w")


def malicious_checkpoint(path: Path, marker: Path, name: str = "wasb") -> Path:
    """A real, loadable WASB-SBDT-format checkpoint with a payload beside the weights."""
    torch.save({"model_state_dict": build_model(name).state_dict(), "epoch": 1, "payload": _CreatesFile(marker)},
               path)
    return path


def test_a_malicious_pickle_does_not_run_without_trust(tmp_path):
    marker = tmp_path / "pwned.txt"
    path = malicious_checkpoint(tmp_path / "evil.pth.tar", marker)
    with pytest.raises(UntrustedCheckpointError, match=r"\(io.open\).*--trust-checkpoint"):
        read_checkpoint(path)
    with pytest.raises(UntrustedCheckpointError):
        load_weights(build_model("wasb"), path)
    with pytest.raises(UntrustedCheckpointError):
        BallDetectorRunner.from_weights("wasb", path)
    assert not marker.exists()
    # the opt-in is what unpickles it, and then its code really runs (the test file is truly malicious)
    model, spec, _ = load_detector(path, "wasb", trust=True)
    assert marker.exists() and spec.arch == "wasb"


def test_cli_refuses_then_trusts(tmp_path, capsys):
    from inference.cli import main

    marker = tmp_path / "pwned.txt"
    path = malicious_checkpoint(tmp_path / "evil.pth.tar", marker)
    clip = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"
    out = tmp_path / "ball.csv"
    rc = main(["detect", str(clip), "--weights", str(path), "--out", str(out)])
    assert rc != 0 and not marker.exists() and not out.exists()
    assert "--trust-checkpoint" in capsys.readouterr().err
    rc = main(["infer", str(clip), "--detector", str(path), "--out", str(tmp_path / "infer"), "--only", "detect",
               "--no-progress"])
    assert rc != 0 and not marker.exists()
    # the parser accepts the opt-in on both commands
    from inference.cli import build_parser

    args = build_parser().parse_args(["detect", str(clip), "--weights", str(path), "--trust-checkpoint"])
    assert args.trust_checkpoint
    args = build_parser().parse_args(["infer", str(clip), "--detector", str(path), "--trust-checkpoint"])
    assert args.trust_checkpoint


def test_numpy_arrays_and_scalars_are_on_the_allow_list(tmp_path):
    path = tmp_path / "np.pth.tar"
    torch.save({"model_state_dict": build_model("wasb").state_dict(), "best": np.float64(0.8),
                "hist": np.arange(4, dtype=np.int32), "kind": np.dtype("float32")}, path)
    info = load_weights(build_model("wasb"), path)
    assert info["format"] == "wasb"
    assert read_checkpoint(path)["hist"].tolist() == [0, 1, 2, 3]


@pytest.mark.parametrize("name", ["wasb", "tracknetv2", "monotrack"])
def test_public_wasb_sbdt_files_get_imagenet_for_every_architecture(name, tmp_path):
    """WASB-SBDT trained every model with ImageNet mean/std: a public file (no rally3d entry) gets it."""
    path = tmp_path / f"{name}_tennis_best.pth.tar"
    torch.save({"model_state_dict": build_model(name).state_dict(), "epoch": 30}, path)
    assert META_KEY not in torch.load(path, weights_only=True)
    runner = BallDetectorRunner.from_weights(name, path)
    assert runner.normalize == "imagenet" and runner.net_size == (288, 512) and runner.frames_in == 3
    assert detector_input(read_checkpoint(path), name) == DetectorInput(name, origin="assumed")


def test_stored_input_description_drives_detection(tmp_path):
    """A rally3d file trained on /255 input at another size is run that way, whatever --model says."""
    torch.manual_seed(0)
    net = build_model("monotrack", frames_in=3, frames_out=1).eval()
    spec = DetectorInput("monotrack", 3, 1, "unit", (96, 160))
    path = save_wasb_checkpoint(net, tmp_path / "mono.pth.tar", input=spec)
    runner = BallDetectorRunner.from_weights("wasb", path)  # the file names its architecture: it wins
    assert (runner.normalize, runner.net_size, runner.frames_in) == ("unit", (96, 160), 3)
    frames = [np.full((96, 160, 3), v, np.uint8) for v in (40, 120, 200)]
    maps, _ = runner.heatmaps(frames)
    with torch.no_grad():
        expected = torch.sigmoid(net(torch.from_numpy(normalize(np.stack(frames), "unit"))[None]))[0, 0].numpy()
        wrong = torch.sigmoid(net(torch.from_numpy(normalize(np.stack(frames), "imagenet"))[None]))[0, 0].numpy()
    np.testing.assert_allclose(maps[2][0], expected, atol=1e-4)
    assert np.abs(maps[2][0] - wrong).max() > 1e-3  # the normalisation matters for this network


def test_invalid_input_descriptions_are_rejected():
    with pytest.raises(ValueError, match="normalize"):
        DetectorInput("wasb", normalize="zscore")
    with pytest.raises(ValueError, match="multiples of 8"):
        DetectorInput("wasb", input_size=(100, 160))
    with pytest.raises(ValueError, match="frames_out <= frames_in"):
        DetectorInput("wasb", 1, 3)
    with pytest.raises(ValueError, match="invalid"):
        detector_input({META_KEY: {"normalize": "nope"}})
