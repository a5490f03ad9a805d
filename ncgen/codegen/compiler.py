"""Finding the system C compiler and its identity.

Lookup order: the ``cc`` argument, else ``$CC`` (may hold a command with arguments, e.g.
``"ccache gcc"``), else the first of ``cc``, ``gcc``, ``clang`` on PATH.  An explicit
choice that does not exist is an error, never silently replaced by another compiler.
"""
from __future__ import annotations

import shlex
import shutil
import subprocess
from dataclasses import dataclass
from functools import lru_cache

from ncgen.environment import decoded, getenv_key
from ncgen.errors import CompilerNotFound

CANDIDATES = ("cc", "gcc", "clang")


@dataclass(frozen=True)
class Compiler:
    """A C compiler command (``argv`` prefix) and the first line of its ``--version``."""

    argv: tuple[str, ...]
    version: str


def find_compiler(cc: str | None = None) -> Compiler:
    """The compiler to use (see module docstring); raises :class:`CompilerNotFound`.  Found
    once per ``cc``, ``$CC`` and ``$PATH`` (a run's kernel choice asks on every call)."""
    return _find(cc, getenv_key("CC"), getenv_key("PATH"))


@lru_cache(maxsize=16)
def _find(cc: str | None, env_cc, path) -> Compiler:
    """The compiler of ``cc``, else of ``$CC`` (``env_cc``), else the first of
    :data:`CANDIDATES` on ``$PATH`` (``path``); both variables as
    :func:`~ncgen.environment.getenv_key` gives them, or None."""
    env_cc = None if env_cc is None else decoded(env_cc)
    path = None if path is None else decoded(path)
    explicit = cc if cc is not None else env_cc
    if explicit:
        argv = shlex.split(explicit)
        found = shutil.which(argv[0], path=path) if argv else None
        if found is None:
            source = "the cc argument" if cc is not None else "$CC"
            raise CompilerNotFound(f"C compiler {explicit!r} from {source} was not found on PATH; "
                                   f"install it, fix {source}, or unset it to use one of "
                                   f"{', '.join(CANDIDATES)}")
        return _identify((found, *argv[1:]))
    for name in CANDIDATES:
        found = shutil.which(name, path=path)
        if found is not None:
            return _identify((found,))
    raise CompilerNotFound(f"no C compiler found (looked for $CC, {', '.join(CANDIDATES)} on PATH)")


def compiler_present(cc: str | None = None) -> bool:
    """Whether :func:`find_compiler` finds a C compiler that runs."""
    try:
        find_compiler(cc)
    except CompilerNotFound:
        return False
    return True


@lru_cache(maxsize=16)
def _identify(argv: tuple[str, ...]) -> Compiler:
    try:
        out = subprocess.run([*argv, "--version"], capture_output=True, text=True, timeout=60)
    except OSError as e:
        raise CompilerNotFound(f"C compiler {shlex.join(argv)} does not run: {e}") from None
    if out.returncode != 0:
        raise CompilerNotFound(f"C compiler {shlex.join(argv)} does not run: `--version` exited with "
                               f"{out.returncode}: {(out.stderr or out.stdout).strip()[:300]}")
    lines = (out.stdout or out.stderr).strip().splitlines()
    return Compiler(argv=argv, version=lines[0] if lines else "")
