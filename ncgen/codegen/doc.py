"""Documentation metadata of a generated C package.

Everything is plain data (str, numbers, lists, dicts) so that it can be hashed, written
to ``manifest.json`` and rendered into the C header.  Nested plain dicts are accepted
wherever a dataclass is expected and converted on construction:

- an argument doc is ``ArgDoc``, a dict ``{"meaning": ..., "units": ...}``, a
  ``(meaning, units)`` pair or just the meaning as a string;
- a function doc is ``FunctionDoc`` or ``{"purpose": ..., "inputs": {...}, "outputs": {...}}``.

``metadata`` holds the model's dimensions, names and default state.  Each key must be a C
identifier; its value becomes, in ``<name>.h``:

- int or bool  -> ``#define <NAME>_<KEY> value``
- float        -> ``#define <NAME>_<KEY> value`` (finite only)
- str          -> ``#define <NAME>_<KEY> "value"``
- 1-D sequence of numbers -> ``extern const casadi_real <name>_<key>[n];``
- 1-D sequence of str     -> ``extern const char *const <name>_<key>[n];``
  (both also get ``#define <NAME>_<KEY>_LEN n``; the arrays live in ``<name>_meta.c``).

``data`` lists the metadata keys that are the model's *data* rather than its code: values
another run of the same compiled functions may change (the initial state and what hashes
it).  They live in ``<name>_data.c`` (arrays, and strings as ``extern const char
<name>_<key>[]`` with ``#define <NAME>_<KEY> <name>_<key>``), so the header and the other
sources do not depend on them; the Makefile and CMake build it into the library and the
programs, the compile cache leaves it out (Python reads them from the manifest).

``defaults`` maps a function *input name* to the metadata key holding its default value
(nonzeros in CasADi's column-major order); ``main.c`` evaluates with these, zeros elsewhere.
"""
from __future__ import annotations

import math
import numbers
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

from ncgen.errors import CodegenError

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


def check_identifier(what: str, name: str) -> str:
    """Return ``name`` if it is a C identifier, else raise naming ``what``."""
    if not isinstance(name, str) or not _IDENT.match(name):
        raise CodegenError(f"{what} must be a C identifier ([A-Za-z_][A-Za-z0-9_]*), found {name!r}")
    return name


@dataclass(frozen=True)
class ArgDoc:
    """Meaning and SI units of one function input or output."""

    meaning: str = ""
    units: str = ""

    @classmethod
    def of(cls, value: Any, where: str) -> "ArgDoc":
        if isinstance(value, ArgDoc):
            return value
        if isinstance(value, str):
            return cls(meaning=value)
        if isinstance(value, Mapping):
            unknown = set(value) - {"meaning", "units"}
            if unknown:
                raise CodegenError(f"{where}: unknown keys {sorted(unknown)}; expected 'meaning', 'units'")
            return cls(**{k: str(v) for k, v in value.items()})
        if isinstance(value, (tuple, list)) and len(value) == 2:
            return cls(meaning=str(value[0]), units=str(value[1]))
        raise CodegenError(f"{where}: expected ArgDoc, str, (meaning, units) or dict, found {value!r}")

    def to_json(self) -> dict:
        return {"meaning": self.meaning, "units": self.units}


@dataclass(frozen=True)
class FunctionDoc:
    """Purpose of one function and docs of its inputs and outputs, by name."""

    purpose: str = ""
    inputs: Mapping[str, ArgDoc] = field(default_factory=dict)
    outputs: Mapping[str, ArgDoc] = field(default_factory=dict)

    @classmethod
    def of(cls, value: Any, where: str) -> "FunctionDoc":
        if isinstance(value, FunctionDoc):
            value = {"purpose": value.purpose, "inputs": value.inputs, "outputs": value.outputs}
        if isinstance(value, str):
            value = {"purpose": value}
        if not isinstance(value, Mapping):
            raise CodegenError(f"{where}: expected FunctionDoc, str or dict, found {value!r}")
        unknown = set(value) - {"purpose", "inputs", "outputs"}
        if unknown:
            raise CodegenError(f"{where}: unknown keys {sorted(unknown)}; expected 'purpose', 'inputs', 'outputs'")
        args = {}
        for kind in ("inputs", "outputs"):
            args[kind] = {str(k): ArgDoc.of(v, f"{where}.{kind}[{k!r}]")
                          for k, v in dict(value.get(kind, {})).items()}
        return cls(purpose=str(value.get("purpose", "")), **args)

    def to_json(self) -> dict:
        return {"purpose": self.purpose,
                "inputs": {k: v.to_json() for k, v in self.inputs.items()},
                "outputs": {k: v.to_json() for k, v in self.outputs.items()}}


@dataclass(frozen=True)
class PackageDoc:
    """What the generated header says about the package (see the module docstring)."""

    summary: str = ""
    functions: Mapping[str, FunctionDoc] = field(default_factory=dict)
    metadata: Mapping[str, Any] = field(default_factory=dict)
    metadata_doc: Mapping[str, str] = field(default_factory=dict)
    defaults: Mapping[str, str] = field(default_factory=dict)
    main_function: str | None = None
    data: tuple[str, ...] = ()

    def __post_init__(self):
        set_ = object.__setattr__
        set_(self, "functions", {str(k): FunctionDoc.of(v, f"PackageDoc.functions[{k!r}]")
                                 for k, v in dict(self.functions).items()})
        set_(self, "metadata", {check_identifier("PackageDoc.metadata key", k): _plain(k, v)
                                for k, v in dict(self.metadata).items()})
        set_(self, "metadata_doc", {str(k): str(v) for k, v in dict(self.metadata_doc).items()})
        set_(self, "defaults", {str(k): str(v) for k, v in dict(self.defaults).items()})
        set_(self, "data", tuple(str(k) for k in self.data))
        for key in self.data:
            if not isinstance(self.metadata.get(key), (list, str)):
                raise CodegenError(f"PackageDoc.data names {key!r}, which must be a metadata key holding "
                                   f"a list or a string; found {self.metadata.get(key)!r}")
        for key in self.metadata_doc:
            if key not in self.metadata:
                raise CodegenError(f"PackageDoc.metadata_doc documents {key!r}, which is not a "
                                   f"metadata key (keys: {sorted(self.metadata)})")
        for arg, key in self.defaults.items():
            value = self.metadata.get(key)
            if not (isinstance(value, list) and all(isinstance(x, float) for x in value)):
                raise CodegenError(f"PackageDoc.defaults[{arg!r}] names metadata key {key!r}, which "
                                   f"must hold a list of numbers; found {value!r}")

    def to_json(self) -> dict:
        return {"summary": self.summary,
                "functions": {k: v.to_json() for k, v in sorted(self.functions.items())},
                "metadata": dict(sorted(self.metadata.items())),
                "metadata_doc": dict(sorted(self.metadata_doc.items())),
                "defaults": dict(sorted(self.defaults.items())),
                "main_function": self.main_function, **({"data": list(self.data)} if self.data else {})}


def _plain(key: str, value: Any):
    """Normalise one metadata value to int, float, str, list[float] or list[str]."""
    where = f"PackageDoc.metadata[{key!r}]"
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return _finite(float(value), where)
    if isinstance(value, str):
        return value
    if hasattr(value, "tolist"):  # numpy arrays and scalars
        return _plain(key, value.tolist())
    if isinstance(value, (list, tuple)):
        if all(isinstance(x, str) for x in value):
            return list(value)
        if all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in value):
            return [_finite(float(x), f"{where}[{i}]") for i, x in enumerate(value)]
    raise CodegenError(f"{where}: expected int, float, str, or a flat list of numbers or of "
                       f"strings, found {type(value).__name__} {value!r}")


def _finite(x: float, where: str) -> float:
    if not math.isfinite(x):
        raise CodegenError(f"{where}: expected a finite number, found {x!r}")
    return x
