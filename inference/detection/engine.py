"""What runs the detector network: eager PyTorch, or ONNX Runtime on the CPU (float or int8), behind one call.

An engine maps a normalised batch ``x (B, 3·F, H, W) float32`` to probabilities ``(B, F_out, H, W) float32``
(the sigmoid of the logits). Both take any ``H, W`` that are multiples of 8 (the networks are fully
convolutional), so the crop-tracking windows run through the same engine as full frames.

The ONNX file is exported from the (batch-norm folded) PyTorch model on first use and cached under
``$RALLY3D_CACHE/onnx`` (default ``~/.cache/rally3d/onnx``), named by a hash of the weights, so a changed
checkpoint is exported again; nothing is ever downloaded. ``onnx-int8`` runs a checkpoint's int8 companion
(``NAME.int8.onnx`` beside it, :mod:`.quantize`) instead: 2.1–2.7× faster, but not the default (it loses a few
% of the weak detections, the ones near contacts: docs/detectors.md#int8).

Example:
    >>> engine = make_engine(model, backend="onnx", frames_in=3)
    >>> probs = engine(x)                                   # numpy in, numpy out
"""
from __future__ import annotations

import hashlib
import logging
import os
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

log = logging.getLogger(__name__)

BACKENDS = ("auto", "torch", "onnx", "onnx-int8")
#: bump when the exported graph changes for the same weights (a new opset, sigmoid inside or not, ...)
EXPORT_VERSION = 1
OPSET = 17


class TorchEngine:
    """Eager PyTorch, ``inference_mode``, channels-last memory."""

    name = "torch"

    def __init__(self, model: nn.Module, device: str = "cpu") -> None:
        self.device = device
        self.model = model.eval().to(device, memory_format=torch.channels_last)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            t = torch.from_numpy(np.ascontiguousarray(x)).to(self.device)
            t = t.contiguous(memory_format=torch.channels_last)
            return torch.sigmoid(self.model(t)).float().cpu().numpy()


class _WithSigmoid(nn.Module):
    """The exported graph: logits → probabilities, so both engines return the same thing."""

    def __init__(self, model: nn.Module) -> None:
        super().__init__()
        self.model = model

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(self.model(x))


class OnnxEngine:
    """ONNX Runtime's CPU execution provider over an exported detector (dynamic batch, height and width)."""

    def __init__(self, path: str | os.PathLike, threads: int | None = None, name: str = "onnx") -> None:
        ort = require_onnxruntime()
        options = ort.SessionOptions()
        options.intra_op_num_threads = threads or torch.get_num_threads()
        # idle pool threads sleep instead of spinning: on the real 1080p tennis clip 17.1 → 14.3 CPU-s, wall
        # 9.3 → 8.3 s with 2 threads (docs/detectors.md)
        options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        self.path, self.name = Path(path), name
        self.session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
        self.input = self.session.get_inputs()[0].name

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return self.session.run(None, {self.input: np.ascontiguousarray(x, np.float32)})[0]


def require_onnxruntime():
    """The ``onnxruntime`` module, or a RuntimeError that says how to install it."""
    try:
        import onnx  # noqa: F401  (the exporter writes through it)
        import onnxruntime
    except ImportError as e:
        raise RuntimeError("the ONNX backend needs onnxruntime and onnx: pip install 'rally3d[onnx]' "
                          "(or use --backend torch)") from e
    return onnxruntime


def cache_dir() -> Path:
    """Where exported ONNX files are kept: ``$RALLY3D_CACHE/onnx`` or ``$XDG_CACHE_HOME/rally3d/onnx``."""
    root = os.environ.get("RALLY3D_CACHE")
    if root:
        return Path(root) / "onnx"
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "rally3d" / "onnx"


def model_digest(model: nn.Module, frames_in: int) -> str:
    """16 hex digits naming the model: its class, input frames, and every parameter and buffer."""
    h = hashlib.sha256(f"{type(model).__name__}:{frames_in}:{EXPORT_VERSION}:{OPSET}".encode())
    for name, t in model.state_dict().items():
        h.update(name.encode())
        h.update(t.detach().cpu().contiguous().numpy().tobytes())
    return h.hexdigest()[:16]


def export_onnx(model: nn.Module, path: str | os.PathLike, frames_in: int, size: tuple[int, int] = (288, 512)
                ) -> Path:
    """Write ``model`` (eval mode; returns probabilities) as ONNX with dynamic batch, height and width.

    ``size``: the ``(H, W)`` traced through (any multiple of 8 works at run time).
    """
    import warnings

    require_onnxruntime()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    x = torch.zeros(1, 3 * frames_in, *size)
    dynamic = {0: "batch", 2: "height", 3: "width"}
    with warnings.catch_warnings():   # tracer notes on the input-shape checks, which hold for every input
        warnings.simplefilter("ignore")
        torch.onnx.export(_WithSigmoid(model).eval(), (x,), str(tmp), input_names=["frames"],
                          output_names=["heatmaps"], dynamic_axes={"frames": dynamic, "heatmaps": dynamic},
                          opset_version=OPSET, dynamo=False)
    tmp.replace(path)   # atomic: a concurrent run never reads a half-written file
    return path


def cached_onnx(model: nn.Module, frames_in: int, directory: str | os.PathLike | None = None) -> Path:
    """The ONNX file of ``model`` in the cache, exported first if it is not there yet."""
    directory = Path(directory) if directory else cache_dir()
    path = directory / f"{type(model).__name__.lower()}-{model_digest(model, frames_in)}.onnx"
    if not path.is_file():
        t0 = time.process_time()
        export_onnx(model, path, frames_in)
        log.info("exported the detector to %s (%.1f CPU s)", path, time.process_time() - t0)
    return path


def onnx_available() -> bool:
    """Whether ONNX Runtime and the exporter are installed (``rally3d[onnx]``; ``make`` installs them)."""
    try:
        require_onnxruntime()
    except RuntimeError:
        return False
    return True


def resolve_backend(backend: str, device: str = "cpu") -> str:
    """``auto`` → ``onnx`` on the CPU where ONNX Runtime is installed (1.5× eager PyTorch with crop-tracking,
    heatmaps within 1e-4, the same F1: docs/detectors.md#speed), else ``torch``; other names unchanged. The int8
    companion (``onnx-int8``) is never chosen by ``auto``: it is faster but loses weak detections
    (docs/detectors.md#int8)."""
    if backend == "auto":
        return "onnx" if device == "cpu" and onnx_available() else "torch"
    return backend


def make_engine(model: nn.Module, backend: str = "auto", frames_in: int = 3, device: str = "cpu",
                onnx_dir: str | os.PathLike | None = None, int8: str | os.PathLike | None = None):
    """A :class:`TorchEngine` or :class:`OnnxEngine` for ``model``: the float network exported and cached on
    first use, or ``int8``, the weights' int8 companion (:func:`~.quantize.int8_companion`); ``backend``
    ``auto``: :func:`resolve_backend`."""
    backend = resolve_backend(backend, device)
    if backend == "torch":
        return TorchEngine(model, device)
    if backend in ("onnx", "onnx-int8") and device != "cpu":
        raise ValueError(f"the ONNX backend runs on the CPU only, not {device!r}; use --backend torch")
    if backend == "onnx":
        return OnnxEngine(cached_onnx(model, frames_in, onnx_dir))
    if backend == "onnx-int8":
        if int8 is None:
            raise ValueError("--backend onnx-int8 needs the weights' int8 companion (NAME.int8.onnx beside "
                             "NAME.pth.tar, made from those weights): make it with `python -m training.quantize "
                             "--weights NAME.pth.tar`, or use --backend onnx")
        require_onnxruntime()
        return OnnxEngine(int8, name="onnx-int8")
    raise ValueError(f"unknown detector backend {backend!r}; choose one of {BACKENDS}")
