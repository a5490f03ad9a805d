"""Direct calls of compiled CasADi functions through ctypes, with preallocated buffers.

``casadi.external`` costs ~15–20 µs per call from Python, more than a small kernel.
:class:`DirectFunction` calls the generated C entry point itself::

    int <fn>(const casadi_real** arg, casadi_real** res, casadi_int* iw, casadi_real* w, int mem)

with the pointer tables, integer and real work arrays allocated once (sizes from
``<fn>_work``) and one NumPy buffer per input and output (their nonzeros, CasADi's
column-major order).  A call copies the inputs into their buffers, calls the kernel and
returns the output buffers (overwritten by the next call; copy them to keep them).  The
overhead is ~1–2 µs (measured in benchmarks/joint_space.py).  Not thread-safe: one object
per thread.
"""
from __future__ import annotations

import ctypes
import weakref
from pathlib import Path

import casadi as ca
import numpy as np

from ncgen.codegen.c_binding import open_library
from ncgen.codegen.casadi_abi import bind_casadi, work_sizes
from ncgen.errors import CodegenError, ShapeError
from ncgen.validation import as_numbers

_REAL_P = ctypes.POINTER(ctypes.c_double)
#: Arguments that hold raw bytes, never read as numbers (NumPy would read a bytearray's bytes).
RAW_BYTES = (bytes, bytearray, memoryview)


class DirectFunction:
    """The compiled function ``c_name`` of ``library`` with the signature of ``f`` (the
    CasADi function it was generated from: input and output sparsities, names)."""

    def __init__(self, library, c_name: str, f: ca.Function):
        self.library = Path(library)
        self.name, self.c_name, self.function = f.name(), c_name, f
        self._lib = open_library(self.library)
        abi = bind_casadi(self._lib, c_name)
        sz_arg, sz_res, sz_iw, sz_w = work_sizes(abi, c_name)
        self.inputs = [np.zeros(f.nnz_in(i)) for i in range(f.n_in())]
        self.outputs = [np.zeros(f.nnz_out(i)) for i in range(f.n_out())]
        self.input_names, self.output_names = f.name_in(), f.name_out()
        self._arg = (_REAL_P * sz_arg)(*[b.ctypes.data_as(_REAL_P) for b in self.inputs])
        self._res = (_REAL_P * sz_res)(*[b.ctypes.data_as(_REAL_P) for b in self.outputs])
        self._iw = np.zeros(sz_iw, dtype=np.int64)
        self._w = np.zeros(sz_w)
        if abi.incref is not None:
            abi.incref()
        self._mem = 0 if abi.checkout is None else int(abi.checkout())
        if self._mem < 0:
            raise CodegenError(f"{c_name}: no free memory slot in {self.library.name} (its C has "
                               "CASADI_MAX_NUM_THREADS of them, each held by a live caller)")
        if abi.checkout is not None and abi.release is not None:     # the slot back when this object goes
            weakref.finalize(self, abi.release, self._mem).atexit = False
        self._fn = abi.eval
        self._args = (ctypes.addressof(self._arg), ctypes.addressof(self._res), self._iw.ctypes.data,
                      self._w.ctypes.data, self._mem)

    def copy(self) -> "DirectFunction":
        """The same compiled function with buffers and work arrays of its own."""
        return DirectFunction(self.library, self.c_name, self.function)

    def call(self) -> list[np.ndarray]:
        """Evaluate with the values already in :attr:`inputs`; returns :attr:`outputs`."""
        if self._fn(*self._args):
            raise CodegenError(f"{self.name}: the compiled kernel returned an error")
        return self.outputs

    def status_call(self, *args) -> int:
        """As :meth:`__call__`, but return the kernel's status (0: success) instead of raising:
        for solvers whose outputs are meaningful after a non-zero status (a QP solver's last
        iterate); the outputs are in :attr:`outputs`."""
        for buf, x in zip(self.inputs, args):
            buf[:] = x
        return int(self._fn(*self._args))

    def __call__(self, *args) -> list[np.ndarray]:
        """Copy ``args`` (one array per input, its nonzeros) into the buffers and evaluate.
        Raises :class:`~ncgen.errors.ShapeError` naming the input for a wrong number of
        arguments or a wrong size (no broadcasting).  Values are not tested for finiteness
        nor for being real on this path (the tests would cost as much as the call: a NaN in
        gives NaN out, a complex array loses its imaginary part as NumPy casts it);
        :meth:`checked` does both."""
        if len(args) != len(self.inputs):
            raise ShapeError(f"{self.name}: expected {len(self.inputs)} arguments "
                             f"({', '.join(self.input_names)}), got {len(args)}")
        try:
            for buf, x in zip(self.inputs, args):
                if isinstance(x, RAW_BYTES):  # NumPy would read a bytearray's bytes as numbers
                    raise ValueError
                buf[:] = x
                if len(x) != buf.size:       # a length-1 argument would broadcast
                    raise ValueError
        except (ValueError, TypeError):      # scalars, nested lists, wrong sizes: the careful way
            self._copy_checked(args)
        if self._fn(*self._args):
            raise CodegenError(f"{self.name}: the compiled kernel returned an error")
        return self.outputs

    def checked(self, *args) -> list[np.ndarray]:
        """As calling the object, with every argument also tested for finite values."""
        if len(args) != len(self.inputs):
            raise ShapeError(f"{self.name}: expected {len(self.inputs)} arguments "
                             f"({', '.join(self.input_names)}), got {len(args)}")
        self._copy_checked(args)
        return self.call()

    def _copy_checked(self, args):
        """Copy ``args`` into the buffers, raising for the first of a wrong size or with a
        non-finite value."""
        for name, buf, x in zip(self.input_names, self.inputs, args):
            a = as_numbers(x, f"{self.name}: argument {name!r}", f"{buf.size} numbers").ravel()
            if a.size != buf.size:
                raise ShapeError(f"{self.name}: argument {name!r}: expected {buf.size} values, got {a.size} "
                                 f"(shape {np.shape(x)})")
            bad = np.flatnonzero(~np.isfinite(a))
            if bad.size:
                raise ShapeError(f"{self.name}: argument {name!r}: expected finite numbers, found "
                                 f"{a[bad[0]]} at index {int(bad[0])}")
            buf[:] = a


def compile_functions(name: str, functions: list, cflags: str | tuple[str, ...] | None = None,
                      **package_options) -> dict[str, DirectFunction]:
    """``functions`` generated as the C package ``name`` (``package_options``: those of
    :func:`~ncgen.codegen.package.write_package`), compiled with ``cflags`` (None: the
    defaults of :func:`~ncgen.codegen.compile_cache.compile_package`; the library is cached by
    content) and loaded for direct calls: ``{function name: DirectFunction}``.  The one helper
    that compiles CasADi functions for calls from Python."""
    import tempfile

    from ncgen.codegen.compile_cache import compile_package
    from ncgen.codegen.package import write_package

    with tempfile.TemporaryDirectory() as tmp:
        pkg = write_package(name, functions, Path(tmp) / "pkg", **package_options)
        built = compile_package(pkg, cflags=cflags)
        names = {f.name(): pkg.c_name(f.name()) for f in functions}
    return {f.name(): DirectFunction(built.path, names[f.name()], f) for f in functions}


def compile_direct(name: str, f: ca.Function, cflags: str | None = None) -> DirectFunction:
    """``f`` alone as the C package ``name``, compiled and loaded (:func:`compile_functions`)."""
    return compile_functions(name, [f], cflags)[f.name()]
