"""Mass properties of MJCF bodies: ``<inertial>`` and the geoms' (``inertiafromgeom``).

A body's mass properties are a list of parts ``(m, c, I)``: mass (kg), centre of mass and
inertia tensor about it (kg·m²), both in the body's frame.  Geoms are solids of uniform
``density`` (kg/m³, default 1000) unless ``mass`` is given, as MuJoCo computes them:

===========  ========================  ===============================================
type         size (m)                  volume; principal moments about the centre
===========  ========================  ===============================================
sphere       r                         4πr³/3; 2mr²/5
capsule      r, h (half length)        πr²(2h) + 4πr³/3; cylinder + two hemispheres
cylinder     r, h                      πr²(2h); m(3r² + (2h)²)/12, mr²/2
box          a, b, c (half sides)      8abc; m(b² + c²)/3, ...
ellipsoid    a, b, c                   4πabc/3; m(b² + c²)/5, ...
===========  ========================  ===============================================

``fromto`` (capsule, cylinder, box, ellipsoid) places the geom's centre midway and its z
axis along the segment, whose half length is the size's last component.
"""
from __future__ import annotations

import numpy as np

from ncgen.errors import ModelError
from ncgen.model.mjcf_frames import pose, z_to
from ncgen.model.mjcf_xml import choice, number, numbers, where

GEOM_TYPES = ("plane", "hfield", "sphere", "capsule", "ellipsoid", "cylinder", "box", "mesh", "sdf")
SOLIDS = ("sphere", "capsule", "ellipsoid", "cylinder", "box")


def geom_frame(el, attrs: dict, compiler) -> tuple[np.ndarray, np.ndarray]:
    """``(T, size)``: the geom's pose in its body's frame and its sizes (``fromto`` applied)."""
    kind = choice(el, attrs, "type", GEOM_TYPES, "sphere")
    size = numbers(el, attrs, "size", (1, 2, 3), default=(0.0, 0.0, 0.0))
    size = np.concatenate([size, np.zeros(3 - size.size)])
    fromto = numbers(el, attrs, "fromto", 6)
    if fromto is None or kind not in ("capsule", "cylinder", "box", "ellipsoid"):
        return pose(el, attrs, compiler), size
    a, b = fromto[:3], fromto[3:]
    d = b - a
    L = np.linalg.norm(d)
    if not L > 0:
        raise ModelError(f"MJCF {where(el)}: <geom fromto={attrs['fromto']!r}>: the two ends coincide")
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = z_to(d), (a + b) / 2
    size[1 if kind in ("capsule", "cylinder") else 2] = L / 2
    return T, size


def solid(kind: str, size: np.ndarray, el) -> tuple[float, np.ndarray]:
    """``(volume, principal moments per unit mass)`` of a solid geom (module docstring)."""
    if np.any(size[:{"sphere": 1, "capsule": 2, "cylinder": 2}.get(kind, 3)] <= 0):
        raise ModelError(f"MJCF {where(el)}: <geom type={kind!r} size={size.tolist()}>: sizes must be positive")
    r = size[0]
    if kind == "sphere":
        return 4 / 3 * np.pi * r**3, np.full(3, 0.4 * r * r)
    if kind in ("capsule", "cylinder"):
        h = 2 * size[1]
        if kind == "cylinder":
            return np.pi * r * r * h, np.array([(3 * r * r + h * h) / 12] * 2 + [r * r / 2])
        vs, vc = 4 / 3 * np.pi * r**3, np.pi * r * r * h
        fs, fc = vs / (vs + vc), vc / (vs + vc)
        across = fc * (3 * r * r + h * h) / 12 + fs * (0.4 * r * r + h * (3 * r + 2 * h) / 8)
        return vs + vc, np.array([across, across, fc * r * r / 2 + fs * 0.4 * r * r])
    a, b, c = size
    if kind == "box":
        return 8 * a * b * c, np.array([b * b + c * c, a * a + c * c, a * a + b * b]) / 3
    return 4 / 3 * np.pi * a * b * c, np.array([b * b + c * c, a * a + c * c, a * a + b * b]) / 5


def geom_part(el, attrs: dict, compiler):
    """The geom's ``(m, c, I)`` in its body's frame, or None when it has no mass."""
    kind = attrs.get("type", "sphere")
    T, size = geom_frame(el, attrs, compiler)
    volume, moments = solid(kind, size, el)
    if "mass" in attrs:
        m = number(el, attrs, "mass", 0.0)
    else:
        m = number(el, attrs, "density", 1000.0) * volume
    if m < 0:
        raise ModelError(f"MJCF {where(el)}: <geom> mass {m:g} kg is negative")
    if m == 0:
        return None
    R = T[:3, :3]
    return m, T[:3, 3].copy(), R @ np.diag(m * moments) @ R.T


def inertial_part(el, attrs: dict, compiler):
    """The ``<inertial>``'s ``(m, c, I)`` in its body's frame."""
    m = number(el, attrs, "mass", float("nan"))
    if not m >= 0:
        raise ModelError(f"MJCF {where(el)}: <inertial> needs mass ≥ 0 (kg), found {attrs.get('mass')!r}")
    T = pose(el, attrs, compiler)
    full = numbers(el, attrs, "fullinertia", 6)
    diag = numbers(el, attrs, "diaginertia", 3)
    if (full is None) == (diag is None):
        raise ModelError(f"MJCF {where(el)}: <inertial> needs exactly one of diaginertia, fullinertia")
    if full is not None:
        xx, yy, zz, xy, xz, yz = full
        I = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
    else:
        I = np.diag(diag)
    e = np.linalg.eigvalsh(I)
    tol = 1e-9 * max(float(np.abs(e).max()), 1e-300)
    if e.min() < -tol or min(e[1] + e[2] - e[0], e[0] + e[2] - e[1], e[0] + e[1] - e[2]) < -tol:
        raise ModelError(f"MJCF {where(el)}: <inertial>: the inertia tensor is not physical: principal moments "
                         f"{np.array2string(e, precision=6)} kg·m² (expected all ≥ 0 and I_a + I_b ≥ I_c)")
    R = T[:3, :3]
    return m, T[:3, 3].copy(), R @ I @ R.T


def lump(parts) -> tuple[float, np.ndarray, np.ndarray]:
    """Total mass, centre of mass and inertia about it of parts ``(m, c, I)`` in one frame."""
    mass = sum(m for m, _, _ in parts)
    if mass <= 0:
        return 0.0, np.zeros(3), np.zeros((3, 3))
    com = sum(m * c for m, c, _ in parts) / mass
    inertia = np.zeros((3, 3))
    for m, c, I in parts:
        d = c - com
        inertia += I + m * (d @ d * np.eye(3) - np.outer(d, d))
    return mass, com, inertia
