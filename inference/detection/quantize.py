"""int8 companions of detector weights: the network quantised for ONNX Runtime on the CPU.

A checkpoint ``NAME.pth.tar`` may have a companion ``NAME.int8.onnx`` beside it: the same network exported to
ONNX and statically quantised (QDQ: int8 weights per output channel, uint8 activations whose ranges were
measured on calibration windows of rendered clips; the first convolution, which sees the normalised frames,
and the last, which writes the heatmaps, stay in float). The companion records the SHA-256 of the checkpoint
it was made from; :func:`int8_companion` returns it only while it matches, so a retrained checkpoint never
runs through a stale companion. ``rally3d infer --detector-backend onnx-int8`` / ``rally3d detect --backend
onnx-int8`` run it (2.1–2.7× faster; not the default: it loses a few % of the weak detections, and events and
3D with them). Figures and the recipe: docs/detectors.md (section "int8").

Example:
    >>> path = int8_companion(Path("inference/weights/wasb_padel.pth.tar"))   # None when absent or stale
    >>> quantize_detector(fp32_onnx, windows, Path("w.int8.onnx"), source_sha256=file_sha256(weights))
"""
from __future__ import annotations

import hashlib
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

INT8_SUFFIX = ".int8.onnx"
#: the metadata key of the checkpoint's SHA-256 in a companion
SOURCE_KEY = "rally3d_source_sha256"
_CHECKPOINT_SUFFIXES = (".pth.tar", ".pth", ".pt", ".ckpt", ".tar")


def companion_path(weights: str | os.PathLike) -> Path:
    """``dir/NAME.int8.onnx`` for the checkpoint ``dir/NAME.pth.tar`` (``.pth``, ``.pt``, ``.ckpt`` alike)."""
    weights = Path(weights)
    name = weights.name
    for suffix in _CHECKPOINT_SUFFIXES:
        if name.endswith(suffix):
            name = name[: -len(suffix)]
            break
    return weights.with_name(name + INT8_SUFFIX)


def file_sha256(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def source_sha256(path: str | os.PathLike) -> str | None:
    """The checkpoint SHA-256 a companion records, or None (not a companion, unreadable)."""
    try:
        import onnx

        model = onnx.load(str(path), load_external_data=False)
    except Exception as e:  # noqa: BLE001 - an unreadable companion is no companion: say so and go on
        log.warning("%s: not a readable ONNX file (%s); it is not used", path, e)
        return None
    return next((p.value for p in model.metadata_props if p.key == SOURCE_KEY), None)


def int8_companion(weights: str | os.PathLike | None) -> Path | None:
    """The int8 companion of checkpoint ``weights`` when it exists and was made from these exact bytes; a stale
    one is named in a warning and ignored."""
    if weights is None:
        return None
    path = companion_path(weights)
    if not path.is_file():
        return None
    recorded = source_sha256(path)
    if recorded is None or recorded != file_sha256(weights):
        log.warning("%s was not made from %s (the checkpoint changed since): it is not used; make a new one with "
                    "`python -m training.quantize --weights %s`", path, Path(weights).name, weights)
        return None
    return path


def _float_ends(model) -> list[str]:
    """Names of the first and the last convolution of an ONNX graph (kept in float)."""
    convs = [n.name for n in model.graph.node if n.op_type in ("Conv", "ConvTranspose")]
    return sorted({convs[0], convs[-1]}) if convs else []


def quantize_detector(fp32: str | os.PathLike, windows: list[np.ndarray], out: str | os.PathLike, *,
                      source_sha256: str, input_name: str = "frames") -> Path:
    """Statically quantise the float ONNX detector ``fp32`` into ``out`` (QDQ, per-channel int8 weights, uint8
    activations with MinMax ranges over ``windows``: normalised inputs ``(1, 3·F, H, W)`` float32, full frames
    and crops alike) and record ``source_sha256`` in it. The first and last convolutions stay in float. Written
    atomically. Needs ``onnxruntime`` and ``onnx``."""
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, CalibrationMethod, QuantFormat, QuantType, quantize_static
    from onnxruntime.quantization.shape_inference import quant_pre_process

    if not windows:
        raise ValueError("quantising a detector needs calibration windows; none were given")

    class Reader(CalibrationDataReader):
        def __init__(self) -> None:
            self.items = iter(windows)

        def get_next(self):
            x = next(self.items, None)
            return None if x is None else {input_name: np.ascontiguousarray(x, np.float32)}

    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="rally3d-quant-") as tmp:
        pre, q = Path(tmp) / "pre.onnx", Path(tmp) / "int8.onnx"
        quant_pre_process(str(fp32), str(pre), skip_symbolic_shape=True)
        quantize_static(str(pre), str(q), Reader(), quant_format=QuantFormat.QDQ, per_channel=True,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8,
                        calibrate_method=CalibrationMethod.MinMax, nodes_to_exclude=_float_ends(onnx.load(str(pre))))
        model = onnx.load(str(q))
        entry = model.metadata_props.add()
        entry.key, entry.value = SOURCE_KEY, source_sha256
        tmp_out = out.with_name(f".{out.name}.{os.getpid()}.tmp")
        onnx.save(model, str(tmp_out))
        tmp_out.replace(out)
    return out
