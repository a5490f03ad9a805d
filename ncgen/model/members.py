"""Members of a system: bodies, bars, points and the ground.

A member couples a :class:`~ncgen.symbolic.member.RigidMember` (local description) with
its initial pose and twist in the world, its named body-fixed points (markers) and the
basic points it shares with other members or with the ground.

Frames: a body's local frame has its origin at the centre of mass and the axes of the
``rotation`` given by the user; a bar's has its origin at the centre of mass and x̄ from
its first end to its second; a point's is the world frame translated to the point; the
ground's is the world frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ncgen.errors import BasisError, ModelError, NcgenError
from ncgen.reproducible import matvec
from ncgen.symbolic.coordinates import CoordinateType
from ncgen.symbolic.member import RigidMember
from ncgen.validation import as_vector
from ncgen.validation import name as valid_name


def model_name(value, what: str) -> str:
    """``value`` checked by the one naming rule (:func:`ncgen.validation.name`), as a ModelError."""
    try:
        return valid_name(value, what)
    except NcgenError as e:
        raise ModelError(str(e)) from None


@dataclass(frozen=True)
class NodeRef:
    """A basic point that members can share: slot ``slot`` of ``member``, or a fixed point
    of the ground at ``position``."""

    member: "Member | Ground"
    slot: int
    position: tuple

    @property
    def label(self) -> str:
        if self.member.is_ground:
            return f"ground point {tuple(round(x, 12) for x in self.position)}"
        return f"{self.member.name}.{self.member.ctype.slots[self.slot]}"


class Ground:
    """The fixed world; ``point(position)`` is a fixed basic point members can share."""

    is_ground = True
    name = "ground"

    def __init__(self, dim: int):
        self.dim = dim

    def point(self, position) -> NodeRef:
        p = as_vector(position, self.dim, "ground point position")
        return NodeRef(self, -1, tuple(float(x) for x in p))

    def to_local(self, world) -> np.ndarray:
        return np.asarray(world, dtype=float)

    def direction_to_local(self, world) -> np.ndarray:
        return np.asarray(world, dtype=float)

    def __repr__(self) -> str:
        return "Ground()"


class Member:
    """A member of a :class:`~ncgen.model.system.System` (create it with ``add_body``,
    ``add_bar`` or ``add_point``)."""

    is_ground = False

    def __init__(self, name: str, rigid: RigidMember, R0, p0, omega0, v0, shared: dict[int, NodeRef]):
        self.name = name
        self.rigid = rigid          # the member's constant description (mass, frame, derivation)
        self.ctype: CoordinateType = rigid.ctype
        self.R0 = R0
        self.p0 = np.asarray(p0, dtype=float)
        self.omega0 = omega0
        self.v0 = np.asarray(v0, dtype=float)
        self.shared = dict(shared)
        self.markers: dict[str, np.ndarray] = {}
        self.spec: dict = {}     # the arguments it was created with (System.add_*), for to_toml
        #: what the viewers draw (:mod:`ncgen.model.shapes`); None: a shape from the inertia
        self.shape = None
        self.q0 = rigid.q_from_pose(R0, p0)
        self.qd0 = rigid.qd_from_twist(R0, p0, omega0, v0)

    @property
    def kind(self) -> str:
        return self.ctype.kind

    @property
    def dim(self) -> int:
        return self.ctype.dim

    # --------------------------------------------------------------- geometry
    def to_local(self, world) -> np.ndarray:
        """Local coordinates of a world point in the initial configuration."""
        w = as_vector(world, self.dim, f"{self.name}: world point")
        R = np.eye(self.dim) if self.R0 is None else self.R0
        return matvec(R.T, w - self.p0)

    def direction_to_local(self, world) -> np.ndarray:
        w = as_vector(world, self.dim, f"{self.name}: world direction")
        R = np.eye(self.dim) if self.R0 is None else self.R0
        return matvec(R.T, w)

    def slot_position(self, slot: int) -> np.ndarray:
        """Initial world position of basic point ``slot``."""
        d = self.dim
        return self.q0[slot * d:(slot + 1) * d].copy()

    def node(self, slot: int | str) -> NodeRef:
        """The basic point ``slot`` (index or name such as ``"r_j"``) as a shareable node."""
        ct = self.ctype
        if isinstance(slot, str):
            if slot not in ct.slots:
                raise ModelError(f"{self.name}: no slot {slot!r}; a {ct.name} member has {', '.join(ct.slots)}")
            slot = ct.slots.index(slot)
        if slot not in ct.point_slots:
            raise ModelError(f"{self.name}: slot {ct.slots[slot] if 0 <= slot < len(ct.slots) else slot!r} "
                             f"of a {ct.name} member is not a basic point; basic points: "
                             f"{', '.join(ct.slots[s] for s in ct.point_slots)}")
        return NodeRef(self, slot, tuple(float(x) for x in self.slot_position(slot)))

    def end(self, i: int) -> NodeRef:
        """End ``i`` (0 or 1) of a bar as a shareable node (only an ``rr`` bar's second end
        is a basic point)."""
        if self.kind != "bar":
            raise ModelError(f"{self.name}: end() is for bars; use node(slot) on a {self.kind}")
        if i not in (0, 1):
            raise ModelError(f"{self.name}: a bar has ends 0 and 1, got {i!r}")
        if i == 1 and self.ctype.name != "rr":
            raise ModelError(f"{self.name}: the second end of an '{self.ctype.name}' bar is not a basic "
                             "point, so it cannot be shared; use coords='rr' or a Spherical joint")
        return self.node(i)

    def add_marker(self, name: str, local) -> "Member":
        """Name a body-fixed point (local coordinates) for outputs, e.g. ``traj.point``."""
        model_name(name, f"{self.name}: marker name")
        if name in self.markers:
            raise ModelError(f"{self.name}: marker {name!r} already defined")
        point = as_vector(local, self.dim, f"{self.name}.{name}: local point")
        try:
            self.rigid.affine(point)
        except BasisError as e:
            raise ModelError(f"marker {self.name}.{name} ({self.ctype.name} {self.kind}): {e}") from None
        self.markers[name] = point
        return self

    def set_shape(self, shape) -> "Member":
        """Draw this member as ``shape`` (``nc.Box``, ``nc.Cylinder``, ``nc.Sphere``, ...,
        :mod:`ncgen.model.shapes`), in its local frame; None: the default."""
        from ncgen.model.shapes import check_shape
        self.shape = check_shape(shape, f"{self.kind} {self.name!r}")
        self.spec["shape"] = self.shape
        return self

    def __repr__(self) -> str:
        return f"<{self.kind} {self.name!r} ({self.ctype.name}, {self.dim}D)>"
