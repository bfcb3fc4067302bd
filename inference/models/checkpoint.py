"""Loading and saving ball-detector weights in the WASB-SBDT checkpoint format and its relatives.

Accepted by :func:`load_weights`:

- a raw ``state_dict`` (a mapping of names to tensors), as a mapping or a file;
- a WASB-SBDT checkpoint ``{'model_state_dict': ..., 'epoch': ..., ...}`` (``*_best.pth.tar``);
- a Lightning checkpoint ``{'state_dict': {'model.xxx' or 'net.xxx': ...}, ...}``: that prefix is stripped and
  entries outside ``model.`` (a loss's buffers, say) are ignored;
- any of these with ``module.`` (DataParallel / DistributedDataParallel) or ``_orig_mod.`` (torch.compile)
  prefixes on every key.

rally3d never downloads weights: a checkpoint is a file the user provides (``model.pretrained=PATH``).
"""
from __future__ import annotations

import os
import pickle
import warnings
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

#: Prefixes stripped when *every* key of a state_dict carries them (and the model's keys do not).
WRAPPER_PREFIXES = ("module.", "_orig_mod.", "model.", "net.")  # net.: our BallDetector module


def unwrap_model(model: nn.Module) -> nn.Module:
    """The bare network inside DataParallel / DistributedDataParallel / ``torch.compile`` wrappers."""
    while True:
        if isinstance(model, (nn.DataParallel, nn.parallel.DistributedDataParallel)):
            model = model.module
        elif isinstance(getattr(model, "_orig_mod", None), nn.Module):
            model = model._orig_mod
        else:
            return model


def read_checkpoint(path: str | os.PathLike, *, allow_pickle: bool = True) -> Any:
    """``torch.load`` a checkpoint onto the CPU, with ``weights_only=True`` when the file allows it.

    A file that stores pickled Python objects besides tensors and plain containers is re-read with
    ``weights_only=False`` after a warning naming those objects, unless ``allow_pickle`` is False (then
    ``ValueError``). Raises ``FileNotFoundError`` for a missing file.
    """
    p = Path(path).expanduser()
    if not p.is_file():
        raise FileNotFoundError(
            f"ball-detector weights not found: {p}. rally3d never downloads weights: get the checkpoint "
            f"(e.g. a WASB-SBDT *_best.pth.tar) yourself and pass model.pretrained=PATH"
        )
    try:
        return torch.load(p, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as err:  # pickled objects that weights_only refuses (or a damaged file)
        safe_error = err
    except Exception as err:  # noqa: BLE001 - torch raises KeyError, RuntimeError, EOFError... on a bad file
        raise ValueError(f"cannot read {p} as a PyTorch checkpoint: {type(err).__name__}: {err}") from err
    objects = _unsafe_globals(p)
    with p.open("rb") as f:
        magic = f.read(2)
    if not objects and magic not in (b"PK", b"\x80\x02"):  # neither torch's zip format nor a legacy pickle
        raise ValueError(f"cannot read {p} as a PyTorch checkpoint: {safe_error}")
    what = f"pickled Python objects ({', '.join(objects)})" if objects else "objects that weights_only=True refuses"
    if not allow_pickle:
        raise ValueError(f"{p} holds {what}; refusing to unpickle it (allow_pickle=False): {safe_error}")
    warnings.warn(
        f"{p} holds {what}, so it is loaded with torch.load(weights_only=False), which runs the pickled "
        f"code: only load checkpoints you trust. Re-save it with save_wasb_checkpoint to avoid this.",
        stacklevel=3,
    )
    try:
        return torch.load(p, map_location="cpu", weights_only=False)
    except Exception as err:  # noqa: BLE001 - any failure here means an unreadable file
        raise ValueError(f"cannot read {p} as a PyTorch checkpoint: {type(err).__name__}: {err}") from err


def _unsafe_globals(path: Path) -> list[str]:
    """The pickled globals that stop ``weights_only=True`` (empty when torch cannot tell)."""
    finder = getattr(torch.serialization, "get_unsafe_globals_in_checkpoint", None)
    try:
        return list(finder(path)) if finder else []
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
            msg += f". Its tensors are those of the {other!r} model: set model.name={other}"
        raise ValueError(msg)
    return {"missing_keys": missing, "unexpected_keys": unexpected}


def load_weights(
    model: nn.Module,
    path_or_state: str | os.PathLike | Mapping[str, Any],
    strict: bool = True,
    *,
    allow_pickle: bool = True,
) -> dict:
    """Load a checkpoint file or an in-memory checkpoint / state_dict into ``model`` (in place).

    Args:
        model: a detector (DataParallel / compiled wrappers are unwrapped).
        path_or_state: a path, or a mapping in any accepted format (see the module docstring).
        strict: require exactly the model's tensor names (shapes must always match).
        allow_pickle: when a file needs ``weights_only=False``, warn and load it (True) or refuse (False).

    Returns:
        ``{'source', 'format', 'stripped_prefixes', 'missing_keys', 'unexpected_keys', 'ignored_keys',
        'meta'}``; ``meta`` holds scalar checkpoint entries such as ``epoch``.

    Raises:
        FileNotFoundError: the file does not exist (weights are never downloaded).
        ValueError: not a checkpoint, or the wrong architecture / shapes (naming the first mismatching
            tensor and the number of missing and unexpected keys).
    """
    if isinstance(path_or_state, (str, os.PathLike)):
        source = str(path_or_state)
        ckpt = read_checkpoint(path_or_state, allow_pickle=allow_pickle)
    else:
        source, ckpt = "<in-memory>", path_or_state
    state, info = extract_state_dict(ckpt)
    target = unwrap_model(model)
    state, stripped = strip_wrapper_prefixes(state, target.state_dict().keys())
    keys = check_compatible(target, state, strict=strict, source=source if source != "<in-memory>" else "")
    target.load_state_dict(state, strict=strict)
    return {"source": source, "stripped_prefixes": stripped, **info, **keys}


def save_wasb_checkpoint(model: nn.Module, path: str | os.PathLike, *, epoch: int = 0, **extra: Any) -> Path:
    """Write ``{'model_state_dict': ..., 'epoch': epoch, **extra}``, the public WASB-SBDT format.

    The state_dict is taken from the unwrapped model (no ``module.`` prefix) and moved to the CPU. Keep
    ``extra`` to plain numbers and strings so that the file loads with ``weights_only=True``.
    """
    p = Path(path).expanduser()
    p.parent.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu() for k, v in unwrap_model(model).state_dict().items()}
    torch.save({"model_state_dict": state, "epoch": epoch, **extra}, p)
    return p
