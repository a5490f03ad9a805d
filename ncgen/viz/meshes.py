"""Mesh files (STL, OBJ, DAE, ... whatever ``trimesh`` reads) as compact triangle arrays.

``trimesh`` (and ``pycollada`` for DAE) is an optional dependency: ``pip install ncgen[viz]``.
File names may be ``package://PKG/rest`` (ROS style: looked up under ``ROS_PACKAGE_PATH``,
the ``share`` folders of this Python environment, e.g. example-robot-data's, and the extra
``search`` folders), ``file://`` URLs, absolute paths, or paths relative to a search folder
or the working directory."""
from __future__ import annotations

import os
import site
import sys
from functools import lru_cache
from pathlib import Path

import numpy as np

from ncgen.errors import NcgenError


class MeshError(NcgenError):
    """A mesh file that cannot be found or read."""


def search_roots(extra=()) -> list[Path]:
    """Folders where ``package://`` names and relative names are looked up, in order."""
    roots = [Path(p) for p in extra]
    roots += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    prefixes = [Path(sys.prefix)] + [Path(p) for p in site.getsitepackages()]
    for prefix in prefixes:
        roots += [prefix / "share", prefix / "cmeel.prefix" / "share"]
    return [r for r in roots if r.is_dir()]


def resolve(filename: str, extra=()) -> Path:
    """The file a mesh name refers to (see the module docstring), or a :class:`MeshError`
    saying where it was looked for."""
    name = str(filename)
    if name.startswith("file://"):
        name = name[len("file://"):]
    candidates = []
    if name.startswith("package://"):
        rest = name[len("package://"):]
        candidates = [root / rest for root in search_roots(extra)]
        pkg, _, tail = rest.partition("/")
        candidates += [root / tail for root in search_roots(extra) if root.name == pkg]
    else:
        path = Path(name)
        candidates = [path] if path.is_absolute() else [Path.cwd() / path] + [r / path for r in search_roots(extra)]
    for c in candidates:
        if c.is_file():
            return c
    roots = ", ".join(str(r) for r in search_roots(extra)) or "none"
    raise MeshError(f"mesh {filename!r}: file not found (looked under: {roots}); pass the folder "
                    "holding it with mesh_paths=[...] (or set ROS_PACKAGE_PATH)")


@lru_cache(maxsize=64)
def load(path: str) -> tuple[np.ndarray, np.ndarray, str | None]:
    """``(vertices (n, 3) float, faces (m, 3) int, colour '#rrggbb' or None)`` of a mesh file,
    duplicate vertices merged, in the file's units."""
    try:
        import trimesh
    except ImportError:
        raise MeshError(f"mesh {path}: reading mesh files needs trimesh: pip install 'ncgen[viz]' "
                        "(or pip install trimesh pycollada)") from None
    try:
        loaded = trimesh.load(path, force="mesh")
    except Exception as e:        # trimesh raises many types; report the file and the reason
        raise MeshError(f"mesh {path}: cannot be read: {type(e).__name__}: {e}") from None
    if not hasattr(loaded, "faces") or len(loaded.faces) == 0:
        raise MeshError(f"mesh {path}: no triangles")
    color = _color(loaded)
    mesh = trimesh.Trimesh(np.asarray(loaded.vertices, float), np.asarray(loaded.faces, int), process=True)
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), color


def _color(mesh) -> str | None:
    """The main colour of a mesh's material or vertex colours, if it has one."""
    try:
        visual = mesh.visual
        if visual.kind == "texture" and getattr(visual, "material", None) is not None:
            rgba = np.asarray(visual.material.main_color, float)
        elif visual.kind in ("vertex", "face"):
            rgba = np.asarray(visual.to_color().main_color, float)
        else:
            return None
    except (AttributeError, ValueError):
        return None
    r, g, b = (int(np.clip(x, 0, 255)) for x in rgba[:3])
    return f"#{r:02x}{g:02x}{b:02x}"


def quantize(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(q uint16 (n, 3), low, high)`` with ``vertices ≈ low + q / 65535 (high − low)``
    (error below 1e-5 of the mesh's extent)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    span = np.where(hi > lo, hi - lo, 1.0)
    q = np.rint((vertices - lo) / span * 65535).astype(np.uint16)
    return q, lo, lo + span
