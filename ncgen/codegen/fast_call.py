"""A CPython extension that calls a compiled kernel with NumPy arrays in ~0.3 µs (ctypes:
~1 µs plus ~0.3 µs per copied input), built once per Python version and compiler, cached.

:func:`fast_caller` returns ``caller(*arrays)``: copies each array's values into the
kernel's input buffer (checked length; float64 contiguous arrays by ``memcpy``, other
sequences element by element; ``bytes``, ``bytearray`` and byte memoryviews refused, not
read as numbers), calls the kernel's C entry point with the work arrays of a
:class:`~ncgen.codegen.direct.DirectFunction` and returns the object given at construction
(its output buffers), or None when an optional check fails: ``check[0] > tol`` and
``check[1]`` finite (the tree kernels' pivot and sum), or (``check="finite"``) a door's
outputs not all finite (a KKT solve's).  ``caller.batch(n, outs, *arrays)``
calls it on ``n`` rows of C-contiguous float64 arrays in one C loop (a door's quaternions
normalised row by row), writing the first
``len(outs)`` outputs to the rows of ``outs`` (the first row whose check fails returned, or
None).  With ``bound > 0`` every input value
must be finite and of magnitude at most ``bound`` (checked while copying, a few ns a value),
an array one-dimensional and a sequence's items Python floats or ints (not booleans); a
TypeError or ValueError otherwise, so that the caller builds its detailed message only then.
A door (``outputs=``) returns fresh NumPy arrays of the outputs or writes them into an
``out`` argument, and can normalise the quaternions of its first input: the whole of
``nc.rnea`` and its siblings in one C call (:class:`~ncgen.runtime.tree_algorithm_kernels.Door`).
It is an accelerator only: when the Python or NumPy headers or a compiler are missing,
:func:`fast_caller` returns None and callers keep the ctypes path.
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
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <string.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>

typedef int (*kernel_fn)(const double**, double**, long long*, double*, int);
#define MAX_IN 8
#define MAX_QUAT 64

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
    int n_out;                                  /* > 0: fresh outputs (or `out` written) each call */
    double *obuf[MAX_IN];
    Py_ssize_t rows[MAX_IN], cols[MAX_IN];      /* cols 0: a vector of rows values */
    int n_quat;
    Py_ssize_t quat[MAX_QUAT];                  /* offsets of [qx, qy, qz, qw] in the first input */
    int finite;                                 /* 1: a door's outputs must be finite (else None) */
} Caller;

static int raw_bytes(PyObject *x) {
    if (PyBytes_Check(x) || PyByteArray_Check(x)) return 1;
    if (!PyMemoryView_Check(x)) return 0;
    const char *f = PyMemoryView_GET_BUFFER(x)->format;
    return !f || ((f[0] == 'B' || f[0] == 'b' || f[0] == 'c') && f[1] == 0);
}

static int check_bound(const double *x, Py_ssize_t n, double bound, int k) {
    long bad = 0;                               /* no early exit: the loop vectorises (-O3) */
    for (Py_ssize_t i = 0; i < n; i++) bad += !(fabs(x[i]) <= bound);
    if (!bad) return 0;
    for (Py_ssize_t i = 0; i < n; i++)
        if (!(fabs(x[i]) <= bound)) {
            PyErr_Format(PyExc_ValueError, "argument %d: value %zd is not finite or too large", k, i);
            return -1;
        }
    return 0;
}

static int copy_in(double *dst, Py_ssize_t n, PyObject *x, int k, double bound) {
    Py_buffer view;
    if (PyArray_Check(x)) {                     /* the common case without the buffer protocol's format string */
        PyArrayObject *a = (PyArrayObject *)x;
        if (PyArray_TYPE(a) == NPY_DOUBLE && PyArray_ISNOTSWAPPED(a) && PyArray_IS_C_CONTIGUOUS(a)
            && PyArray_SIZE(a) == n && (bound <= 0 || PyArray_NDIM(a) == 1)) {
            memcpy(dst, PyArray_DATA(a), (size_t)n * 8);
            return bound > 0 ? check_bound(dst, n, bound, k) : 0;
        }
    }
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

/* The quaternions of the first input normalised, qw >= 0 (as numpy's x / |x| * sign). */
static int unit_quaternions(Caller *self) {
    for (int i = 0; i < self->n_quat; i++) {
        double *x = self->buf[0] + self->quat[i];
        double n = sqrt(x[0] * x[0] + x[1] * x[1] + x[2] * x[2] + x[3] * x[3]);
        if (!(n > 0)) {
            PyErr_Format(PyExc_ValueError, "argument 0: the quaternion at %zd is zero", self->quat[i]);
            return -1;
        }
        int flip = !(x[3] >= 0);
        for (int k = 0; k < 4; k++) { x[k] = x[k] / n; if (flip) x[k] = -x[k]; }
    }
    return 0;
}

/* Whether every value of a door's outputs is finite (no early exit: the sum vectorises). */
static int outputs_finite(const Caller *self) {
    for (int j = 0; j < self->n_out; j++) {
        Py_ssize_t m = self->rows[j] * (self->cols[j] ? self->cols[j] : 1);
        double sum = 0.0;
        for (Py_ssize_t i = 0; i < m; i++) sum += self->obuf[j][i] * 0.0;
        if (sum != 0.0) return 0;
    }
    return 1;
}

/* Output j as row-major values (matrices are stored column-major by the kernels). */
static void write_output(const Caller *self, int j, double *dst) {
    Py_ssize_t r = self->rows[j], c = self->cols[j];
    const double *src = self->obuf[j];
    if (!c) { memcpy(dst, src, (size_t)r * 8); return; }
    for (Py_ssize_t i = 0; i < r; i++)
        for (Py_ssize_t k = 0; k < c; k++) dst[i * c + k] = src[k * r + i];
}

/* Whether x is a writable, aligned, C-contiguous native float64 array of output j's shape. */
static int output_fits(const Caller *self, int j, PyObject *x) {
    if (!PyArray_Check(x)) return 0;
    PyArrayObject *a = (PyArrayObject *)x;
    int nd = self->cols[j] ? 2 : 1;
    return PyArray_TYPE(a) == NPY_DOUBLE && PyArray_ISCARRAY(a) && PyArray_ISNOTSWAPPED(a) && PyArray_NDIM(a) == nd
           && PyArray_DIM(a, 0) == self->rows[j] && (nd == 1 || PyArray_DIM(a, 1) == self->cols[j]);
}

static PyObject *new_output(const Caller *self, int j) {
    npy_intp dims[2] = {self->rows[j], self->cols[j]};
    PyObject *a = PyArray_SimpleNew(self->cols[j] ? 2 : 1, dims, NPY_DOUBLE);
    if (a) write_output(self, j, (double *)PyArray_DATA((PyArrayObject *)a));
    return a;
}

/* The outputs as fresh arrays (a tuple for several), or written into `out` (an array, or a
   tuple of arrays for several outputs) and `out` returned. */
static PyObject *outputs(const Caller *self, PyObject *out) {
    if (out) {
        for (int j = 0; j < self->n_out; j++)
            write_output(self, j, (double *)PyArray_DATA((PyArrayObject *)(
                self->n_out == 1 ? out : PyTuple_GET_ITEM(out, j))));
        Py_INCREF(out);
        return out;
    }
    if (self->n_out == 1) return new_output(self, 0);
    PyObject *t = PyTuple_New(self->n_out);
    if (!t) return NULL;
    for (int j = 0; j < self->n_out; j++) {
        PyObject *a = new_output(self, j);
        if (!a) { Py_DECREF(t); return NULL; }
        PyTuple_SET_ITEM(t, j, a);
    }
    return t;
}

static int out_fits(const Caller *self, PyObject *out) {
    if (self->n_out == 1) return output_fits(self, 0, out);
    if (!PyTuple_Check(out) || PyTuple_GET_SIZE(out) != self->n_out) return 0;
    for (int j = 0; j < self->n_out; j++)
        if (!output_fits(self, j, PyTuple_GET_ITEM(out, j))) return 0;
    return 1;
}

static PyObject *caller_call(PyObject *self_, PyObject *const *args, size_t nargsf, PyObject *kwnames) {
    Caller *self = (Caller *)self_;
    Py_ssize_t nargs = PyVectorcall_NARGS(nargsf);
    PyObject *out = NULL;
    if (kwnames || !(nargs == self->n_in || (self->n_out && nargs == self->n_in + 1))) {
        PyErr_Format(PyExc_TypeError, "expected %d positional arguments, got %zd", self->n_in, nargs);
        return NULL;
    }
    if (nargs > self->n_in && args[self->n_in] != Py_None) {
        out = args[self->n_in];
        if (!out_fits(self, out)) {
            PyErr_SetString(PyExc_ValueError, "out: not float64 C-contiguous writable arrays of the outputs' shapes");
            return NULL;
        }
    }
    for (int k = 0; k < self->n_in; k++)
        if (copy_in(self->buf[k], self->size[k], args[k], k, self->bound)) return NULL;
    if (self->n_quat && unit_quaternions(self)) return NULL;
    if (self->fn(self->arg, self->res, self->iw, self->w, self->mem)) {
        PyErr_SetString(PyExc_RuntimeError, "the compiled kernel returned an error");
        return NULL;
    }
    if (self->check && !(self->check[0] > self->tol && isfinite(self->check[1]))) Py_RETURN_NONE;
    if (self->finite && !outputs_finite(self)) Py_RETURN_NONE;
    if (self->n_out) return outputs(self, out);
    Py_INCREF(self->result);
    return self->result;
}

/* batch(n, outs, in_0, ..., in_{n_in - 1}): the kernel on n rows: row i of in_k (C-contiguous
   float64, n x size_k) copied in (checked against the bound, the quaternions of a door's first
   input normalised), the first len(outs) outputs
   copied to row i of outs[j] (C-contiguous float64, n x m_j, m_j the output's size).  Returns
   None, or the first row whose check fails (nothing written from it on). */
static PyObject *caller_batch(PyObject *self_, PyObject *args) {
    Caller *self = (Caller *)self_;
    Py_ssize_t nargs = PyTuple_GET_SIZE(args), n, n_out, i;
    Py_buffer in[MAX_IN], out[MAX_IN];
    int n_in_got = 0, n_out_got = 0, k, j;
    PyObject *ret = NULL;
    if (nargs != 2 + self->n_in) {
        PyErr_Format(PyExc_TypeError, "batch: expected n, outs and %d arrays, got %zd arguments", self->n_in, nargs);
        return NULL;
    }
    n = PyLong_AsSsize_t(PyTuple_GET_ITEM(args, 0));
    if (n < 0) { if (!PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "batch: n < 0"); return NULL; }
    PyObject *outs = PySequence_Fast(PyTuple_GET_ITEM(args, 1), "batch: outs must be a sequence of arrays");
    if (!outs) return NULL;
    n_out = PySequence_Fast_GET_SIZE(outs);
    if (n_out > MAX_IN) { PyErr_SetString(PyExc_ValueError, "batch: too many outputs"); goto done; }
    for (k = 0; k < self->n_in; k++, n_in_got++) {
        if (PyObject_GetBuffer(PyTuple_GET_ITEM(args, 2 + k), &in[k], PyBUF_C_CONTIGUOUS | PyBUF_FORMAT)) goto done;
        if (!(in[k].itemsize == 8 && in[k].format && in[k].format[0] == 'd' && in[k].format[1] == 0
              && in[k].len == n * self->size[k] * 8)) {
            PyErr_Format(PyExc_ValueError, "batch: argument %d: expected %zd x %zd float64 values", k, n, self->size[k]);
            n_in_got++; goto done;
        }
    }
    for (j = 0; j < n_out; j++, n_out_got++) {
        if (PyObject_GetBuffer(PySequence_Fast_GET_ITEM(outs, j), &out[j],
                               PyBUF_C_CONTIGUOUS | PyBUF_WRITABLE | PyBUF_FORMAT)) goto done;
        if (!(out[j].itemsize == 8 && out[j].format && out[j].format[0] == 'd' && out[j].format[1] == 0
              && (n == 0 || out[j].len % (n * 8) == 0))) {
            PyErr_Format(PyExc_ValueError, "batch: output %d: expected n rows of float64 values", j);
            n_out_got++; goto done;
        }
    }
    for (i = 0; i < n; i++) {
        for (k = 0; k < self->n_in; k++) {
            memcpy(self->buf[k], (const double *)in[k].buf + i * self->size[k], (size_t)self->size[k] * 8);
            if (self->bound > 0 && check_bound(self->buf[k], self->size[k], self->bound, k)) {
                PyObject *type, *value, *tb;
                PyErr_Fetch(&type, &value, &tb);
                PyErr_Format(PyExc_ValueError, "row %zd, argument %d: a value is not finite or too large", i, k);
                Py_XDECREF(type); Py_XDECREF(value); Py_XDECREF(tb);
                goto done;
            }
        }
        if (self->n_quat && unit_quaternions(self)) {
            PyObject *type, *value, *tb;
            PyErr_Fetch(&type, &value, &tb);
            PyErr_Format(PyExc_ValueError, "row %zd, argument 0: a quaternion is zero", i);
            Py_XDECREF(type); Py_XDECREF(value); Py_XDECREF(tb);
            goto done;
        }
        if (self->fn(self->arg, self->res, self->iw, self->w, self->mem)) {
            PyErr_Format(PyExc_RuntimeError, "the compiled kernel returned an error at row %zd", i);
            goto done;
        }
        if (self->check && !(self->check[0] > self->tol && isfinite(self->check[1]))) {
            ret = PyLong_FromSsize_t(i);
            goto done;
        }
        for (j = 0; j < n_out; j++) {
            Py_ssize_t m = n ? out[j].len / (n * 8) : 0;
            memcpy((double *)out[j].buf + i * m, self->res[j], (size_t)m * 8);
        }
    }
    Py_INCREF(Py_None);
    ret = Py_None;
done:
    for (k = 0; k < n_in_got; k++) PyBuffer_Release(&in[k]);
    for (j = 0; j < n_out_got; j++) PyBuffer_Release(&out[j]);
    Py_DECREF(outs);
    return ret;
}

static PyMethodDef caller_methods[] = {
    {"batch", caller_batch, METH_VARARGS, "batch(n, outs, *arrays): the kernel on n rows (see fast_call.py)"},
    {NULL, NULL, 0, NULL}
};

static PyObject *caller_new(PyTypeObject *type, PyObject *a, PyObject *kw) {
    unsigned long long fn, arg, res, iw, w, check; int mem; double tol, bound;
    (void)kw;
    int finite = 0;
    PyObject *bufs, *sizes, *result, *keep, *outs = NULL, *quats = NULL;
    if (!PyArg_ParseTuple(a, "KKKKKiOOKddOO|OOp", &fn, &arg, &res, &iw, &w, &mem, &bufs, &sizes, &check, &tol, &bound,
                          &result, &keep, &outs, &quats, &finite))
        return NULL;
    Py_ssize_t n = PySequence_Size(bufs);
    Py_ssize_t n_out = outs ? PySequence_Size(outs) : 0, n_quat = quats ? PySequence_Size(quats) : 0;
    if (n < 0 || n > MAX_IN || PySequence_Size(sizes) != n || n_out < 0 || n_out > MAX_IN || n_quat < 0
        || n_quat > MAX_QUAT || (n_quat && !n)) {
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
    self->n_out = (int)n_out; self->n_quat = (int)n_quat; self->finite = finite && n_out;
    for (Py_ssize_t j = 0; j < n_out; j++) {
        unsigned long long address = 0;
        PyObject *o = PySequence_GetItem(outs, j);
        if (o && !PyArg_ParseTuple(o, "Knn", &address, &self->rows[j], &self->cols[j])) PyErr_Clear(), address = 0;
        Py_XDECREF(o);
        self->obuf[j] = (double *)(uintptr_t)address;
        if (!address && !PyErr_Occurred()) PyErr_SetString(PyExc_ValueError, "bad output list");
    }
    for (Py_ssize_t i = 0; i < n_quat; i++) {
        PyObject *o = PySequence_GetItem(quats, i);
        self->quat[i] = o ? PyLong_AsSsize_t(o) : -1;
        Py_XDECREF(o);
        if (!PyErr_Occurred() && (self->quat[i] < 0 || self->quat[i] + 4 > self->size[0]))
            PyErr_SetString(PyExc_ValueError, "bad quaternion offsets");
    }
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
    .tp_methods = caller_methods,
    .tp_dealloc = (destructor)caller_dealloc,
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "ncgen_fast_call", NULL, -1, NULL, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit_ncgen_fast_call(void) {
    import_array();
    if (PyType_Ready(&CallerType) < 0) return NULL;
    PyObject *m = PyModule_Create(&module);
    if (!m) return NULL;
    Py_INCREF(&CallerType);
    PyModule_AddObject(m, "Caller", (PyObject *)&CallerType);
    return m;
}
"""

#: The extension's compiler flags (-O3: the bound check vectorises).
FLAGS = ("-O3", "-Wall", "-Wextra", "-Werror")

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

        import numpy

        include, numpy_include = sysconfig.get_paths()["include"], numpy.get_include()
        if not (Path(include) / "Python.h").exists() or not (Path(numpy_include) / "numpy" / "arrayobject.h").exists():
            return None
        compiler = find_compiler()
        suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
        key = hashlib.sha256("\n".join([SOURCE, " ".join(FLAGS), sys.version, compiler.version, include, numpy_include,
                                         numpy.__version__]).encode()).hexdigest()[:24]
        entry = cache_dir() / f"fast_call-{key}"
        library = entry / f"ncgen_fast_call{suffix}"
        if not library.exists():
            entry.parent.mkdir(parents=True, exist_ok=True)
            with fsutil.locked(entry.parent / f".{entry.name}.lock"):
                if not library.exists():
                    with fsutil.temporary_sibling(entry) as tmp:
                        (tmp / "fast_call.c").write_text(SOURCE)
                        subprocess.run([*compiler.argv, *FLAGS, "-shared", "-fPIC",
                                        f"-I{include}", f"-I{numpy_include}", "-o",
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
                bound: float = 0.0, outputs=None, quaternions=()):
    """``caller(*arrays)`` for the inputs ``first .. first + n_inputs − 1`` of the
    :class:`~ncgen.codegen.direct.DirectFunction` ``direct`` (module docstring; ``check``: a
    2-entry output buffer, ``result``: what a call returns, ``bound``: the largest magnitude of
    an input value, 0 for no check), or None without the extension.

    A door (``outputs``: ``[(buffer, rows, columns)]``, the kernel's output buffers, matrices
    column-major, ``columns`` 0 for a vector): each call returns fresh arrays of the outputs
    (matrices row-major ``(rows, columns)``, a tuple for several) or, given one more argument
    ``out`` (an array, or a tuple of arrays for several outputs; float64, C-contiguous,
    writable, the outputs' shapes, else a ValueError), writes them into it and returns it.
    ``quaternions``: offsets of ``[qx, qy, qz, qw]`` in the first input, normalised after the
    copy with ``qw ≥ 0`` (as :func:`~ncgen.codegen.tree_check.unit_quaternions`; a zero one a
    ValueError).  ``check="finite"`` (a door's): None when a value of its outputs is not finite
    (the check of kernels without a check output, e.g. a KKT solve's)."""
    mod = _module()
    if mod is None:
        return None
    bufs = direct.inputs[first:first + n_inputs]
    fn, arg, res, iw, w, mem = direct._fn, *direct._args
    import ctypes
    address = ctypes.cast(fn, ctypes.c_void_p).value
    outs = [(b.ctypes.data, int(r), int(c)) for b, r, c in (outputs or ())]
    finite = isinstance(check, str) and check == "finite"
    check = None if finite else check
    return mod.Caller(address, arg, res, iw, w, mem, [b.ctypes.data for b in bufs], [b.size for b in bufs],
                      0 if check is None else check.ctypes.data, float(tol), float(bound), result,
                      (direct, bufs, check, outputs), outs, [int(i) for i in quaternions], bool(finite))
