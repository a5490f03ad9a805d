"""File-system helpers: hashing, advisory locks and replacing a directory by a finished one.

Directories are always produced complete in a temporary sibling and then renamed into
place, so a reader never sees a half-written directory.  Locks are ``fcntl.flock`` locks
(POSIX), released when the context exits or the process dies.  Temporary siblings are
named after their owner process (:func:`ncgen.files.temporary_name`), and those left by a
killed process are removed the next time a sibling of the same target is made.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterator

from ncgen.files import cache_dir, sweep_stale, temporary_name  # noqa: F401 (cache_dir: here for codegen)


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def sha256_file(path: Path) -> str:
    return sha256_bytes(Path(path).read_bytes())


@contextlib.contextmanager
def locked(path: Path) -> Iterator[None]:
    """Hold an exclusive lock on ``path`` (a lock file, created if missing, or a directory)."""
    path = Path(path)
    fd = os.open(path, os.O_RDONLY) if path.is_dir() else os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # closing releases the lock


@contextlib.contextmanager
def temporary_sibling(target: Path) -> Iterator[Path]:
    """A fresh empty directory next to ``target``, removed on exit unless it was renamed away."""
    target = Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    sweep_stale(target.parent, target.name)
    tmp = Path(tempfile.mkdtemp(prefix=temporary_name(target.name), dir=target.parent))
    try:
        yield tmp
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def fsync_tree(path: Path) -> None:
    """Flush every file under ``path`` and the directories themselves to disk, so that a
    rename publishing ``path`` never exposes files whose data a crash could still lose."""
    for root, _, files in os.walk(path):
        for name in files:
            fd = os.open(os.path.join(root, name), os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        fsync_dir(Path(root))


def fsync_dir(path: Path) -> None:
    """Flush the directory entry list of ``path`` (after a rename into it)."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:         # some file systems cannot fsync a directory
        pass
    finally:
        os.close(fd)


def remove_dir(path: Path) -> None:
    """Remove the directory ``path``: renamed aside first (one atomic step, so no reader sees
    it half-deleted), then deleted."""
    path = Path(path)
    aside = Path(tempfile.mkdtemp(prefix=temporary_name(path.name, "old"), dir=path.parent))
    os.rename(path, aside / path.name)
    shutil.rmtree(aside, ignore_errors=True)


def default_mode_dir(path: Path) -> None:
    """Give ``path`` (made by mkdtemp, mode 0700) the mode a plain ``mkdir`` would."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(path, 0o777 & ~umask)


def check_target(target: Path, may_replace: Callable[[Path], None]) -> None:
    """Call ``may_replace(target)`` early (before any work), under the lock ``replace_dir`` takes.

    The lock keeps the check from seeing a target that a concurrent writer is swapping.
    """
    target = Path(target)
    if not target.parent.is_dir():
        return
    with locked(target.parent):
        may_replace(target)


def replace_dir(new: Path, target: Path, may_replace: Callable[[Path], None],
                carry: Callable[[Path], list[str]] | None = None) -> None:
    """Move the complete directory ``new`` to ``target``.

    If ``target`` exists, ``may_replace(target)`` is called (under a lock on the parent
    directory, so concurrent writers are serialised) and must raise to refuse; the entries
    ``carry(target)`` names (top-level names: what the caller did not write) are moved into
    ``new``, the old directory is moved aside, ``new`` renamed into place and the old one
    deleted.  On failure everything is put back.
    """
    new, target = Path(new), Path(target)
    with locked(target.parent):
        if not target.exists():
            os.rename(new, target)
            return
        may_replace(target)
        moved: list[str] = []
        try:
            for name in (carry(target) if carry else ()):
                os.rename(target / name, new / name)
                moved.append(name)
            old_root = Path(tempfile.mkdtemp(prefix=temporary_name(target.name, "old"), dir=target.parent))
            old = old_root / target.name
            os.rename(target, old)
        except BaseException:
            for name in moved:
                os.rename(new / name, target / name)
            raise
        try:
            os.rename(new, target)
        except BaseException:
            os.rename(old, target)
            os.rmdir(old_root)
            for name in moved:
                os.rename(new / name, target / name)
            raise
    shutil.rmtree(old_root, ignore_errors=True)
