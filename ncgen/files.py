"""Output files written whole or not at all.

:func:`atomic_path` hands out a temporary path next to the target (same directory, same
suffix, so that writers which infer the format from the name still work); the file is
renamed onto the target when the block succeeds and deleted when it fails, so a reader
never sees a partial file and a failed run leaves nothing behind.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Iterator


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """A temporary sibling of ``target`` to write to; renamed onto ``target`` on success."""
    target = Path(target)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=target.suffix, dir=target.parent.resolve())
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.chmod(tmp, _new_file_mode(target))
        os.replace(tmp, target)
    finally:
        tmp.unlink(missing_ok=True)


def _new_file_mode(target: Path) -> int:
    """The existing file's mode, or the default for a new file (0666 minus the umask)."""
    if target.exists():
        return target.stat().st_mode & 0o7777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask
