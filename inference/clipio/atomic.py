"""Atomic file writes: write to a temporary file in the same folder, fsync, then rename; clean-up of the
temporary files a crashed write leaves behind.

A crash mid-write leaves the old file intact; readers never see a half-written file.
"""
from __future__ import annotations

import os
import secrets
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same folder + ``os.replace``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; give the file the usual permissions
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    return path


def private_temp_path(path: str | Path) -> Path:
    """A temporary name beside ``path`` that no other process uses (pid and random token), keeping the
    suffix (``np.save`` keeps ``.npy``): two processes building the same file (DDP ranks, two runs)
    never write into one temporary file; the last ``os.replace`` wins with a complete file."""
    path = Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}-{secrets.token_hex(4)}.tmp{path.suffix}")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8, ``\\n`` line ends) to ``path`` atomically."""
    return atomic_write_bytes(path, text.encode("utf-8"))


STALE_TEMP_S = 60.0
"""A temporary file of an atomic write older than this is litter from a crashed write (a write takes ms)."""


def stale_temp_files(folder: str | Path, older_than_s: float = STALE_TEMP_S) -> list[Path]:
    """Temporary files of atomic writes (``.<name>.<random>.tmp``) in ``folder`` older than ``older_than_s``."""
    now = time.time()
    out = []
    for p in sorted(Path(folder).glob(".*.tmp")):
        try:
            if p.is_file() and now - p.stat().st_mtime > older_than_s:
                out.append(p)
        except FileNotFoundError:  # finished (renamed) meanwhile
            continue
    return out


def remove_stale_temp_files(folder: str | Path, older_than_s: float = STALE_TEMP_S) -> list[Path]:
    """Delete :func:`stale_temp_files` of ``folder`` (left by a save that crashed); returns what was removed."""
    removed = []
    for p in stale_temp_files(folder, older_than_s):
        try:
            p.unlink()
            removed.append(p)
        except FileNotFoundError:
            pass
    return removed


def backup_file(path: str | Path, folder: str | Path) -> Path:
    """Copy ``path`` to ``folder/<name>.<timestamp>`` before it is replaced; returns the copy's path."""
    path, folder = Path(path), Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    dest = folder / f"{path.name}.{stamp}"
    n = 1
    while dest.exists():  # two backups of one file within a second
        dest = folder / f"{path.name}.{stamp}-{n}"
        n += 1
    shutil.copy2(path, dest)
    return dest


BACKUP_DIR = Path(".rally3d") / "backup"
"""Where a replaced file's previous version goes, relative to the folder that holds the file."""


@dataclass(frozen=True)
class Replaced:
    """What :func:`replace_keeping_backup` did.

    Attributes:
        path: the file written.
        backup: the copy of the previous version (None when there was none, or it was identical).
        changed: False when the new content equals the old one (nothing was touched).
    """

    path: Path
    backup: Path | None
    changed: bool

    def line(self, command: str = "rally3d") -> str | None:
        """``<command>: <file> replaced; the previous version is kept in <copy>`` (None: nothing to say)."""
        if self.backup is None:
            return None
        return f"{command}: {self.path} replaced; the previous version is kept in {self.backup}"


def replace_keeping_backup(path: str | Path, write: Callable[[Path], object], *,
                           backup_dir: str | Path | None = None, log: Callable[[str], object] | None = print,
                           command: str = "rally3d") -> Replaced:
    """The one rule for commands that write a file a person may have edited (ball.csv, events.csv,
    court_points.csv, camera.yaml, players.csv …): never lose the previous version.

    ``write(tmp)`` writes the new file at a temporary path beside ``path``; when ``path`` exists with
    other content, it is first copied to ``backup_dir`` (default ``<folder of path>/.rally3d/backup``,
    named ``<name>.<timestamp>``), then the new file replaces it atomically, and ``log`` says so in one
    line. Identical content leaves the old file (and its modification time) alone.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = private_temp_path(path)
    try:
        write(tmp)
        if path.is_file() and _same_bytes(path, tmp):
            return Replaced(path, None, False)
        copy = None
        if path.is_file():
            copy = backup_file(path, backup_dir if backup_dir is not None else path.parent / BACKUP_DIR)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    result = Replaced(path, copy, True)
    if log is not None and result.line(command):
        log(result.line(command))
    return result


def _same_bytes(a: Path, b: Path) -> bool:
    if a.stat().st_size != b.stat().st_size:
        return False
    return a.read_bytes() == b.read_bytes()
