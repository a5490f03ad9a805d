"""One rule for the BLAS threads of ncgen's own dense algebra: one thread.

ncgen's dense solves are small (tens to a few hundred unknowns) and run in loops (a QP's
iterations, an MPC's steps, MUMPS's fronts inside IPOPT); an OpenBLAS thread pool makes
them slower, and on a shared or loaded machine its threads wait for a core and multiply the
wall time (inverse statics 1.65 s wall for 0.23 s of CPU, IPOPT/MUMPS 82 s instead of 26 s).
So the public entry points that run such loops are decorated with :func:`one_blas_thread`
(:func:`blas_limit` as a ``with`` block):
inside them every BLAS that threadpoolctl controls (NumPy's and SciPy's OpenBLAS, and the
OpenBLAS that CasADi's IPOPT and MUMPS use) runs on ``$NCGEN_BLAS_THREADS`` threads
(default 1; ``0`` leaves the BLAS as it is), and the caller's setting is restored on the way
out, so the user's own algebra outside ncgen keeps its threads.  Nested entries cost nothing;
OpenBLAS's limit is process-wide, so Python threads running ncgen at once share it.
"""
from __future__ import annotations

import functools
import os
import sys
import threading
from contextlib import contextmanager

from ncgen.errors import NcgenError

ENV = "NCGEN_BLAS_THREADS"
CASADI_OPENBLAS = "libcasadi-tp-openblas"       # the OpenBLAS of CasADi's plugins (IPOPT, MUMPS)

_depth = threading.local()
_cache: dict = {}


def blas_threads() -> int:
    """``$NCGEN_BLAS_THREADS`` as a count of threads (default 1; 0: leave the BLAS alone)."""
    text = os.environ.get(ENV, "1").strip()
    if not text.isdigit():
        raise NcgenError(f"{ENV}: expected a whole number of threads (0: leave the BLAS alone), got {text!r}")
    return int(text)


@contextmanager
def blas_limit():
    """``with blas_limit():`` the BLAS libraries loaded in this process run on
    :func:`blas_threads` threads, each set back to its own count on leaving (module docstring)."""
    depth = getattr(_depth, "n", 0)
    threads = blas_threads() if depth == 0 else 0
    libraries = blas_libraries() if threads else []
    before = [lib.get_num_threads() for lib in libraries]
    for lib in libraries:
        lib.set_num_threads(threads)
    _depth.n = depth + 1
    try:
        yield
    finally:
        _depth.n = depth
        for lib, n in zip(libraries, before):
            lib.set_num_threads(n)


def one_blas_thread(fn):
    """Decorate an entry point of ncgen's dense algebra: its body runs in :func:`blas_limit`."""
    @functools.wraps(fn)
    def limited(*args, **kwargs):
        with blas_limit():
            return fn(*args, **kwargs)
    limited.blas_limit = True
    return limited


def blas_libraries() -> list:
    """threadpoolctl's controllers of the BLAS libraries loaded now, found again only when a
    module was imported since (finding them reads every loaded library: about 5 ms).  With CasADi
    imported, its OpenBLAS is loaded first (the file its IPOPT and MUMPS plugins load), so that
    it is limited from the first solve on."""
    key = len(sys.modules)
    if _cache.get("key") != key:
        import threadpoolctl
        _register_casadi_openblas(threadpoolctl)
        _load_casadi_openblas()
        found = threadpoolctl.ThreadpoolController().select(user_api="blas").lib_controllers
        _cache.update(key=key, libraries=found)
    return _cache["libraries"]


def _load_casadi_openblas() -> None:
    casadi = sys.modules.get("casadi")
    if casadi is None or _cache.get("casadi_openblas"):
        return
    import ctypes
    path = os.path.join(os.path.dirname(casadi.__file__), CASADI_OPENBLAS + ".so.0")   # its soname
    if os.path.exists(path):
        _cache["casadi_openblas"] = ctypes.CDLL(path)


def _register_casadi_openblas(threadpoolctl) -> None:
    """Teach threadpoolctl CasADi's OpenBLAS (its file name has no prefix threadpoolctl knows)."""
    if _cache.get("registered"):
        return

    class CasadiOpenBLAS(threadpoolctl.LibController):
        user_api, internal_api, filename_prefixes = "blas", "openblas", (CASADI_OPENBLAS,)
        check_symbols = ("openblas_get_num_threads", "openblas_set_num_threads")

        def get_num_threads(self):
            return self.dynlib.openblas_get_num_threads()

        def set_num_threads(self, num_threads):
            self.dynlib.openblas_set_num_threads(num_threads)

        def get_version(self):
            import ctypes
            get_config = self.dynlib.openblas_get_config
            get_config.restype = ctypes.c_char_p
            return get_config().decode().split()[1]

    threadpoolctl.register(CasadiOpenBLAS)
    _cache["registered"] = True
