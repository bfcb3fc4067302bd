"""Loading and saving ball-detector weights in the WASB-SBDT checkpoint format and its relatives.

Accepted by :func:`load_weights`:

- a raw ``state_dict`` (a mapping of names to tensors), as a mapping or a file;
- a WASB-SBDT checkpoint ``{'model_state_dict': ..., 'epoch': ..., ...}`` (``*_best.pth.tar``);
- a Lightning checkpoint ``{'state_dict': {'model.xxx' or 'net.xxx': ...}, ...}``: that prefix is stripped and
  entries outside ``model.`` (a loss's buffers, say) are ignored;
- any of these with ``module.`` (DataParallel / DistributedDataParallel) or ``_orig_mod.`` (torch.compile)
  prefixes on every key.

**Safety.** A checkpoint is code as much as data: unpickling runs whatever the file asks for. Files are read
with an allow-list (``torch.load(weights_only=True)``: tensors, plain containers and numbers, plus the numpy
array and scalar types of :data:`NUMPY_SAFE`); a file that needs anything else is refused with
:class:`UntrustedCheckpointError` unless the caller passes ``trust=True`` (``--trust-checkpoint`` on the
command line, ``trust_checkpoint=true`` in train.py / eval.py).

**Input description.** Every checkpoint rally3d writes stores how the network's input was made
(:class:`DetectorInput`: architecture, frames in/out, normalisation, input size) under :data:`META_KEY`;
:func:`detector_input` reads it back, from a Lightning checkpoint's data-module hyper-parameters for older
files, and otherwise assumes WASB-SBDT's convention: ImageNet mean/std for every architecture (its public
TrackNetV2 and MonoTrack files included), 288×512.

rally3d never downloads weights: a checkpoint is a file the user provides (``init_weights=PATH``).
"""
from __future__ import annotations

import os
import pickle
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

#: Prefixes stripped when *every* key of a state_dict carries them (and the model's keys do not).
WRAPPER_PREFIXES = ("module.", "_orig_mod.", "model.", "net.")  # net.: our BallDetector module

#: Where rally3d stores the :class:`DetectorInput` of a checkpoint it writes.
META_KEY = "rally3d_detector"
#: Input normalisations a detector can be trained with (``inference.detection.preprocess.normalize``).
NORMALIZATIONS = ("imagenet", "unit")
#: WASB-SBDT's input size (H, W) and normalisation, for checkpoints that do not state theirs.
DEFAULT_INPUT_SIZE = (288, 512)
DEFAULT_NORMALIZE = "imagenet"
#: numpy globals a checkpoint may reference without ``trust`` (arrays and scalars of plain numeric dtypes).
NUMPY_SAFE: tuple = (
    np._core.multiarray._reconstruct, np._core.multiarray.scalar, np.ndarray, np.dtype,
    *(getattr(np.dtypes, n) for n in dir(np.dtypes)
      if n.endswith("DType") and n not in ("ObjectDType", "VoidDType", "StringDType")),
)
TRUST_HINT = ("pass --trust-checkpoint (rally3d detect / infer) or trust_checkpoint=true (train.py / eval.py) "
              "only if you trust where the file comes from: unpickling runs code stored in it")


class UntrustedCheckpointError(ValueError):
    """A checkpoint holds pickled objects outside the allow-list and the caller did not opt in (``trust``)."""


@dataclass(frozen=True)
class DetectorInput:
    """How a ball detector's input is made, as stored in (or assumed for) a checkpoint.

    Attributes:
        arch: ``wasb``, ``tracknetv2``, ``monotrack``, or None when the file does not say.
        frames_in, frames_out: frames stacked on the input channels / heatmaps predicted.
        normalize: ``imagenet`` (RGB/255, then ImageNet mean/std) or ``unit`` (RGB/255).
        input_size: (H, W) of the letterboxed network input.
        origin: where the description comes from: ``stored`` (written by rally3d), ``lightning`` (a
            Lightning checkpoint's data-module hyper-parameters) or ``assumed`` (WASB-SBDT's convention).
    """

    arch: str | None = None
    frames_in: int = 3
    frames_out: int = 3
    normalize: str = DEFAULT_NORMALIZE
    input_size: tuple[int, int] = DEFAULT_INPUT_SIZE
    origin: str = "assumed"

    def __post_init__(self) -> None:
        if self.normalize not in NORMALIZATIONS:
            raise ValueError(f"normalize must be one of {NORMALIZATIONS}, got {self.normalize!r}")
        if not (isinstance(self.frames_in, int) and isinstance(self.frames_out, int)
                and 1 <= self.frames_out <= self.frames_in):
            raise ValueError(f"need whole numbers 1 <= frames_out <= frames_in, got {self.frames_out}, {self.frames_in}")
        h, w = (int(v) for v in self.input_size)
        if h <= 0 or w <= 0 or h % 8 or w % 8:
            raise ValueError(f"input_size (H, W) must be positive multiples of 8, got {self.input_size}")
        object.__setattr__(self, "input_size", (h, w))

    def to_dict(self) -> dict[str, Any]:
        """Plain types only (a checkpoint holding it still loads with the allow-list)."""
        d = asdict(self)
        d["input_size"] = list(self.input_size)
        d.pop("origin")
        return d

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], origin: str = "stored") -> DetectorInput:
        known = {"arch", "frames_in", "frames_out", "normalize", "input_size"}
        return cls(**{k: (tuple(v) if k == "input_size" else v) for k, v in d.items() if k in known}, origin=origin)


def unwrap_model(model: nn.Module) -> nn.Module:
    """The bare network inside DataParallel / DistributedDataParallel / ``torch.compile`` wrappers."""
    while True:
        if isinstance(model, (nn.DataParallel, nn.parallel.DistributedDataParallel)):
            model = model.module
        elif isinstance(getattr(model, "_orig_mod", None), nn.Module):
            model = model._orig_mod
        else:
            return model


def read_checkpoint(path: str | os.PathLike, *, trust: bool = False) -> Any:
    """``torch.load`` a checkpoint onto the CPU through the allow-list (see the module docstring).

    Raises:
        FileNotFoundError: no such file (weights are never downloaded).
        UntrustedCheckpointError: the file needs objects outside the allow-list and ``trust`` is False; the
            message names them. With ``trust=True`` such a file is unpickled (its code runs).
        ValueError: not a PyTorch checkpoint.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(
            f"ball-detector weights not found: {p}. rally3d never downloads weights: get the checkpoint "
            f"(e.g. a WASB-SBDT *_best.pth.tar) yourself and pass its path (init_weights=PATH for train.py, "
            f"--weights PATH for rally3d detect, --detector PATH for rally3d infer)"
        )
    try:
        with torch.serialization.safe_globals(list(NUMPY_SAFE)):
            return torch.load(p, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:  # objects outside the allow-list (or a damaged file)
        safe_error = err
    except Exception as err:  # noqa: BLE001 - torch raises KeyError, RuntimeError, EOFError... on a bad file
        raise ValueError(f"cannot read {p} as a PyTorch checkpoint: {type(err).__name__}: {err}") from err
    objects = _unsafe_globals(p)
    with p.open("rb") as f:
        magic = f.read(2)
    if not objects and magic not in (b"PK", b"\x80\x02"):  # neither torch's zip format nor a legacy pickle
        raise ValueError(f"cannot read {p} as a PyTorch checkpoint: {safe_error}")
    if not trust:
        what = f"pickled Python objects ({', '.join(objects)})" if objects else "pickled objects outside the allow-list"
        raise UntrustedCheckpointError(f"{p} holds {what}; refusing to unpickle it: {TRUST_HINT}")
    try:
        return torch.load(p, map_location="cpu", weights_only=False)
    except Exception as err:  # noqa: BLE001 - any failure here means an unreadable file
        raise ValueError(f"cannot read {p} as a PyTorch checkpoint: {type(err).__name__}: {err}") from err


def _unsafe_globals(path: Path) -> list[str]:
    """The pickled globals that stop ``weights_only=True`` (empty when torch cannot tell)."""
    finder = getattr(torch.serialization, "get_unsafe_globals_in_checkpoint", None)
    allowed = {f"{g.__module__}.{g.__name__}" for g in NUMPY_SAFE}
    try:
        return [g for g in finder(path) if g not in allowed] if finder else []
    except Exception:  # noqa: BLE001 - a non-zip (legacy or corrupt) file: no details available
        return []


def _is_state_dict(obj: Any) -> bool:
    return isinstance(obj, Mapping) and len(obj) > 0 and all(
        isinstance(k, str) and isinstance(v, torch.Tensor) for k, v in obj.items()
    )


def _plain_meta(ckpt: Mapping[str, Any], skip: str) -> dict[str, Any]:
    """Top-level scalar entries of a checkpoint (epoch, losses, metrics)."""
    return {
        k: (v.item() if isinstance(v, torch.Tensor) and v.numel() == 1 else v)
        for k, v in ckpt.items()
        if k != skip and (isinstance(v, (int, float, str, bool)) or (isinstance(v, torch.Tensor) and v.numel() == 1))
    }


def extract_state_dict(ckpt: Any) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Split a loaded checkpoint into its model ``state_dict`` and a description.

    The description has ``format`` (``"wasb"``, ``"lightning"`` or ``"raw"``), ``meta`` (scalar top-level
    entries such as ``epoch``) and ``ignored_keys`` (Lightning entries outside ``model.``).
    """
    info: dict[str, Any] = {"meta": {}, "ignored_keys": []}
    if isinstance(ckpt, Mapping) and "model_state_dict" in ckpt:
        state, info["format"] = ckpt["model_state_dict"], "wasb"
        info["meta"] = _plain_meta(ckpt, "model_state_dict")
    elif isinstance(ckpt, Mapping) and "state_dict" in ckpt and isinstance(ckpt["state_dict"], Mapping):
        state, info["format"] = dict(ckpt["state_dict"]), "lightning"
        info["meta"] = _plain_meta(ckpt, "state_dict")
        if any(k.startswith("model.") for k in state):
            info["ignored_keys"] = [k for k in state if not k.startswith("model.")]
            state = {k[len("model."):]: v for k, v in state.items() if k.startswith("model.")}
    else:
        state, info["format"] = ckpt, "raw"
    if not _is_state_dict(state):
        top = list(ckpt)[:8] if isinstance(ckpt, Mapping) else type(ckpt).__name__
        raise ValueError(
            "not a recognised checkpoint: expected a state_dict of tensors, {'model_state_dict': ...} "
            f"(WASB-SBDT) or {{'state_dict': ...}} (Lightning); found {top}"
        )
    return dict(state), info


def strip_wrapper_prefixes(state: Mapping[str, torch.Tensor], model_keys) -> tuple[dict[str, torch.Tensor], list[str]]:
    """Remove ``module.`` / ``_orig_mod.`` / ``model.`` prefixes that every key carries and the model lacks."""
    state, stripped = dict(state), []
    model_keys = list(model_keys)
    changed = True
    while changed:
        changed = False
        for prefix in WRAPPER_PREFIXES:
            if all(k.startswith(prefix) for k in state) and not all(k.startswith(prefix) for k in model_keys):
                state = {k[len(prefix):]: v for k, v in state.items()}
                stripped.append(prefix)
                changed = True
    return state, stripped


def _shape(t: torch.Tensor | None) -> str:
    return "missing" if t is None else str(tuple(t.shape))


def _matching_architecture(state: Mapping[str, torch.Tensor]) -> str | None:
    """The registered model whose tensor names equal the checkpoint's, if any (built on the meta device)."""
    from .registry import MODEL_NAMES, build_model  # registry imports the models; avoid a cycle at import

    names = set(state)
    for name in MODEL_NAMES:
        with torch.device("meta"):
            if set(build_model(name).state_dict()) == names:
                return name
    return None


def check_compatible(model: nn.Module, state: Mapping[str, torch.Tensor], strict: bool = True, source: str = "") -> dict:
    """Compare a state_dict with a model; raise a short ``ValueError`` when it cannot be loaded.

    Shape mismatches always fail; missing and unexpected keys fail when ``strict``. The message names the
    first mismatching tensor in the model's order (name, expected shape, found shape), then counts the
    missing, unexpected and reshaped tensors. Returns ``{'missing_keys', 'unexpected_keys'}``.
    """
    expected = model.state_dict()
    missing = [k for k in expected if k not in state]
    unexpected = [k for k in state if k not in expected]
    reshaped = [k for k in expected if k in state and state[k].shape != expected[k].shape]
    if reshaped or (strict and (missing or unexpected)):
        arch = type(model).__name__
        first = next((k for k in expected if k in missing or k in reshaped), None)
        if first is not None:
            detail = f"first mismatching tensor {first!r}: expected {_shape(expected[first])}, found {_shape(state.get(first))}"
        else:
            first = unexpected[0]
            detail = f"first mismatching tensor {first!r}: expected none (not in {arch}), found {_shape(state[first])}"
        msg = (
            f"checkpoint{' ' + source if source else ''} does not fit {arch}: {detail}; "
            f"{len(missing)} missing, {len(unexpected)} unexpected, {len(reshaped)} with another shape"
        )
        other = _matching_architecture(state)
        if other is not None and not missing and not unexpected:
            msg += " (same layout: was it trained with other frames_in/frames_out?)"
        elif other is not None:
            msg += (f". Its tensors are those of the {other!r} model: set model.net.name={other} (train.py / "
                    f"eval.py) or --model {other} (rally3d detect; --detector-model for rally3d infer)")
        raise ValueError(msg)
    return {"missing_keys": missing, "unexpected_keys": unexpected}


def detector_input(ckpt: Any, arch: str | None = None) -> DetectorInput:
    """How the network of a loaded checkpoint wants its input (see the module docstring).

    Args:
        ckpt: what :func:`read_checkpoint` returned.
        arch: the architecture to report when the file does not name one.
    """
    if isinstance(ckpt, Mapping) and isinstance(ckpt.get(META_KEY), Mapping):
        try:
            return DetectorInput.from_dict(ckpt[META_KEY], origin="stored")
        except (TypeError, ValueError) as e:
            raise ValueError(f"the checkpoint's {META_KEY} entry is invalid: {e}") from None
    if isinstance(ckpt, Mapping) and isinstance(ckpt.get("datamodule_hyper_parameters"), Mapping):
        data = ckpt["datamodule_hyper_parameters"]  # a Lightning checkpoint of ours written before META_KEY
        net = (ckpt.get("hyper_parameters") or {}).get("net") if isinstance(ckpt.get("hyper_parameters"), Mapping) else None
        name = net.get("name") if isinstance(net, Mapping) else None
        try:
            return DetectorInput(name or arch, int(data.get("frames_in", 3)), int(data.get("frames_out", 3)),
                                 str(data.get("normalize", DEFAULT_NORMALIZE)),
                                 tuple(data.get("net_size", DEFAULT_INPUT_SIZE)), origin="lightning")
        except (TypeError, ValueError):
            pass
    return DetectorInput(arch, origin="assumed")


def load_weights(
    model: nn.Module,
    path_or_state: str | os.PathLike | Mapping[str, Any],
    strict: bool = True,
    *,
    trust: bool = False,
) -> dict:
    """Load a checkpoint file or an in-memory checkpoint / state_dict into ``model`` (in place).

    Args:
        model: a detector (DataParallel / compiled wrappers are unwrapped).
        path_or_state: a path, or a mapping in any accepted format (see the module docstring).
        strict: require exactly the model's tensor names (shapes must always match).
        trust: unpickle a file that needs objects outside the allow-list (runs its code); else refuse it.

    Returns:
        ``{'source', 'format', 'stripped_prefixes', 'missing_keys', 'unexpected_keys', 'ignored_keys',
        'meta', 'input'}``; ``meta`` holds scalar checkpoint entries such as ``epoch``, ``input`` the
        :class:`DetectorInput` of the file.

    Raises:
        FileNotFoundError: the file does not exist (weights are never downloaded).
        UntrustedCheckpointError: the file needs pickled objects and ``trust`` is False.
        ValueError: not a checkpoint, or the wrong architecture / shapes (naming the first mismatching
            tensor and the number of missing and unexpected keys).
    """
    if isinstance(path_or_state, (str, os.PathLike)):
        source = str(path_or_state)
        ckpt = read_checkpoint(path_or_state, trust=trust)
    else:
        source, ckpt = "<in-memory>", path_or_state
    state, info = extract_state_dict(ckpt)
    target = unwrap_model(model)
    state, stripped = strip_wrapper_prefixes(state, target.state_dict().keys())
    keys = check_compatible(target, state, strict=strict, source=source if source != "<in-memory>" else "")
    target.load_state_dict(state, strict=strict)
    return {"source": source, "stripped_prefixes": stripped, **info, **keys, "input": detector_input(ckpt)}


def load_detector(path: str | os.PathLike, arch: str | None = None, *, trust: bool = False
                  ) -> tuple[nn.Module, DetectorInput, dict]:
    """Build the detector a checkpoint file describes and load its weights (the file is read once).

    The architecture and frame counts come from the file when it states them, else from ``arch``
    (default ``wasb``) and 3 → 3. Returns ``(model in eval mode, input description, load_weights' info)``.
    """
    from .registry import build_model  # registry imports the models; avoid a cycle at import

    ckpt = read_checkpoint(path, trust=trust)
    spec = detector_input(ckpt, arch)
    name = spec.arch or arch or "wasb"
    model = build_model(name, spec.frames_in, spec.frames_out)
    state, info = extract_state_dict(ckpt)
    state, stripped = strip_wrapper_prefixes(state, model.state_dict().keys())
    keys = check_compatible(model, state, strict=True, source=str(path))
    model.load_state_dict(state)
    spec = DetectorInput(name, spec.frames_in, spec.frames_out, spec.normalize, spec.input_size, spec.origin)
    return model.eval(), spec, {"source": str(path), "stripped_prefixes": stripped, **info, **keys, "input": spec}


def architecture_of(model: nn.Module) -> str | None:
    """The registry name of a detector instance (None for other modules)."""
    from .registry import _MODELS

    target = unwrap_model(model)
    return next((name for name, cls in _MODELS.items() if type(target) is cls), None)


def save_wasb_checkpoint(model: nn.Module, path: str | os.PathLike, *, epoch: int = 0,
                         input: DetectorInput | None = None, **extra: Any) -> Path:
    """Write ``{'model_state_dict': ..., 'epoch': epoch, META_KEY: input, **extra}``: the public WASB-SBDT
    format plus rally3d's input description (other tools ignore the extra key).

    ``input`` defaults to the model's architecture and frame counts with WASB-SBDT's normalisation and
    input size. The state_dict is taken from the unwrapped model (no ``module.`` prefix) and moved to the
    CPU. Keep ``extra`` to plain numbers and strings so that the file loads through the allow-list.
    """
    target = unwrap_model(model)
    if input is None:
        input = DetectorInput(architecture_of(target), int(getattr(target, "frames_in", 3)),
                              int(getattr(target, "frames_out", 3)), origin="stored")
    p = Path(path).expanduser()
    p.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu() for k, v in target.state_dict().items()}
    tmp = p.with_name(f".{p.name}.tmp")
    torch.save({"model_state_dict": state, "epoch": epoch, META_KEY: input.to_dict(), **extra}, tmp)
    os.replace(tmp, p)
    return p
