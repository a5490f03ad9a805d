"""A CPython extension that calls a compiled kernel with NumPy arrays in ~0.3 µs (ctypes:
~1 µs plus ~0.3 µs per copied input), built once per Python version and compiler, cached.

:func:`fast_caller` returns ``caller(*arrays)``: copies each array's values into the
kernel's input buffer (checked length; float64 contiguous arrays by ``memcpy``, other
sequences element by element; ``bytes``, ``bytearray`` and byte memoryviews refused, not
read as numbers), calls the kernel's C entry point with the work arrays of a
:class:`~ncgen.codegen.direct.DirectFunction` and returns the object given at construction
(its output buffers), or None when an optional check fails: ``check[0] > tol`` and
``check[1]`` finite (the tree kernels' pivot and sum).  With ``bound > 0`` every input value
must be finite and of magnitude at most ``bound`` (checked while copying, a few ns a value),
an array one-dimensional and a sequence's items Python floats or ints (not booleans); a
TypeError or ValueError otherwise, so that the caller builds its detailed message only then.
It is an accelerator only: when the Python headers or a compiler are missing, :func:`fast_caller`
returns None and callers keep the ctypes path.
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import subprocess
import sys
import sysconfig
from pathlib import Path

SOURCE = r"""
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>

typedef int (*kernel_fn)(const double**, double**, long long*, double*, int);
#define MAX_IN 8

typedef struct {
    PyObject_HEAD
    vectorcallfunc vectorcall;
    kernel_fn fn;
    const double **arg; double **res; long long *iw; double *w; int mem;
    int n_in;
    double *buf[MAX_IN];
    Py_ssize_t size[MAX_IN];
    const double *check; double tol; double bound;
    PyObject *result; PyObject *keep;
} Caller;

static int raw_bytes(PyObject *x) {
    if (PyBytes_Check(x) || PyByteArray_Check(x)) return 1;
    if (!PyMemoryView_Check(x)) return 0;
    const char *f = PyMemoryView_GET_BUFFER(x)->format;
    return !f || ((f[0] == 'B' || f[0] == 'b' || f[0] == 'c') && f[1] == 0);
}

static int check_bound(const double *x, Py_ssize_t n, double bound, int k) {
    for (Py_ssize_t i = 0; i < n; i++)
        if (!(fabs(x[i]) <= bound)) {
            PyErr_Format(PyExc_ValueError, "argument %d: value %zd is not finite or too large", k, i);
            return -1;
        }
    return 0;
}

static int copy_in(double *dst, Py_ssize_t n, PyObject *x, int k, double bound) {
    Py_buffer view;
    if (raw_bytes(x)) {
        PyErr_Format(PyExc_TypeError, "argument %d: expected numbers, got %s (raw bytes are not read as numbers)",
                     k, Py_TYPE(x)->tp_name);
        return -1;
    }
    if (PyObject_GetBuffer(x, &view, PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) == 0) {
        int ok = view.itemsize == 8 && view.format && view.format[0] == 'd' && view.format[1] == 0;
        if (ok && view.len == n * 8 && (bound <= 0 || view.ndim == 1)) {
            memcpy(dst, view.buf, (size_t)view.len); PyBuffer_Release(&view);
            return bound > 0 ? check_bound(dst, n, bound, k) : 0;
        }
        const char *f = view.format ? view.format : "";
        while (*f && strchr("@=<>!", *f)) f++;
        int not_real = *f == 'Z' || *f == '?';          /* complex, bool: not read as real numbers */
        PyBuffer_Release(&view);
        if (ok) { PyErr_Format(PyExc_ValueError, "argument %d: expected %zd values, got %zd", k, n, view.len / 8); return -1; }
        if (not_real) { PyErr_Format(PyExc_ValueError, "argument %d: expected real numbers", k); return -1; }
    } else PyErr_Clear();
    PyObject *seq = PySequence_Fast(x, "expected a sequence of numbers");
    if (!seq) return -1;
    if (PySequence_Fast_GET_SIZE(seq) != n) {
        PyErr_Format(PyExc_ValueError, "argument %d: expected %zd values, got %zd", k, n, PySequence_Fast_GET_SIZE(seq));
        Py_DECREF(seq); return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *item = PySequence_Fast_GET_ITEM(seq, i);
        if (bound > 0 && !(PyFloat_Check(item) || (PyLong_Check(item) && !PyBool_Check(item)))) {
            PyErr_Format(PyExc_TypeError, "argument %d: value %zd is not a float or an int", k, i);
            Py_DECREF(seq); return -1;
        }
        double v = PyFloat_AsDouble(item);
        if (v == -1.0 && PyErr_Occurred()) { Py_DECREF(seq); return -1; }
        dst[i] = v;
    }
    Py_DECREF(seq);
    return bound > 0 ? check_bound(dst, n, bound, k) : 0;
}

static PyObject *caller_call(PyObject *self_, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    Caller *self = (Caller *)self_;
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    if (kwnames || nargs != self->n_in) {
        PyErr_Format(PyExc_TypeError, "expected %d positional arguments, got %zd", self->n_in, nargs);
        return NULL;
    }
    for (int k = 0; k < self->n_in; k++)
        if (copy_in(self->buf[k], self->size[k], args[k], k, self->bound)) return NULL;
    if (self->fn(self->arg, self->res, self->iw, self->w, self->mem)) {
        PyErr_SetString(PyExc_RuntimeError, "the compiled kernel returned an error");
        return NULL;
    }
    if (self->check && !(self->check[0] > self->tol && isfinite(self->check[1]))) Py_RETURN_NONE;
    Py_INCREF(self->result);
    return self->result;
}

static PyObject *caller_new(PyTypeObject *type, PyObject *a, PyObject *kw) {
    unsigned long long fn, arg, res, iw, w, check; int mem; double tol, bound;
    (void)kw;
    PyObject *bufs, *sizes, *result, *keep;
    if (!PyArg_ParseTuple(a, "KKKKKiOOKddOO", &fn, &arg, &res, &iw, &w, &mem, &bufs, &sizes, &check, &tol, &bound,
                          &result, &keep))
        return NULL;
    Py_ssize_t n = PySequence_Size(bufs);
    if (n < 0 || n > MAX_IN || PySequence_Size(sizes) != n) {
        PyErr_SetString(PyExc_ValueError, "bad buffer lists"); return NULL;
    }
    Caller *self = (Caller *)type->tp_alloc(type, 0);
    if (!self) return NULL;
    self->vectorcall = caller_call;
    self->fn = (kernel_fn)(uintptr_t)fn; self->arg = (const double **)(uintptr_t)arg; self->res = (double **)(uintptr_t)res;
    self->iw = (long long *)(uintptr_t)iw; self->w = (double *)(uintptr_t)w; self->mem = mem; self->n_in = (int)n;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *b = PySequence_GetItem(bufs, i), *s = PySequence_GetItem(sizes, i);
        self->buf[i] = (double *)(uintptr_t)PyLong_AsUnsignedLongLong(b);
        self->size[i] = PyLong_AsSsize_t(s);
        Py_XDECREF(b); Py_XDECREF(s);
    }
    self->check = (const double *)(uintptr_t)check; self->tol = tol; self->bound = bound;
    Py_INCREF(result); self->result = result; Py_INCREF(keep); self->keep = keep;
    if (PyErr_Occurred()) { Py_DECREF(self); return NULL; }
    return (PyObject *)self;
}

static void caller_dealloc(Caller *self) {
    Py_XDECREF(self->result); Py_XDECREF(self->keep);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

static PyTypeObject CallerType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "ncgen_fast_call.Caller",
    .tp_basicsize = sizeof(Caller),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_VECTORCALL,
    .tp_vectorcall_offset = offsetof(Caller, vectorcall),
    .tp_call = PyVectorcall_Call,
    .tp_new = caller_new,
    .tp_dealloc = (destructor)caller_dealloc,
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "ncgen_fast_call", NULL, -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit_ncgen_fast_call(void) {
    if (PyType_Ready(&CallerType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    Py_INCREF(&CallerType);
    PyModule_AddObject(m, "Caller", (PyObject *)&CallerType);
    return m;
}
"""

_MODULE: list = []


def _module():
    """The extension module (built on first use into the compile cache), or None."""
    if _MODULE:
        return _MODULE[0]
    _MODULE.append(None)
    if os.environ.get("NCGEN_FAST_CALL", "1") == "0":
        return None
    try:
        from ncgen.codegen import fsutil
        from ncgen.codegen.compile_cache import cache_dir
        from ncgen.codegen.compiler import find_compiler

        include = sysconfig.get_paths()["include"]
        if not (Path(include) / "Python.h").exists():
            return None
        compiler = find_compiler()
        suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
        key = hashlib.sha256("\n".join([SOURCE, sys.version, compiler.version, include]).encode()).hexdigest()[:24]
        entry = cache_dir() / f"fast_call-{key}"
        library = entry / f"ncgen_fast_call{suffix}"
        if not library.exists():
            entry.parent.mkdir(parents=True, exist_ok=True)
            with fsutil.locked(entry.parent / f".{entry.name}.lock"):
                if not library.exists():
                    with fsutil.temporary_sibling(entry) as tmp:
                        (tmp / "fast_call.c").write_text(SOURCE)
                        subprocess.run([*compiler.argv, "-O2", "-Wall", "-Wextra", "-Werror", "-shared", "-fPIC",
                                        f"-I{include}", "-o",
                                        str(tmp / library.name), str(tmp / "fast_call.c")],
                                       check=True, capture_output=True)
                        os.replace(tmp, entry)
        spec = importlib.util.spec_from_file_location("ncgen_fast_call", library)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        _MODULE[0] = mod
    except Exception:                      # an accelerator: any failure keeps the ctypes path
        _MODULE[0] = None
    return _MODULE[0]


def fast_caller(direct, n_inputs: int, first: int = 0, check=None, tol: float = 0.0, result=None,
                bound: float = 0.0):
    """``caller(*arrays)`` for the inputs ``first .. first + n_inputs − 1`` of the
    :class:`~ncgen.codegen.direct.DirectFunction` ``direct`` (module docstring; ``check``: a
    2-entry output buffer, ``result``: what a call returns, ``bound``: the largest magnitude of
    an input value, 0 for no check), or None without the extension."""
    mod = _module()
    if mod is None:
        return None
    bufs = direct.inputs[first:first + n_inputs]
    fn, arg, res, iw, w, mem = direct._fn, *direct._args
    import ctypes
    address = ctypes.cast(fn, ctypes.c_void_p).value
    return mod.Caller(address, arg, res, iw, w, mem, [b.ctypes.data for b in bufs], [b.size for b in bufs],
                      0 if check is None else check.ctypes.data, float(tol), float(bound), result,
                      (direct, bufs, check))
