"""The element library: the kernels of every shipped kind and the table loops, compiled once
per ncgen version and compiler and shared by every model (docs/architecture.md, "Element
tables").

:func:`element_library` finds the library through an index file of the compile cache,
``element-tables-<sources key>-<compiler key>.json`` (the library's path and sha256): the
sources key hashes ncgen's version, CasADi's and the files the library is made of
(:data:`~ncgen.codegen.element_kernels.SOURCES`, the kernel generator and the symbolic
formulas it reads); the compiler key the compiler's path (found as
:func:`ncgen.codegen.compiler.find_compiler` does, without running it).  A hit loads the
library with no call of the compiler, and so does a process with no compiler at all when a
library of the same sources is cached.  Before the cache, the library ``pip install .``
compiled into the package is taken when its keys, flags and sha256 match
(:mod:`ncgen.runtime.installed_libraries`).  A miss writes the package
(:func:`~ncgen.codegen.element_kernels.write_element_package`) and compiles it with
:func:`ncgen.codegen.compile_cache.compile_package` (cached by content, atomic).

:class:`TableFunctions` evaluates ``Φ(q)``, ``A(q)`` (CSC nonzeros), ``Φ_t`` and ``M`` of
one model from its :class:`~ncgen.codegen.model_tables.ModelTables`.
"""
from __future__ import annotations

import ctypes
import hashlib
import json
import os
import platform
import shlex
import shutil
import sys
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.codegen import c_binding
from ncgen.codegen.compile_cache import BUILD_SCHEME, cache_dir, entry_problem
from ncgen.codegen.compiler import CANDIDATES
from ncgen.codegen.element_kernels import (CONTACT_PACKAGE, CONTACT_SOURCES, PACKAGE, SOURCES, kind_names,
                                           write_element_package)
from ncgen.codegen.model_tables import ModelTables
from ncgen.codegen.render import shipped_templates_dir
from ncgen.errors import CodegenError, CompilerNotFound, ShapeError
from ncgen.files import atomic_path
from ncgen.runtime.installed_libraries import installed_library
from ncgen.version import __version__

#: Fields of ``ncgen_tables`` (templates/c/runtime/ncgen_element_tables.h), in order.
TABLE_FIELDS = (
    ("int", "nq"), ("int", "nc"), ("int", "dim"), ("int", "a_nnz"), ("int", "m_nnz"), ("int", "nf"),
    *(("const int *", f) for f in ("feat_ptr", "feat_row", "feat_col")),
    *(("const double *", f) for f in ("feat_coef", "feat_const")),
    ("int", "ne"),
    *(("const int *", f) for f in ("el_kind", "el_arg_ptr", "el_arg", "el_sc_ptr")),
    ("const double *", "el_sc"),
    *(("const int *", f) for f in ("el_row_ptr", "el_row", "el_apos_ptr", "el_apos")),
    ("int", "nm"),
    *(("const int *", f) for f in ("mem_kind", "mem_q_ptr", "mem_q_col")),
    ("const double *", "mem_q_const"), ("const int *", "mem_c_ptr"), ("const double *", "mem_c"),
    *(("const int *", f) for f in ("mem_row_ptr", "mem_row", "mem_apos_ptr", "mem_apos", "mem_mpos_ptr",
                                   "mem_mpos")),
)
#: The library's entry points (``PACKAGE`` prefix), as element_tables.c.j2 spells them.
SIGNATURES = {
    "kind_names": c_binding.Signature("const char *", ()),
    "work_size": c_binding.Signature("long", (("const ncgen_tables *", "T"),)),
    "check": c_binding.Signature("int", (("const ncgen_tables *", "T"),)),
    "phi": c_binding.Signature("int", (("const ncgen_tables *", "T"), ("const double *", "q"),
                                       ("double *", "phi"), ("double *", "work"))),
    "jacobian": c_binding.Signature("int", (("const ncgen_tables *", "T"), ("const double *", "q"),
                                            ("double *", "A"), ("double *", "work"))),
    "phi_t": c_binding.Signature("int", (("const ncgen_tables *", "T"), ("double *", "phi_t"))),
    "gamma": c_binding.Signature("int", (("const ncgen_tables *", "T"), ("const double *", "q"),
                                         ("const double *", "v"), ("double *", "gamma"), ("double *", "work"))),
    "mass": c_binding.Signature("int", (("const ncgen_tables *", "T"), ("double *", "M"), ("double *", "work"))),
}
INDEX_PREFIX = "element-tables"
CONTACT_INDEX_PREFIX = "contact-tables"


class _Tables(ctypes.Structure):
    _fields_ = [(name, ctypes.c_void_p if "*" in t else ctypes.c_int) for t, name in TABLE_FIELDS]


def sources_key(contacts: bool = False) -> str:
    """sha256 of what the library is made of (see module docstring); ``contacts``: the contact
    library's (also the contact C and the pair kinds' formulas)."""
    import ncgen.codegen.element_kernels as ek
    import ncgen.model.sym2casadi as s2c
    import ncgen.symbolic.coordinates as coords
    import ncgen.symbolic.joint_primitives as joints

    templates = shipped_templates_dir()
    modules = [ek, s2c, coords, joints]
    if contacts:
        import ncgen.assembly.contact_kinematics as kinematics
        import ncgen.assembly.pair_kinds as pair_kinds
        import ncgen.codegen.stepper_package as stepper_package

        modules += [kinematics, pair_kinds, stepper_package]
    files = [templates / rel for rel in SOURCES + (CONTACT_SOURCES if contacts else ())] + \
        [Path(m.__file__) for m in modules]
    h = hashlib.sha256(f"{__version__}\n{ca.__version__}\n{BUILD_SCHEME}\n{sys.platform}\n"
                       f"{platform.machine()}\n".encode())
    for f in files:
        h.update(f.name.encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def compiler_path() -> str | None:
    """The compiler command :func:`~ncgen.codegen.compiler.find_compiler` would use, found on
    PATH without running it, or None."""
    explicit = os.environ.get("CC")
    if explicit:
        argv = shlex.split(explicit)
        path = shutil.which(argv[0]) if argv else None
        return None if path is None else shlex.join([path, *argv[1:]])
    return next((p for p in (shutil.which(n) for n in CANDIDATES) if p is not None), None)


def _index(prefix: str, source: str, compiler: str, cflags: str | None = None) -> Path:
    """The index file of a library of ``source`` built by ``compiler`` with the flags ``cflags``
    (:func:`effective_cflags`: given, else ``$NCGEN_CFLAGS``; part of its name unless None, ncgen's
    defaults: builds of other flags are other libraries)."""
    tag = compiler if cflags is None else f"{compiler}\0{cflags}"
    ckey = hashlib.sha256(tag.encode()).hexdigest()[:12]
    return cache_dir() / f"{prefix}-{source[:20]}-{ckey}.json"


def _indexed(index: Path) -> Path | None:
    """The intact library an index file names, or None."""
    try:
        library = Path(json.loads(index.read_text())["library"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return library if entry_problem(library.parent, library) is None else None


def element_library(cflags: str | None = None) -> tuple[Path, bool]:
    """``(path of the element library, whether it was compiled now)``."""
    return cached_library(INDEX_PREFIX, sources_key(), write_element_package, PACKAGE, cflags)


def contact_library(cflags: str | None = None) -> tuple[Path, bool]:
    """``(path of the contact library, whether it was compiled now)``: the element library's
    kernels and stepper with nonsmooth contacts and the pair kinds (``CONTACT_PACKAGE``),
    compiled once per ncgen version and compiler as the element library is."""
    return cached_library(CONTACT_INDEX_PREFIX, sources_key(contacts=True),
                          lambda out: write_element_package(out, contacts=True), CONTACT_PACKAGE, cflags)


def library_ready(prefix: str, source: str, cflags: str | None = None) -> bool:
    """Whether :func:`cached_library` would find the library (``cflags`` as it takes them)
    installed or in the compile cache (no compile)."""
    compiler = compiler_path()
    if installed_library(prefix, source, compiler, effective_cflags(cflags)) is not None:
        return True
    if compiler is None:
        return any(_indexed(index) is not None for index in cache_dir().glob(f"{prefix}-{source[:20]}-*.json"))
    return _indexed(_index(prefix, source, compiler, effective_cflags(cflags))) is not None


def effective_cflags(cflags: str | None) -> str | None:
    """The flags a library is built with: ``cflags``, else ``$NCGEN_CFLAGS``, else None (ncgen's defaults)."""
    return os.environ.get("NCGEN_CFLAGS") if cflags is None else cflags


def cached_library(prefix: str, source: str, write, package: str, cflags: str | None = None) -> tuple[Path, bool]:
    """``(path, compiled now)`` of the library ``package`` written by ``write(out_dir)`` and
    compiled once per ``source`` key and compiler, found through the index files
    ``<prefix>-<source>-<compiler>.json`` of the compile cache (module docstring), with the
    flags ``cflags``, else ``$NCGEN_CFLAGS`` if set (then part of the index's name: the test
    suite's fast tier builds the libraries at -O0 beside the default ones), else ncgen's
    defaults.  A library the install built with the same keys and flags comes first
    (:func:`~ncgen.runtime.installed_libraries.installed_library`, verified by its sha256)."""
    cflags = effective_cflags(cflags)
    compiler = compiler_path()
    installed = installed_library(prefix, source, compiler, cflags)
    if installed is not None:       # built by the install (ncgen/runtime/installed_libraries.py)
        return installed, False
    if compiler is None:            # no compiler: any library of these sources will do
        for index in sorted(cache_dir().glob(f"{prefix}-{source[:20]}-*.json")):
            library = _indexed(index)
            if library is not None:
                return library, False
        raise CompilerNotFound(f"no C compiler found (looked for $CC, {', '.join(CANDIDATES)} on PATH) and no "
                               f"{package} library of ncgen {__version__} in the compile cache {cache_dir()}")
    index = _index(prefix, source, compiler, cflags)
    library = _indexed(index)
    if library is not None:
        return library, False
    from ncgen.codegen.compile_cache import compile_package

    with tempfile.TemporaryDirectory(prefix=f"{package}-") as tmp:
        built = compile_package(write(Path(tmp) / package), cflags=cflags, env_flags=False)
    index.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(index) as tmp_index:
        tmp_index.write_text(json.dumps({"library": str(built.path), "compiler": built.compiler.version,
                                         "ncgen": __version__}, indent=1) + "\n")
    return built.path, True


class ElementLibrary:
    """The loaded element library (or the contact library, ``package``): its entry points
    bound (:data:`SIGNATURES`)."""

    def __init__(self, path: Path, package: str = PACKAGE):
        self.path, self.package = path, package
        self._lib = c_binding.open_library(path)
        structs = {"ncgen_tables": _Tables}
        self.fn = {k: c_binding.bind(self._lib, f"{package}_{k}", s, structs=structs, addresses=True)
                   for k, s in SIGNATURES.items()}
        found = self.fn["kind_names"]().decode()
        if found != kind_names():
            raise CodegenError(f"{path}: element library of other kinds ({found!r}, expected {kind_names()!r}); "
                               "delete it to have it rebuilt")


_LOADED: dict[Path, ElementLibrary] = {}


def load_element_library(cflags: str | None = None) -> ElementLibrary:
    """The element library, compiled at first use (:func:`element_library`) and loaded once per process."""
    path, _ = element_library(cflags)
    if path not in _LOADED:
        _LOADED[path] = ElementLibrary(path)
    return _LOADED[path]


def load_contact_library(cflags: str | None = None) -> ElementLibrary:
    """The contact library, compiled at first use (:func:`contact_library`) and loaded once per process."""
    path, _ = contact_library(cflags)
    if path not in _LOADED:
        _LOADED[path] = ElementLibrary(path, CONTACT_PACKAGE)
    return _LOADED[path]


class TableFunctions:
    """``Φ``, ``A``, ``Φ_t``, ``γ`` and ``M`` of one model from its tables, through the element
    library.  ``A(q)`` and ``M()`` return CSC nonzeros in the pattern of ``tables``
    (``tables.dense_A`` / ``dense_M`` expand them); outputs are fresh arrays.  Not thread-safe
    (one work array): one object per thread."""

    def __init__(self, tables: ModelTables, library: ElementLibrary | None = None):
        self.tables = tables
        self.library = library or load_element_library()
        missing = [f for t, f in TABLE_FIELDS if "*" in t and f not in tables.arrays]
        if missing:
            raise CodegenError(f"model {tables.name!r}: its element tables lack {', '.join(missing)}")
        self._arrays = {f: np.ascontiguousarray(tables.arrays[f], dtype=np.int32 if "int" in t else np.float64)
                        for t, f in TABLE_FIELDS if "*" in t}
        sizes = {"nq": tables.nq, "nc": tables.nc, "dim": tables.dim, "a_nnz": tables.a_nnz,
                 "m_nnz": tables.m_nnz, "nf": len(self._arrays["feat_ptr"]) - 1,
                 "ne": len(self._arrays["el_kind"]), "nm": len(self._arrays["mem_kind"])}
        self._struct = _Tables(**sizes, **{k: v.ctypes.data for k, v in self._arrays.items()})
        self._ref = ctypes.addressof(self._struct)
        if self.library.fn["check"](self._ref):
            raise CodegenError(f"model {tables.name!r}: its element tables are inconsistent (ncgen_tables_check)")
        self._work = np.zeros(max(1, int(self.library.fn["work_size"](self._ref))))

    def _q(self, q, what: str = "q") -> np.ndarray:
        q = np.ascontiguousarray(q, dtype=float).reshape(-1)
        if q.size != self.tables.nq:
            raise ShapeError(f"{what}: expected {self.tables.nq} values (one per natural coordinate) of model "
                             f"{self.tables.name!r}, got {q.size}")
        return q

    def _call(self, name: str, *args) -> None:
        status = self.library.fn[name](self._ref, *args)
        if status:
            raise CodegenError(f"model {self.tables.name!r}: the element library's {name} failed (status {status})")

    def phi(self, q) -> np.ndarray:
        q, out = self._q(q), np.zeros(self.tables.nc)
        self._call("phi", q.ctypes.data, out.ctypes.data, self._work.ctypes.data)
        return out

    def A(self, q) -> np.ndarray:
        q, out = self._q(q), np.zeros(self.tables.a_nnz)
        self._call("jacobian", q.ctypes.data, out.ctypes.data, self._work.ctypes.data)
        return out

    def phi_t(self) -> np.ndarray:
        out = np.zeros(self.tables.nc)
        self._call("phi_t", out.ctypes.data)
        return out

    def gamma(self, q, v) -> np.ndarray:
        """``γ = −[vᵀ H_r v]_r`` (``A q̈ = γ``; every covered element is scleronomic)."""
        q, v, out = self._q(q), self._q(v, "v"), np.zeros(self.tables.nc)
        self._call("gamma", q.ctypes.data, v.ctypes.data, out.ctypes.data, self._work.ctypes.data)
        return out

    def M(self) -> np.ndarray:
        out = np.zeros(self.tables.m_nnz)
        self._call("mass", out.ctypes.data, self._work.ctypes.data)
        return out


def table_functions(model, library: ElementLibrary | None = None) -> TableFunctions:
    """The table-driven functions of ``model`` (packs its tables; raises
    :class:`~ncgen.codegen.model_tables.UnsupportedElements` for kinds not covered)."""
    from ncgen.codegen.model_tables import model_tables

    return TableFunctions(model_tables(model), library)
