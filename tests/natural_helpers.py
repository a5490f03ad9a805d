"""Random members, states and the seed's matrices, shared by the natural-coordinate tests.

The seed's matrices are typed here from /work/shared/seeds/natural-coordinates.md: they are
the specification the derivation is checked against, so they are deliberately *not*
computed by ncgen.
"""
from __future__ import annotations

import numpy as np

from ncgen.symbolic.coordinates import available_types, coordinate_type
from ncgen.symbolic.member import RigidMember

ALL_TYPES = available_types()            # [(dim, name), ...]
IDS = [f"{n}-{d}d" for d, n in ALL_TYPES]

# Ȳ with Y_type = Ȳ ⊗ I_3, printed in the seed for the 3D bodies and bars.
# Hand checks: row block 2 of Y_rrvw is [-1, 1, 0, 0] because u = r_j - r_i; row block 3 of
# Y_rrrw is [-1, 0, 1, 0] because v = r_k - r_i; the last row of Y_rrrr, w = r_l - r_i.
SEED_YBAR = {
    (3, "ruvw"): [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
    (3, "rrvw"): [[1, 0, 0, 0], [-1, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]],
    (3, "rrrw"): [[1, 0, 0, 0], [-1, 1, 0, 0], [-1, 0, 1, 0], [0, 0, 0, 1]],
    (3, "rrrr"): [[1, 0, 0, 0], [-1, 1, 0, 0], [-1, 0, 1, 0], [-1, 0, 0, 1]],
    (3, "ru"): [[1, 0], [0, 1]],
    (3, "rr"): [[1, 0], [-1, 1]],
}
# Not printed in the seed (it treats 3D only and no point members); implied by its
# definitions u = r_j - r_i, v = r_k - r_i applied in the plane, and q = r_i for a point.
IMPLIED_YBAR = {
    (2, "ruv"): [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
    (2, "rrv"): [[1, 0, 0], [-1, 1, 0], [0, 0, 1]],
    (2, "rrr"): [[1, 0, 0], [-1, 1, 0], [-1, 0, 1]],
    (2, "ru"): [[1, 0], [0, 1]],
    (2, "rr"): [[1, 0], [-1, 1]],
    (2, "r"): [[1]],
    (3, "r"): [[1]],
}
YBAR = {**SEED_YBAR, **IMPLIED_YBAR}


def seed_base_vectors(name: str, dim: int, q: np.ndarray) -> list[np.ndarray]:
    """[u, v, w][:k] from q by the seed's definitions (u = r_j - r_i if slot 1 is a point)."""
    slots = q.reshape(len(name), dim)
    return [slots[s] - slots[0] if ch == "r" else slots[s] for s, ch in enumerate(name[1:], 1)]


def seed_phi(name: str, dim: int, q: np.ndarray, Xbar: np.ndarray) -> np.ndarray:
    """The seed's intrinsic constraints (3D body order uu, vv, ww, vw, uw, uv; the planar
    analogue uu, vv, uv; a bar uu; none for a point)."""
    x = seed_base_vectors(name, dim, q)
    xb = [Xbar[:, s] for s in range(Xbar.shape[1])]
    pairs = {3: [(0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1)], 2: [(0, 0), (1, 1), (0, 1)],
             1: [(0, 0)], 0: []}[len(x)]
    return np.array([x[s] @ x[t] - xb[s] @ xb[t] for s, t in pairs])


def random_rotation(rng, dim: int = 3) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(dim, dim)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def random_inertia(rng) -> np.ndarray:
    """A physical 3D inertia tensor: principal second moments a, b, c > 0 give principal
    moments (b+c, a+c, a+b), which satisfy the triangle inequality; then rotated."""
    a, b, c = rng.uniform(0.05, 1.0, 3)
    Q = random_rotation(rng)
    return Q @ np.diag([b + c, a + c, a + b]) @ Q.T


def random_basis(rng, name: str, dim: int) -> list[np.ndarray]:
    """Slot values in the local frame: a random r̄_i and random, non-orthonormal, well
    conditioned base vectors (a point slot is r̄_i + x̄_s)."""
    rbar_i = rng.uniform(-1, 1, dim)
    X = rng.uniform(-1, 1, (dim, dim)) + 1.5 * np.eye(dim)
    return [rbar_i] + [rbar_i + X[:, s - 1] if ch == "r" else X[:, s - 1] for s, ch in enumerate(name[1:], 1)]


def random_member(rng, name: str, dim: int) -> tuple[RigidMember, object]:
    """A member of type (dim, name) with random mass, basis and inertia; returns
    ``(member, inertia)`` with the inertia as the user gave it (None for a point)."""
    ct = coordinate_type(name, dim)
    mass = rng.uniform(0.5, 2.0)
    if ct.kind == "body":
        inertia = random_inertia(rng) if dim == 3 else rng.uniform(0.1, 1.0)
        return RigidMember.body(ct, mass, inertia, basis=random_basis(rng, name, dim)), inertia
    if ct.kind == "bar":
        L = rng.uniform(0.5, 2.0)
        inertia = rng.uniform(0.02, 0.3)
        return RigidMember.bar(ct, mass, L, inertia=inertia, com=rng.uniform(0.1, 0.9) * L), inertia
    return RigidMember.point(ct, mass), None


def random_state(rng, member: RigidMember, omega_normal_to_axis: bool = False):
    """Random pose and twist ``(R, p, omega, v)`` (omega a scalar in 2D, None for a point);
    for a bar, ``omega_normal_to_axis`` removes the spin about its axis."""
    ct = member.ctype
    d = ct.dim
    R = random_rotation(rng, d)
    p, v = rng.normal(size=d), rng.normal(size=d)
    if ct.kind == "point":
        return np.eye(d), p, None, v
    if d == 2:
        return R, p, float(rng.normal()), v
    w = rng.normal(size=3)
    if ct.kind == "bar" and omega_normal_to_axis:
        w -= (w @ R[:, 0]) * R[:, 0]
    return R, p, w, v


def skew(w: np.ndarray) -> np.ndarray:
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def cross(omega, r: np.ndarray) -> np.ndarray:
    """ω × r, with a scalar ω in 2D."""
    if r.shape[0] == 2:
        return omega * np.array([-r[1], r[0]])
    return np.cross(omega, r)
