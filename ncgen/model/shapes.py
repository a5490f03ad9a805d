"""Shapes of members, for drawing only (they change no mass property).

A shape lies in its member's local frame (a body's frame: origin at the centre of mass,
axes of ``rotation``; a bar's: origin at its centre of mass, x̄ from its first end to its
second), offset by ``position`` (m) and ``rotation`` (shape → member axes, 3×3).

* ``Box(a, b, c)``: edge lengths along the local x, y, z axes (m);
* ``Cylinder(radius, length)`` and ``Capsule(radius, length)``: axis along local z (a bar's
  along x̄), ``length`` of the straight part;
* ``Sphere(radius)``; ``Ellipsoid(a, b, c)``: semi-axes along x, y, z;
* ``Mesh(filename, scale=1)``: an STL, OBJ, DAE (... any file ``trimesh`` reads) in member
  coordinates, ``scale`` a number or three.

Python: ``s.add_body(..., shape=nc.Box(0.1, 0.2, 0.3))`` or ``member.set_shape(...)``.
TOML (a member's ``shape`` key): ``{box = [a, b, c]}``, ``{cylinder = [radius, length]}``,
``{capsule = [radius, length]}``, ``{sphere = radius}``, ``{ellipsoid = [a, b, c]}``,
``{mesh = "file.stl", scale = 0.001}``; each may add ``position = [...]`` and ``rotation = [[...]]``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ncgen.errors import ModelError
from ncgen.validation import rotation as _rotation


class Shape:
    """Base class: a kind, positive dimensions and a placement in the member frame."""

    kind = "shape"
    #: names of the dimensions, in order
    dims: tuple[str, ...] = ()

    def __init__(self, *values, position=None, rotation=None):
        if len(values) != len(self.dims):
            raise ModelError(f"{self.kind}: expected {len(self.dims)} dimensions ({', '.join(self.dims)}), "
                             f"got {len(values)}: {list(values)!r}")
        size = []
        for name, v in zip(self.dims, values):
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise ModelError(f"{self.kind}: {name}: expected a positive number (m), got {v!r}") from None
            if not np.isfinite(x) or x <= 0:
                raise ModelError(f"{self.kind}: {name}: expected a positive number (m), got {v!r}")
            size.append(x)
        self.size = np.array(size)
        self.position = _placement_vector(position, self.kind)
        self.rotation = np.eye(3) if rotation is None else _rotation(rotation, 3, f"{self.kind}: rotation")

    def to_toml(self) -> dict:
        out = {self.kind: self.size.tolist() if len(self.size) > 1 else float(self.size[0])}
        return {**out, **self._placement()}

    def _placement(self) -> dict:
        out = {}
        if np.any(self.position):
            out["position"] = self.position.tolist()
        if not np.array_equal(self.rotation, np.eye(3)):
            out["rotation"] = self.rotation.tolist()
        return out

    def __repr__(self) -> str:
        return f"{type(self).__name__}({', '.join(f'{x:g}' for x in self.size)})"


class Box(Shape):
    kind, dims = "box", ("edge x", "edge y", "edge z")


class Cylinder(Shape):
    kind, dims = "cylinder", ("radius", "length")


class Capsule(Shape):
    kind, dims = "capsule", ("radius", "length")


class Sphere(Shape):
    kind, dims = "sphere", ("radius",)


class Ellipsoid(Shape):
    kind, dims = "ellipsoid", ("semi-axis x", "semi-axis y", "semi-axis z")


class Mesh(Shape):
    """A mesh file (drawn by the HTML viewer through the optional ``trimesh``)."""

    kind = "mesh"

    def __init__(self, filename, scale=1.0, *, position=None, rotation=None):
        if not isinstance(filename, (str, Path)) or not str(filename):
            raise ModelError(f"mesh: filename: expected a file name, got {filename!r}")
        s = np.atleast_1d(np.asarray(scale, dtype=float)).reshape(-1)
        if s.size not in (1, 3) or not np.all(np.isfinite(s)) or np.any(s <= 0):
            raise ModelError(f"mesh {filename}: scale: expected a positive number or three, got {scale!r}")
        self.filename = str(filename)
        self.scale = np.repeat(s, 3) if s.size == 1 else s
        super().__init__(position=position, rotation=rotation)

    def to_toml(self) -> dict:
        out = {"mesh": self.filename}
        if not np.allclose(self.scale, 1.0):
            out["scale"] = float(self.scale[0]) if np.all(self.scale == self.scale[0]) else self.scale.tolist()
        return {**out, **self._placement()}

    def __repr__(self) -> str:
        return f"Mesh({self.filename!r})"


KINDS = {cls.kind: cls for cls in (Box, Cylinder, Capsule, Sphere, Ellipsoid, Mesh)}


def check_shape(shape, what: str) -> Shape:
    """``shape`` if it is a :class:`Shape` (None passes), else a clear error naming ``what``."""
    if shape is None or isinstance(shape, Shape):
        return shape
    raise ModelError(f"{what}: shape: expected nc.Box, nc.Cylinder, nc.Capsule, nc.Sphere, nc.Ellipsoid or "
                     f"nc.Mesh, got {shape!r}")


def shape_from_table(table, path: str, base: Path | None = None) -> Shape:
    """A shape from its TOML table (see the module docstring); a relative mesh file name is
    taken relative to ``base`` (the model file's folder)."""
    if not isinstance(table, dict):
        raise ModelError(f"{path}: expected a table such as {{box = [0.1, 0.2, 0.3]}}, got {table!r}")
    kinds = [k for k in table if k in KINDS]
    extra = [k for k in table if k not in KINDS and k not in ("position", "rotation", "scale")]
    if len(kinds) != 1 or extra:
        raise ModelError(f"{path}: expected exactly one of {', '.join(KINDS)} (with optional position, "
                         f"rotation{', scale' if 'mesh' in kinds else ''}), got keys {list(table)}")
    kind = kinds[0]
    if "scale" in table and kind != "mesh":
        raise ModelError(f"{path}.scale: only a mesh has a scale")
    place = {k: table[k] for k in ("position", "rotation") if k in table}
    value = table[kind]
    try:
        if kind == "mesh":
            name = Path(value) if isinstance(value, str) else value
            if isinstance(name, Path) and not name.is_absolute() and base is not None:
                name = base / name
            return Mesh(name, table.get("scale", 1.0), **place)
        values = value if isinstance(value, list) else [value]
        return KINDS[kind](*values, **place)
    except ModelError as e:
        raise ModelError(f"{path}: {e}") from None


def _placement_vector(position, kind: str) -> np.ndarray:
    if position is None:
        return np.zeros(3)
    p = np.asarray(position, dtype=float).reshape(-1)
    if p.size != 3 or not np.all(np.isfinite(p)):
        raise ModelError(f"{kind}: position: expected three numbers (m), got {position!r}")
    return p
