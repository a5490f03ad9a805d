"""Output files and directories written whole or not at all, and the clean-up of what a
killed run leaves behind.

:func:`atomic_path` hands out a temporary path next to the target (same directory, same
suffix, so that writers which infer the format from the name still work); the file is
renamed onto the target when the block succeeds and deleted when it fails, so a reader
never sees a partial file and a failed run leaves nothing behind.

Every temporary name made here carries its owner: ``.<target>.tmp-<host>-<pid>-<random>``
(:func:`temporary_name`).  A process killed before it could clean up leaves such an entry;
:func:`sweep_stale` removes the entries of a directory whose owner process is gone (same
host) or that are older than :data:`STALE_AGE` (another host, or names without an owner),
and never touches anything else.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import shutil
import socket
import tempfile
import time
from pathlib import Path
from typing import Callable, Iterator

from ncgen.errors import NcgenError

#: Age (s) after which a temporary entry whose owner cannot be checked counts as stale.
STALE_AGE = 24 * 3600.0
#: ``.<target>.tmp-<host>-<pid>-<random>`` (and ``.old-`` for directories being replaced).
_OWNED = re.compile(r"^\..+\.(?:tmp|old)-(?P<host>[A-Za-z0-9_]*)-(?P<pid>\d+)-[^/]*$")
#: Names written by older versions of ncgen, without an owner: only the age bound applies.
_UNOWNED = re.compile(r"^\..+\.(?:tmp|old)-[a-z0-9_]{8}$")


def cache_dir() -> Path:
    """``$NCGEN_CACHE_DIR``, else ``~/.cache/ncgen``: the compile cache, the store of built
    models and the stored derivations of coordinate types."""
    env = os.environ.get("NCGEN_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "ncgen"


#: The environment variable that turns the stores of built models and of derivations off.
MODEL_CACHE_ENV = "NCGEN_MODEL_CACHE"


def model_cache_enabled() -> bool:
    """Whether built models and derivations are read from and written to their stores
    (``$NCGEN_MODEL_CACHE``: ``0``, ``off``, ``no`` or ``false`` turn them off)."""
    return os.environ.get(MODEL_CACHE_ENV, "1").strip().lower() not in ("0", "off", "no", "false")


def _host() -> str:
    return re.sub(r"[^A-Za-z0-9_]", "_", socket.gethostname())[:40]


def temporary_name(target: str, kind: str = "tmp") -> str:
    """The prefix of a temporary sibling of ``target`` (a file or directory name) owned by
    this process: ``.<target>.<kind>-<host>-<pid>-`` (the caller adds a random part)."""
    return f".{target}.{kind}-{_host()}-{os.getpid()}-"


def _owner_gone(host: str, pid: int) -> bool | None:
    """True if process ``pid`` of this host is gone, False if it runs, None if unknowable."""
    if host != _host():
        return None
    if pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:        # exists, owned by someone else
        return False
    return False


def is_stale(entry: Path, now: float | None = None) -> bool:
    """Whether ``entry`` is a temporary left by a process that is gone (see module docstring)."""
    m = _OWNED.match(entry.name)
    if m is None and not _UNOWNED.match(entry.name):
        return False
    if m is not None:
        gone = _owner_gone(m["host"], int(m["pid"]))
        if gone is not None:
            return gone
    try:
        age = (time.time() if now is None else now) - entry.lstat().st_mtime
    except OSError:
        return False
    return age > STALE_AGE


def sweep_stale(directory: str | os.PathLike, target: str | None = None) -> list[Path]:
    """Remove the stale temporaries in ``directory`` (only those of ``target`` if given);
    returns what was removed.  Errors (a concurrent sweep, permissions) are ignored."""
    directory = Path(directory)
    removed = []
    try:
        entries = list(directory.iterdir())
    except OSError:
        return removed
    for entry in entries:
        if target is not None and not entry.name.startswith(f".{target}."):
            continue
        if not is_stale(entry):
            continue
        try:
            if entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry)
            else:
                entry.unlink()
            removed.append(entry)
        except OSError:
            pass
    return removed


def decode_text(data: bytes, origin: str) -> str:
    """The UTF-8 text of a file's bytes (a byte-order mark is accepted and dropped); another
    encoding is an :class:`~ncgen.errors.NcgenError` naming ``origin``, the line and the byte."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        line = data[:e.start].count(b"\n") + 1
        raise NcgenError(f"{origin}: not UTF-8 text: byte 0x{data[e.start]:02x} at line {line} cannot be "
                         f"decoded; save the file as UTF-8") from None


def incomplete_path(target: str | os.PathLike) -> Path:
    """Where the partial result of a failed run that was to write ``target`` goes:
    ``name.incomplete.suffix`` beside it, so that nothing mistakes it for a finished one."""
    target = Path(target)
    return target.with_name(f"{target.stem}.incomplete{target.suffix}")


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike) -> Iterator[Path]:
    """A temporary sibling of ``target`` to write to; renamed onto ``target`` on success."""
    target = Path(target)
    parent = target.parent.resolve()
    if target.is_dir():
        raise NcgenError(f"cannot write {str(target)!r}: it is a directory")
    try:
        sweep_stale(parent, target.stem)
        fd, tmp = tempfile.mkstemp(prefix=temporary_name(target.stem), suffix=target.suffix, dir=parent)
    except OSError as exc:                # name the user's path, not the temporary one
        raise NcgenError(f"cannot write {str(target)!r}: {exc.strerror or exc} "
                         f"(directory {str(target.parent)!r})") from None
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        os.chmod(tmp, _new_file_mode(target))
        try:
            os.replace(tmp, target)
        except OSError as exc:
            raise NcgenError(f"cannot write {str(target)!r}: {exc.strerror or exc}") from None
    finally:
        tmp.unlink(missing_ok=True)


def _new_file_mode(target: Path) -> int:
    """The existing file's mode, or the default for a new file (0666 minus the umask)."""
    if target.exists():
        return target.stat().st_mode & 0o7777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def write_entry(path: str | os.PathLike, header: dict, payload: bytes) -> bool:
    """Write a store entry atomically: one line of JSON (``header`` with the payload's size and
    sha256 added), then ``payload``; False if it cannot be written."""
    path = Path(path)
    head = json.dumps({**header, "size": len(payload), "sha256": hashlib.sha256(payload).hexdigest()}).encode()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            tmp.write_bytes(head + b"\n" + payload)
    except (OSError, NcgenError):
        return False
    return True


def read_entry(path: str | os.PathLike, header: dict, decode: Callable[[bytes], object], what: str,
               redo: str = "building it again"):
    """``decode(payload)`` of the store entry at ``path`` written by :func:`write_entry`, or None:
    absent, or damaged (a field of ``header``, the size or the sha256 not matching, or ``decode``
    failing), then removed with a note on stderr naming it as ``what`` and saying ``redo``."""
    import sys

    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError:
        return None
    head, _, payload = raw.partition(b"\n")
    try:
        found = json.loads(head)
        ok = (isinstance(found, dict) and all(found.get(k) == v for k, v in header.items())
              and found.get("size") == len(payload) and found.get("sha256") == hashlib.sha256(payload).hexdigest())
    except ValueError:
        ok = False
    if ok:
        try:
            hit = decode(payload)
            os.utime(path)                 # most recently used: kept longest by a pruning store
            return hit
        except Exception as exc:          # noqa: BLE001 — any failure of a stored entry means: make it again
            why = f"cannot be read back ({type(exc).__name__}: {exc})"
    else:
        why = "is damaged or from another version of ncgen"
    print(f"ncgen: the stored {what} {path} {why}; {redo}", file=sys.stderr)
    path.unlink(missing_ok=True)
    return None
