"""Compile a generated package into a shared library, cached by content.

The cache lives in ``$NCGEN_CACHE_DIR`` (default ``~/.cache/ncgen``); an entry
``<name>-<key>/`` holds ``lib<name>.so``, a copy of the package manifest and
``build.json`` (commands used, and ``library_sha256``: the hash of the library recorded
when the entry was published).  The key hashes the package's C sources and headers, the
compiler (path and version) and the flags, so an unchanged package is never rebuilt.  The
package's *data* sources (``build.data``: its initial state, which Python reads from the
manifest) are left out of the library and of the key, so a model at a new initial state
finds its library in the cache (:func:`library_sources`).
Entries are built in a temporary sibling directory, flushed to disk (fsync) and renamed
into place under an exclusive lock, so concurrent builds of the same package are safe,
yield one library, and a crash or a kill leaves either no entry or a complete one.

Before a cached library is used its record's ``key`` is checked against the one asked for (an
entry holding a build of other flags or sources under this name, copied or left by hand, is
rebuilt: a library compiled at -O0 never passes for a default build) and its sha256 against
``library_sha256``: a truncated, zeroed, garbage or empty file (or a missing/unreadable ``build.json``) is never
loaded (``dlopen`` of such a file crashes the process with SIGBUS/SIGSEGV or fails with a
raw OSError); the damaged entry is removed and rebuilt, with a note on stderr.  Temporary
build folders left by killed builds are removed once their process is gone
(:func:`ncgen.files.sweep_stale`).

Flags: ``cflags`` argument, else ``$NCGEN_CFLAGS`` (unless ``env_flags`` is false: ncgen's
model-independent libraries, compiled once per ncgen version and compiler whatever the flags),
else the defaults: ``-O2``, and ``-O1``
for the package's ``build.large_sources`` (files holding a function so long, or belonging
to a package so big, that gcc's -O2 passes take several times longer than -O1's; see
:data:`ncgen.codegen.package.LARGE_FUNCTION_INSTRUCTIONS`).  Never ``-O0``: straight-line
code at -O0 keeps every value on the stack and runs ~3x slower than at -O1/-O2.  ``-fPIC`` and ``-shared`` (and
``-lm``) are always added.  Sources are compiled in parallel (``jobs``, default: CPU count),
one object per file.
"""
from __future__ import annotations

import json
import os
import platform
import shlex
import subprocess
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

from ncgen.codegen import fsutil, manifest
from ncgen.codegen.compiler import Compiler, find_compiler
from ncgen.codegen.fsutil import cache_dir
from ncgen.codegen.package import Package
from ncgen.errors import CodegenError

DEFAULT_CFLAGS = ("-O2",)
#: Default flags of a package's ``build.large_sources``: the 31 k-instruction KKT solve of
#: the 40-bar chain's stepper compiles in 4.6 s (CPU) at -O1, 1.9 s at -O0, ~9 s at -O2, and
#: runs in 24 us at -O1, 27 us at -O2, 77 us at -O0 (benchmarks/README.md, "Compile flags of long
#: functions").
LARGE_CFLAGS = ("-O1",)
#: Bump when the way libraries are built changes, to invalidate old cache entries.
BUILD_SCHEME = 4
#: Seconds before a running compile prints its status line.
PROGRESS_DELAY = 1.0


@dataclass(frozen=True)
class BuildResult:
    """The compiled library (``path``; the object is also path-like) and whether it came
    from the cache."""

    path: Path
    cached: bool
    key: str
    compiler: Compiler
    cflags: tuple[str, ...]

    def __fspath__(self) -> str:
        return str(self.path)


def resolve_cflags(cflags: str | Sequence[str] | None, env_flags: bool = True) -> tuple[str, ...]:
    """The user part of the flags: ``cflags``, else ``$NCGEN_CFLAGS`` (if ``env_flags``), else ``-O2``."""
    if cflags is None:
        env = os.environ.get("NCGEN_CFLAGS") if env_flags else None
        return tuple(shlex.split(env)) if env is not None else DEFAULT_CFLAGS
    return tuple(shlex.split(cflags)) if isinstance(cflags, str) else tuple(cflags)


def source_cflags(pkg: Package, cflags: str | Sequence[str] | None,
                  env_flags: bool = True) -> dict[str, tuple[str, ...]]:
    """The flags of each source of ``pkg``: the user's for all (``cflags``, or
    ``$NCGEN_CFLAGS`` if ``env_flags``), else :data:`DEFAULT_CFLAGS`, and :data:`LARGE_CFLAGS`
    for the manifest's ``build.large_sources``."""
    build = pkg.manifest["build"]
    flags = resolve_cflags(cflags, env_flags)
    chosen = cflags is not None or (env_flags and os.environ.get("NCGEN_CFLAGS") is not None)
    large = set() if chosen else set(build.get("large_sources", ()))
    return {src: LARGE_CFLAGS if src in large else flags for src in library_sources(build)}


def library_sources(build: Mapping) -> list[str]:
    """The sources of a package's cached library: its manifest's ``build.sources`` without
    ``build.data`` (the files the Makefile adds for C programs, see
    :class:`~ncgen.codegen.doc.PackageDoc`)."""
    data = set(build.get("data", ()))
    return [src for src in build["sources"] if src not in data]


def compile_package(pkg: Package | str | os.PathLike, cc: str | None = None,
                    cflags: str | Sequence[str] | None = None, jobs: int | None = None,
                    env_flags: bool = True) -> BuildResult:
    """Build (or find in the cache) the shared library of package ``pkg`` (``env_flags``:
    whether ``$NCGEN_CFLAGS`` applies when ``cflags`` is None; module docstring)."""
    pkg = pkg if isinstance(pkg, Package) else Package.open(pkg)
    compiler = find_compiler(cc)
    flags = resolve_cflags(cflags, env_flags)
    per_source = source_cflags(pkg, cflags, env_flags)
    key = build_key(pkg, compiler, per_source)
    root = cache_dir()
    entry = root / f"{pkg.name}-{key[:24]}"
    library = entry / f"lib{pkg.name}.so"
    result = BuildResult(path=library, cached=True, key=key, compiler=compiler, cflags=flags)
    fsutil.sweep_stale(root)          # build folders of killed builds (owner gone)
    if entry_problem(entry, library, key) is None:
        return result
    try:
        root.mkdir(parents=True, exist_ok=True)
        with fsutil.locked(root / f".{entry.name}.lock"):
            problem = entry_problem(entry, library, key)
            if problem is None:  # another process built it while we waited
                return result
            if entry.exists():
                _status(f"cached library {library} is damaged ({problem}); rebuilding it")
            with fsutil.temporary_sibling(entry) as tmp:
                commands = _build(pkg, compiler, flags, per_source, jobs, tmp)
                (tmp / manifest.FILENAME).write_bytes((pkg.path / manifest.FILENAME).read_bytes())
                (tmp / BUILD_RECORD).write_text(json.dumps(
                    {"key": key, "package": pkg.name, "content_hash": pkg.content_hash,
                     "compiler": compiler.version, "commands": commands,
                     "library_sha256": fsutil.sha256_file(tmp / library.name)}, indent=1) + "\n")
                fsutil.default_mode_dir(tmp)
                fsutil.fsync_tree(tmp)
                if entry.exists():  # damaged, or left incomplete by hand or an older ncgen
                    fsutil.remove_dir(entry)
                os.rename(tmp, entry)
                fsutil.fsync_dir(root)
    except OSError as e:
        raise CodegenError(f"could not write the compile cache {root}: {e.strerror or e} "
                           f"({e.filename or root}); set NCGEN_CACHE_DIR to a writable directory") from None
    return BuildResult(path=library, cached=False, key=key, compiler=compiler, cflags=flags)


#: The file of a cache entry recording how it was built and the library's sha256.
BUILD_RECORD = "build.json"


def entry_problem(entry: Path, library: Path, key: str | None = None) -> str | None:
    """Why the cache entry ``entry`` may not be used (missing, no record, a record of another
    build than ``key`` when given, library hash differing from the one recorded at
    publication), or ``None`` when it is intact."""
    if not entry.exists():
        return "missing"
    try:
        record = json.loads((entry / BUILD_RECORD).read_text())
        expected = record["library_sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        return f"no readable {BUILD_RECORD} with the library's hash"
    if key is not None and record.get("key") != key:
        return f"its {BUILD_RECORD} records another build (flags {recorded_flags(record)})"
    try:
        actual = fsutil.sha256_file(library)
    except OSError as e:
        return f"library unreadable: {e.strerror or e}"
    if actual != expected:
        return f"library sha256 {actual[:12]}... differs from the {expected[:12]}... recorded when it was built"
    return None


def recorded_flags(record: Mapping) -> list[str]:
    """The optimisation flags (``-O…``) of the commands a build record lists, in order, once each."""
    flags = [a for cmd in record.get("commands", ()) for a in cmd if isinstance(a, str) and a.startswith("-O")]
    return list(dict.fromkeys(flags))


def optimised(library: Path) -> bool:
    """Whether the cached ``library`` was compiled with optimisation: its entry's record lists
    ``-O`` flags and none is ``-O0`` (False when the record cannot be read)."""
    try:
        record = json.loads((Path(library).parent / BUILD_RECORD).read_text())
    except (OSError, ValueError):
        return False
    flags = recorded_flags(record) if isinstance(record, dict) else []
    return bool(flags) and "-O0" not in flags


def build_key(pkg: Package, compiler: Compiler, per_source: dict[str, tuple[str, ...]]) -> str:
    """sha256 of what the library depends on: sources, headers, compiler, flags of each
    source, platform."""
    build = pkg.manifest["build"]
    files = {rel: fsutil.sha256_file(pkg.path / rel) for rel in library_sources(build) + build["headers"]}
    data = {"scheme": BUILD_SCHEME, "name": pkg.name, "files": files, "compiler": list(compiler.argv),
            "compiler_version": compiler.version, "cflags": {k: list(v) for k, v in per_source.items()},
            "platform": [sys.platform, platform.machine()]}
    return fsutil.sha256_bytes(manifest.canonical_json(data).encode())


def _build(pkg: Package, compiler: Compiler, flags: tuple[str, ...], per_source: dict[str, tuple[str, ...]],
           jobs: int | None, out: Path) -> list[list[str]]:
    """Compile every source of ``pkg`` to an object in ``out`` (``per_source`` flags) and link
    ``out/lib<name>.so`` (``flags``)."""
    sources = library_sources(pkg.manifest["build"])
    compile_cmds = [[*compiler.argv, *per_source[src], "-fPIC", "-I.", "-c", src, "-o", str(out / f"{src}.o")]
                    for src in sources]
    link_cmd = [*compiler.argv, *flags, "-shared", "-o", str(out / f"lib{pkg.name}.so"),
                *(str(out / f"{src}.o") for src in sources), "-lm"]
    large = [src for src in sources if per_source[src] != flags]
    how = shlex.join(flags) + (f"; {len(large)} with {shlex.join(LARGE_CFLAGS)}: very long functions" if large else "")
    progress = _Progress(f"compiling C package {pkg.name!r} ({len(sources)} files, {how})", len(sources))
    try:
        workers = max(1, min(jobs or os.cpu_count() or 1, len(sources)))
        # longest files first, so that no core is left compiling a big one alone at the end
        order = sorted(range(len(sources)), key=lambda i: -(pkg.path / sources[i]).stat().st_size)
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for _ in pool.map(lambda i: _run(compile_cmds[i], pkg.path, progress), order):
                pass
        _run(link_cmd, pkg.path, None)
        for src in sources:
            (out / f"{src}.o").unlink()
    finally:
        progress.finish()
    return [[arg.replace(str(out), "$BUILD_DIR") for arg in cmd] for cmd in compile_cmds + [link_cmd]]


def _run(cmd: list[str], cwd: Path, progress: "_Progress | None") -> None:
    try:
        out = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    except OSError as e:
        raise CodegenError(f"could not run the C compiler: {e}\ncommand: {shlex.join(cmd)}") from None
    if out.returncode != 0:
        raise CodegenError(f"C compilation failed (exit status {out.returncode}) in {cwd}\n"
                           f"command: {shlex.join(cmd)}\n{_first_errors(out.stderr + out.stdout)}")
    if progress is not None:
        progress.step()


def _first_errors(log: str, n: int = 12) -> str:
    """The first ``n`` lines of the compiler output from the first line mentioning an error."""
    lines = log.strip().splitlines()
    start = next((i for i, line in enumerate(lines) if "error" in line.lower()), 0)
    shown = lines[start:start + n]
    more = len(lines) - start - len(shown)
    return "\n".join(shown) + (f"\n... ({more} more lines)" if more > 0 else "")


class _Progress:
    """Progress of a compile: a tqdm bar over the files on a terminal (:mod:`ncgen.progress`),
    else status lines on stderr for logs, shown only if the work lasts longer than
    PROGRESS_DELAY; both end with a line saying how long it took."""

    def __init__(self, what: str, total: int):
        from ncgen.progress import bar, enabled

        self.what, self.total, self.done = what, total, 0
        self.start = time.monotonic()
        self.shown = False
        self.lock = threading.Lock()
        self.bar = bar(total, "compiling C", unit="file", mode=None) if enabled(None) else None
        self.timer = threading.Timer(PROGRESS_DELAY, self._show)
        self.timer.daemon = True
        self.timer.start()

    def _show(self) -> None:
        with self.lock:
            self.shown = True
            if self.bar is not None:
                return
            _status(f"{self.what}: {self.done}/{self.total} compiled, {time.monotonic() - self.start:.0f} s")

    def step(self) -> None:
        with self.lock:
            self.done += 1
            if self.bar is not None:
                self.bar.update(1)
            show = self.shown and self.done < self.total
        if show:
            self._show()

    def finish(self) -> None:
        self.timer.cancel()
        if self.bar is not None:
            self.bar.close()
        if self.shown:
            _status(f"{self.what}: done in {time.monotonic() - self.start:.1f} s")


def _status(line: str) -> None:
    sys.stderr.write(f"ncgen: {line}\n")
    sys.stderr.flush()
