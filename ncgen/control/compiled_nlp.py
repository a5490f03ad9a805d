"""Fatrop's whole solver as compiled C called directly (:func:`compiled_fatrop`).

CasADi generates Fatrop's solver as C (the problem's functions and the calls of Fatrop's C
interface, ``<fatrop/ocp/OCPCInterface.h>``); linked to the ``libfatrop`` and ``libblasfeo``
of the CasADi wheel, it is called through ctypes (:class:`~ncgen.codegen.direct.DirectFunction`)
without CasADi's Python call, its conversions and ``stats()`` (0.2–0.3 ms a solve on the
cart-pole).  ncgen's packages prefix every symbol with the package's name and link no C++
library, so this one file is compiled here, cached in ``$NCGEN_CACHE_DIR`` under the hash of
its C, the compiler and the flags (those of the step packages: ``$NCGEN_CFLAGS`` if set, else ``-O1``,
straight-line code).  The
generated entry point returns 0 whatever Fatrop answered, so two lines are added to the
generated C (each anchor checked to occur once): a failed solve returns 1, a successful one
``−(its interior-point iterations)``.
"""
from __future__ import annotations

import os
import subprocess
import tempfile
from pathlib import Path

import casadi as ca

from ncgen.codegen import fsutil
from ncgen.codegen.compile_cache import resolve_cflags
from ncgen.codegen.compiler import find_compiler
from ncgen.control.step_support import compile_flags
from ncgen.errors import CodegenError
from ncgen.files import cache_dir

#: Memory slots of a compiled solver (CasADi's generated code has one by default): solvers of
#: the same problem alive at a time in one process (a slot is given back when its solver goes).
SLOTS = 8
#: The generated Fatrop solver's lines after which the status is returned, and its last lines.
SOLVED, END = "  casadi_fatrop_solve(d);\n", "  return 0;\n  return 0;\n}\n"


def fatrop_c(name: str, nlp: dict, options: dict) -> tuple[ca.Function, str]:
    """``(solver, C)``: ``casadi.nlpsol(name, "fatrop", nlp, options)`` and its generated C
    (entry point ``name``; no header), with the two lines that return the status added
    (module docstring), each anchor checked to occur once, else :class:`CodegenError`."""
    solver = ca.nlpsol(name, "fatrop", nlp, options)
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        cg.add(solver)
        cg.generate(tmp + os.sep)
        text = (Path(tmp) / f"{name}.c").read_text()
    if text.count(SOLVED) != 1 or text.count(END) != 1:
        raise CodegenError(f"{name}: CasADi {ca.__version__}'s generated Fatrop solver has not the expected "
                           f"shape (once each: {SOLVED!r}, {END!r}); its status cannot be returned")
    return solver, (text.replace(SOLVED, SOLVED + "  if (!d->success) return 1;\n")
                    .replace(END, "  return -(int) d->stats.iterations_count;\n}\n"))


def compiled_fatrop(name: str, nlp: dict, options: dict):
    """``casadi.nlpsol(name, "fatrop", nlp, options)`` as generated C (:func:`fatrop_c`),
    compiled (cached) and loaded: a :class:`~ncgen.codegen.direct.DirectFunction` whose
    :meth:`status_call` returns 1 for a failed solve, else ``−(interior-point iterations)``."""
    from ncgen.codegen.direct import DirectFunction
    solver, text = fatrop_c(name, nlp, options)
    casadi = Path(ca.__file__).parent
    with tempfile.TemporaryDirectory() as tmp:
        source = Path(tmp) / f"{name}.c"
        source.write_text(text)
        library = _library(name, source, (f"-I{casadi / 'include'}", f"-DCASADI_MAX_NUM_THREADS={SLOTS}"),
                           (f"-L{casadi}", "-lfatrop", "-lblasfeo", f"-Wl,-rpath,{casadi}"))
    return DirectFunction(library, name, solver)


def _library(name: str, source: Path, include: tuple = (), link: tuple = ()) -> Path:
    """The cached shared library of the C file ``source`` (built when missing), compiled with
    the ``include`` flags and linked with the ``link`` ones."""
    compiler, flags = find_compiler(), resolve_cflags(compile_flags())
    key = fsutil.sha256_bytes(source.read_bytes() + "\0".join((*compiler.argv, compiler.version,
                                                                *flags, *include, *link)).encode())
    root = cache_dir()
    entry = root / f"{name}-{key[:24]}"
    library = entry / f"lib{name}.so"
    if library.is_file():
        return library
    root.mkdir(parents=True, exist_ok=True)
    with fsutil.locked(root / f".{entry.name}.lock"):
        if library.is_file():                   # another process built it while we waited
            return library
        with fsutil.temporary_sibling(entry) as tmp:
            cmd = [*compiler.argv, *flags, *include, "-fPIC", "-shared", str(source), "-o",
                   str(tmp / library.name), *link, "-lm"]
            out = subprocess.run(cmd, capture_output=True, text=True)
            if out.returncode != 0:
                raise CodegenError(f"C compilation of the NLP functions of {name!r} failed (exit status "
                                   f"{out.returncode})\n{out.stderr[-2000:]}")
            os.rename(tmp, entry)
    return library
