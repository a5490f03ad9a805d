"""CasADi functions backed by a compiled package, or by CasADi's virtual machine.

Backends: ``"compiled"`` builds (or reuses from the cache) the package's library and wraps
each function with ``casadi.external``; ``"vm"`` returns the original SX functions (only for
a :class:`Package` returned by ``write_package``, which holds them); ``"auto"`` compiles if a
C compiler exists and otherwise warns once per process and uses the VM.

Results are keyed by the function names given to ``write_package``; compiled functions
are named by their C symbol ``<package>_<function>``.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Iterable

import casadi as ca

from ncgen.codegen import manifest
from ncgen.codegen.compile_cache import BuildResult, compile_package
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.package import Package
from ncgen.errors import CodegenError, CompilerNotFound

BACKENDS = ("compiled", "vm", "auto")

_warned_no_compiler = False


class NoCompilerWarning(UserWarning):
    """``backend="auto"`` found no C compiler and fell back to CasADi's virtual machine."""


def load_functions(source: Package | BuildResult | str | os.PathLike,
                   names: Iterable[str] | None = None, *, backend: str = "auto",
                   cc: str | None = None, cflags=None, jobs: int | None = None) -> dict[str, ca.Function]:
    """Functions ``names`` (default: all) of ``source``: a Package, a package directory,
    a BuildResult or a compiled library (``.so``; names are then looked up in the
    ``manifest.json`` next to it if present, else taken as C symbols).  ``cc``, ``cflags``,
    ``jobs`` go to :func:`~ncgen.codegen.compile_cache.compile_package`."""
    if backend not in BACKENDS:
        raise CodegenError(f"backend must be one of {BACKENDS}, found {backend!r}")
    if isinstance(source, BuildResult):
        source = source.path
    if not isinstance(source, Package):
        path = Path(source)
        if path.is_file():
            if backend == "vm":
                raise CodegenError(f"backend 'vm' needs the CasADi functions, but {path} is a "
                                   f"compiled library; pass the Package returned by write_package")
            return external_functions(path, names, _manifest_beside(path))
        source = Package.open(path)
    pkg = source
    if backend == "vm":
        return _vm(pkg, names)
    try:
        built = compile_package(pkg, cc=cc, cflags=cflags, jobs=jobs)
    except CompilerNotFound as e:
        if backend == "compiled" or pkg.functions is None:
            raise
        warn_no_compiler(e)
        return _vm(pkg, names)
    return external_functions(built.path, names, pkg.manifest)


def _vm(pkg: Package, names: Iterable[str] | None) -> dict[str, ca.Function]:
    if pkg.functions is None:
        raise CodegenError(f"backend 'vm' needs the CasADi functions in memory, but package "
                           f"{pkg.path} was opened from disk; use the Package returned by "
                           f"write_package, or backend='compiled'")
    return {n: pkg.functions[n] for n in _check_names(names, list(pkg.functions), pkg.name)}


def external_functions(library: Path, names: Iterable[str] | None, data: dict | None) -> dict[str, ca.Function]:
    """Functions ``names`` (default: all) of compiled ``library`` through ``casadi.external``;
    ``data``: the package manifest (maps names to C symbols), or None to take names as symbols."""
    if data is None:
        if names is None:
            raise CodegenError(f"{library} has no manifest.json beside it; pass the C names of "
                               f"the functions to load")
        c_names = {n: n for n in names}
    else:
        known = {f["name"]: f["c_name"] for f in data["functions"]}
        c_names = {n: known[n] for n in _check_names(names, list(known), data["name"])}
    out = {}
    for name, c_name in c_names.items():
        try:
            out[name] = ca.external(c_name, str(library))
        except RuntimeError as e:
            raise CodegenError(f"could not load function {c_name!r} from {library}: "
                               f"{str(e).strip().splitlines()[-1]}") from None
    return out


def _check_names(names: Iterable[str] | None, known: list[str], package: str) -> list[str]:
    if names is None:
        return known
    names = [names] if isinstance(names, str) else list(names)
    missing = [n for n in names if n not in known]
    if missing:
        raise CodegenError(f"package {package!r} has no function {missing}; it has {known}")
    return names


def _manifest_beside(library: Path) -> dict | None:
    if not (library.parent / manifest.FILENAME).is_file():
        return None
    return manifest.read_manifest(library.parent)


def warn_no_compiler(error: CompilerNotFound) -> None:
    """Warn once per process that no C compiler was found and the VM is used instead."""
    global _warned_no_compiler
    if _warned_no_compiler:
        return
    _warned_no_compiler = True
    reason = str(error)
    if reason.startswith("no C compiler found"):
        reason = f"looked for $CC, {', '.join(CANDIDATES)}"
    warnings.warn(f"no C compiler found ({reason}); falling back to CasADi's virtual machine, "
                  f"which is slower; install gcc to get compiled kernels", NoCompilerWarning, stacklevel=3)
