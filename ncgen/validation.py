"""Argument checks shared by every layer: names, numbers, shapes, rotations, run sizes.

Each check returns a clean value and raises a :mod:`ncgen.errors` exception whose message
names the argument (``what``), what was expected and what was found.  The Python API, the
TOML loader and the command line all go through these, so one input is judged by one rule:

* names (:func:`name`): ASCII identifiers ``[A-Za-z_][A-Za-z0-9_]*`` of at most
  :data:`MAX_NAME` characters, because every name becomes part of C identifiers, file
  names and CSV headers; a system's name (:func:`system_name`) also starts with a letter
  and has no ``__`` and no final ``_``, because it prefixes CasADi's function names
  (``<system>_step``), which must;
* numbers (:func:`as_array`, :func:`as_scalar`): real (not complex, not booleans, not
  strings or ``None``), finite, of magnitude at most :data:`MAX_MAGNITUDE` (so that
  products of two stay finite in double precision), integers too long for a double included;
* run sizes (:func:`allocation`): an output that would need more than
  :data:`MAX_ALLOCATION` bytes is refused with the size it would need.
"""
from __future__ import annotations

import math
import re
import warnings

import numpy as np

from ncgen.environment import getenv
from ncgen.errors import InertiaError, InvalidName, NcgenError, RotationError, ShapeError

ROTATION_TOL = 1e-9
#: Longest name of a system, member, joint, force, marker, parameter or input.
MAX_NAME = 64
#: Largest magnitude of any number of a model or a run (SI units).
MAX_MAGNITUDE = 1e100
#: Largest array a run may allocate for its results (bytes); ``$NCGEN_MAX_BYTES`` overrides.
MAX_ALLOCATION = 8 * 2**30
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_SYSTEM_NAME = re.compile(r"[A-Za-z](?:_?[A-Za-z0-9])*")


def name(value, what: str) -> str:
    """``value`` if it is an ASCII identifier of at most :data:`MAX_NAME` characters."""
    rule = f"an identifier (ASCII letters, digits, _; not starting with a digit; at most {MAX_NAME} characters)"
    if not isinstance(value, str):
        raise InvalidName(f"{what}: expected {rule}, got {type(value).__name__} {value!r}")
    shown = value if len(value) <= 40 else value[:37] + "..."
    if len(value) > MAX_NAME:
        raise InvalidName(f"{what}: expected {rule}, got {shown!r}: {len(value)} characters long "
                          f"(names become C identifiers and file names)")
    if not _NAME.fullmatch(value):
        bad = next((c for c in value if not (c.isascii() and (c.isalnum() or c == "_"))), None)
        why = (f"the character {bad!r} is not allowed" if bad is not None else
               "it starts with a digit" if value else "it is empty")
        raise InvalidName(f"{what}: expected {rule}, got {shown!r}: {why}")
    return value


def system_name(value, what: str) -> str:
    """``value`` if it is a :func:`name` that starts with a letter, has no ``__`` and does
    not end with ``_`` (it prefixes CasADi function names, e.g. ``<system>_step``)."""
    name(value, what)
    if not _SYSTEM_NAME.fullmatch(value):
        why = ("it does not start with a letter" if not value[0].isalpha() else
               "it has two underscores in a row" if "__" in value else "it ends with '_'")
        raise InvalidName(f"{what}: expected an identifier that starts with a letter, without '__' and not "
                          f"ending with '_' (it prefixes C function names), got {value!r}: {why}")
    return value


def as_system_name(text: str, fallback: str) -> str:
    """A :func:`system_name` made from ``text`` (a file stem, a robot's name): other characters
    become ``_``, runs of ``_`` one, ``_`` at the ends dropped, ``fallback`` + ``_`` put before
    a leading digit; ``fallback`` if nothing is left."""
    s = re.sub(r"_+", "_", re.sub(r"[^A-Za-z0-9]", "_", text)).strip("_")[:MAX_NAME].rstrip("_")
    if not s:
        return fallback
    return s if s[0].isalpha() else f"{fallback}_{s}"[:MAX_NAME].rstrip("_")


def allocation(n_bytes: float, what, hint: str) -> None:
    """Refuse an allocation of ``n_bytes`` above :data:`MAX_ALLOCATION` (or
    ``$NCGEN_MAX_BYTES``), saying how much it would need (``what``: the text, or a function
    making it only then) and ``hint`` (what to change)."""
    limit = float(getenv("NCGEN_MAX_BYTES", MAX_ALLOCATION))
    if n_bytes > limit:
        what = what() if callable(what) else what
        raise NcgenError(f"{what} would need {_bytes(n_bytes)} of memory, more than the limit of "
                         f"{_bytes(limit)} (NCGEN_MAX_BYTES); {hint}")


def _bytes(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if n < 1024 or unit == "EiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} EiB"


def _float_array(x, what: str = "value") -> np.ndarray:
    """``np.asarray(x, float)``; integers too long for a double raise OverflowError; complex
    numbers, booleans and ``None`` entries raise :class:`ShapeError` (NumPy would drop the
    imaginary part, read ``True`` as 1 and ``None`` as NaN)."""
    kind = _wrong_kind(x)
    if kind:
        raise ShapeError(f"{what}: expected real numbers, got {kind}")
    return np.asarray(x, dtype=float)


def _wrong_kind(x) -> str | None:
    """What makes ``x`` not an array of real numbers although NumPy converts it, or None."""
    if isinstance(x, (bytes, bytearray, memoryview)):
        return f"{type(x).__name__} (raw bytes are not read as numbers)"
    if type(x) in (str, float, int) or (type(x) is np.ndarray and x.dtype.kind in "fiu"):
        return None                              # the common cases; NumPy refuses strings itself
    try:
        a = np.asarray(x)
    except Exception:                            # ragged: NumPy's conversion error says it
        return None
    if a.dtype.kind == "c":
        return "complex numbers" + (f" ({complex(a.reshape(-1)[0])}, ...)" if a.size else "")
    if a.dtype.kind == "b":
        return "booleans"
    if a.dtype.kind == "O":
        for i, e in enumerate(a.reshape(-1)):
            if e is None or isinstance(e, (bool, np.bool_, complex, np.complexfloating)):
                index = tuple(int(k) for k in np.unravel_index(i, a.shape))
                where = f" at index {index[0] if a.ndim == 1 else index}" if a.ndim else ""
                return f"{type(e).__name__} {e!r}{where}"
    return None


def _check_magnitude(a: np.ndarray, what: str) -> None:
    if not np.all(np.isfinite(a)):
        shown = a.tolist() if a.size <= 12 else f"{np.sum(~np.isfinite(a))} non-finite values"
        raise ShapeError(f"{what}: expected finite numbers, got {shown}")
    if a.size and np.max(np.abs(a)) > MAX_MAGNITUDE:
        raise ShapeError(f"{what}: expected numbers of magnitude at most {MAX_MAGNITUDE:g}, got "
                         f"{float(np.max(np.abs(a))):g}")


#: Largest |RᵀR − 1| of a matrix accepted as a rotation given with printed precision (copied
#: from a paper or another tool, ~6 digits); it is projected to the nearest rotation.
PRINTED_ROTATION_TOL = 1e-5


class RotationProjected(UserWarning):
    """A rotation given with printed precision was replaced by the nearest rotation."""


def _shape_of(x) -> str:
    """What ``x`` is, for a message: its shape if it is numeric, else (a prefix of) its repr."""
    text = " ".join(repr(x).split())
    text = text if len(text) <= 60 else text[:57] + "..."
    try:
        np.asarray(x, dtype=object).astype(float)
    except (TypeError, ValueError, OverflowError):
        return f"{type(x).__name__} {text}"
    try:
        return "shape " + str(np.shape(x))
    except Exception:  # ragged input
        return f"{type(x).__name__} {text}"


def as_array(x, shape: tuple, what: str) -> np.ndarray:
    """``x`` as a finite float array of exactly ``shape``."""
    if type(x) is np.ndarray and x.dtype == np.float64 and x.shape == tuple(shape) and \
            (not x.size or float(np.abs(x).max()) <= MAX_MAGNITUDE):
        return x                    # the common case, at one reduction's cost (NaN fails the bound)
    a = as_numbers(x, what, f"numbers of shape {shape}")
    if a.shape != tuple(shape):
        if len(shape) == 1:
            raise ShapeError(f"{what}: expected {shape[0]} numbers, got {_describe(a)}")
        raise ShapeError(f"{what}: expected shape {tuple(shape)}, got {_describe(a)}")
    _check_magnitude(a, what)
    return a


def as_numbers(x, what: str, expected: str = "numbers") -> np.ndarray:
    """``x`` as a float array of whatever shape it has (the caller checks the shape, saying
    ``expected``): real numbers only (see :func:`_float_array`); finiteness is not checked."""
    try:
        return _float_array(x, what)
    except ShapeError:
        raise
    except OverflowError:
        raise ShapeError(f"{what}: a number is too large (more than {MAX_MAGNITUDE:g})") from None
    except (TypeError, ValueError):
        raise ShapeError(f"{what}: expected {expected}, got {_shape_of(x)}") from None


def _describe(a: np.ndarray) -> str:
    if a.ndim == 1:
        return f"{a.shape[0]}"
    if a.ndim == 0:
        return "a scalar"
    return f"shape {a.shape}"


def as_vector(x, n: int, what: str) -> np.ndarray:
    return as_array(x, (n,), what)


def write_out(out, result, what: str):
    """``out`` (an array, or a tuple of arrays for several results) with ``result`` (an array
    or a tuple of arrays) written into it, for the ``out=`` argument of ``what``; a
    :class:`~ncgen.errors.ShapeError` naming ``out`` unless each array is a writable
    C-contiguous float64 array of its result's shape."""
    several = type(result) is tuple
    results, outs = (result, out) if several else ((result,), (out,))
    if several and not (type(out) is tuple and len(out) == len(result)):
        raise ShapeError(f"{what}: out: expected a tuple of {len(result)} arrays (one per output), got "
                         f"{type(out).__name__}")
    for o, r in zip(outs, results):
        if not (type(o) is np.ndarray and o.dtype == np.float64 and o.shape == r.shape and o.flags.c_contiguous
                and o.flags.writeable):
            found = (f"{o.dtype} array of shape {o.shape}{'' if o.flags.c_contiguous else ', not C-contiguous'}"
                     f"{'' if o.flags.writeable else ', read-only'}" if isinstance(o, np.ndarray) else type(o).__name__)
            raise ShapeError(f"{what}: out: expected a writable C-contiguous float64 array of shape {r.shape}, "
                             f"got {found}")
        o[...] = r
    return out


def as_scalar(x, what: str) -> float:
    if type(x) is float and abs(x) <= MAX_MAGNITUDE:
        return x                    # the common case (NaN fails the bound)
    try:
        v = float(_float_array(x, what).reshape(()))
    except ShapeError:
        raise
    except OverflowError:
        raise ShapeError(f"{what}: the number is too large (more than {MAX_MAGNITUDE:g})") from None
    except (TypeError, ValueError):
        shown = repr(x) if len(repr(x)) <= 60 else repr(x)[:57] + "..."
        raise ShapeError(f"{what}: expected a number, got {shown}") from None
    if not np.isfinite(v):
        raise ShapeError(f"{what}: expected a finite number, got {v}")
    if abs(v) > MAX_MAGNITUDE:
        raise ShapeError(f"{what}: expected a number of magnitude at most {MAX_MAGNITUDE:g}, got {v:g}")
    return v


def nonnegative(x, what: str) -> float:
    v = as_scalar(x, what)
    if v < 0:
        raise ShapeError(f"{what}: expected a number >= 0, got {v:g}")
    return v


def positive(x, what: str) -> float:
    v = as_scalar(x, what)
    if v <= 0:
        raise InertiaError(f"{what}: expected a positive number, got {v}")
    return v


def rotation(R, dim: int, what: str = "rotation") -> np.ndarray:
    """A proper rotation matrix (``RᵀR = 1``, ``det R = +1`` to 1e-9); in 2D an angle is accepted."""
    if dim == 2 and np.ndim(R) == 0:
        a = as_scalar(R, what)
        c, s = math.cos(a), math.sin(a)        # libm, not NumPy's CPU-dependent SIMD loops
        return np.array([[c, -s], [s, c]])
    return nearest_rotation(as_array(R, (dim, dim), what), what)


def nearest_rotation(R: np.ndarray, what: str) -> np.ndarray:
    """Rotation matrices ``R`` (shape ``(..., d, d)``) as given when ``max |RᵀR − 1|`` is at
    most :data:`ROTATION_TOL`; up to :data:`PRINTED_ROTATION_TOL` (a rotation copied with
    printed precision) each is replaced by its nearest rotation (the polar factor ``U Vᵀ`` of
    its SVD) with a :class:`RotationProjected` warning; beyond that, or with ``det R < 0``, a
    :class:`~ncgen.errors.RotationError` says what was found.  The one rule for every entry
    point that takes a rotation."""
    R = np.asarray(R, float)
    d = R.shape[-1]
    err = float(np.max(np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(d)), initial=0.0))
    if err > PRINTED_ROTATION_TOL:
        raise RotationError(f"{what}: expected an orthonormal matrix, |RᵀR - 1| = {err:.3g} "
                            f"(up to {PRINTED_ROTATION_TOL:g} is projected to the nearest rotation)")
    det = np.linalg.det(R)
    if np.any(det < 0):
        raise RotationError(f"{what}: expected det = +1 (a proper rotation), got det = {float(np.min(det)):.6g} "
                            "(a reflection)")
    if err > ROTATION_TOL:
        U, _, Vt = np.linalg.svd(R)
        P = U @ Vt                                # the nearest rotation (polar factor), det +1 here
        warnings.warn(f"{what}: |RᵀR - 1| = {err:.3g}: projected to the nearest rotation "
                      f"(largest change of an entry {np.max(np.abs(P - R)):.3g})", RotationProjected, stacklevel=3)
        return P
    return R
