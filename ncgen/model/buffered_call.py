"""CasADi functions called through preallocated buffers (``casadi.Function.buffer``): about
5 µs a call of a small function on the virtual machine, where ``f(*args)`` with NumPy
arguments costs 50–150 µs (the conversions to and from ``DM``).  For the per-call work in
front of the compiled loops (a run's initial-state checks and joint coordinates).

Buffers are per thread (one evaluation at a time each); outputs are returned as fresh dense
arrays, so callers may keep them."""
from __future__ import annotations

import threading
from typing import Callable

import casadi as ca
import numpy as np

from ncgen.model.data import model_data


class BufferedFunction:
    """``f`` (dense column-vector or scalar inputs) evaluated into NumPy arrays:
    ``call(*args)`` → the outputs."""

    def __init__(self, f: ca.Function):
        for i in range(f.n_in()):
            if not (f.sparsity_in(i).is_dense() and f.size2_in(i) == 1):
                raise ValueError(f"BufferedFunction: input {f.name_in(i)!r} of {f.name()} is not a dense vector")
        self.f = f
        self._outputs = []
        for i in range(f.n_out()):
            sp = f.sparsity_out(i)
            rows, cols = sp.get_triplet()
            self._outputs.append(((sp.size1(),) if sp.size2() == 1 else (sp.size1(), sp.size2()), sp.is_dense(),
                                  (np.array(rows, dtype=np.intp),) if sp.size2() == 1 else
                                  (np.array(rows, dtype=np.intp), np.array(cols, dtype=np.intp))))
        self._local = threading.local()

    def _buffers(self):
        b = getattr(self._local, "buffers", None)
        if b is None:
            buf, evaluate = self.f.buffer()
            ins = [np.zeros(self.f.nnz_in(i)) for i in range(self.f.n_in())]
            outs = [np.zeros(self.f.nnz_out(i)) for i in range(self.f.n_out())]
            for i, x in enumerate(ins):
                buf.set_arg(i, memoryview(x))
            for i, x in enumerate(outs):
                buf.set_res(i, memoryview(x))
            b = self._local.buffers = (buf, evaluate, ins, outs)
        return b

    def call(self, *args) -> tuple[np.ndarray, ...]:
        """The outputs of ``f(*args)`` (each argument a scalar or a 1-D array of the input's
        size), dense: an output of one column 1-D, others 2-D."""
        buf, evaluate, ins, outs = self._buffers()
        for x, a in zip(ins, args):
            x[...] = a
        evaluate()
        if buf.ret():
            raise RuntimeError(f"{self.f.name()}: evaluation failed (status {buf.ret()})")
        result = []
        for (shape, dense, index), nz in zip(self._outputs, outs):
            if dense:
                result.append(nz.copy() if len(shape) == 1 else nz.reshape(shape, order="F").copy())
            else:
                y = np.zeros(shape)
                y[index] = nz
                result.append(y)
        return tuple(result)


def buffered(model, key: str, make: Callable[[], ca.Function] | None = None) -> BufferedFunction:
    """The :class:`BufferedFunction` of ``model.functions[key]`` (or of the function ``make()``
    builds, kept under ``key``), built once per model (``model.data``)."""
    slot = model_data(model).buffered
    hit = slot.get(key)
    if hit is None:
        hit = slot[key] = BufferedFunction(model.functions[key] if make is None else make())
    return hit
