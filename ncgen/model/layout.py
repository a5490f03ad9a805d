"""Global coordinate layout: which entries of the system vector ``q`` each member uses.

The system coordinates are *nodes*: basic points (shareable between members, or fixed to
the ground, in which case they are constants and not coordinates at all) and base vectors
(owned by one member).  Free nodes are numbered in the order members were added; a
member's local coordinates are ``q_I = S_I q + b_I`` where ``S_I`` selects its free nodes
and ``b_I`` holds its ground-fixed points.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.model.members import Member, NodeRef


@dataclass
class Node:
    """``dim`` coordinates: a basic point or a base vector."""

    name: str                      # e.g. "b1.r_j" (named after its first owner)
    is_point: bool
    fixed: np.ndarray | None = None  # world position of a ground-fixed point
    index: int = -1                 # first entry in q (free nodes only)
    owners: list = field(default_factory=list)   # (member name, slot)


@dataclass
class Layout:
    dim: int
    nodes: list[Node]
    slots: dict[str, list[int]]     # member name -> node index per slot
    nq: int

    def member_indices(self, name: str) -> list[int | None]:
        """Per local coordinate of member ``name``: its index in q, or None if fixed."""
        out = []
        for n in self.slots[name]:
            node = self.nodes[n]
            out += [None] * self.dim if node.fixed is not None else list(range(node.index, node.index + self.dim))
        return out

    def member_constant(self, name: str) -> np.ndarray:
        """``b_I``: the fixed part of member ``name``'s local coordinates (zeros elsewhere)."""
        parts = []
        for n in self.slots[name]:
            node = self.nodes[n]
            parts.append(node.fixed if node.fixed is not None else np.zeros(self.dim))
        return np.concatenate(parts) if parts else np.zeros(0)

    @property
    def coordinate_names(self) -> list[str]:
        names = [""] * self.nq
        for node in self.nodes:
            if node.fixed is None:
                for a in range(self.dim):
                    names[node.index + a] = f"{node.name}.{'xyz'[a]}"
        return names


def make_layout(dim: int, members: list[Member]) -> Layout:
    nodes: list[Node] = []
    slots: dict[str, list[int]] = {}
    ground_nodes: dict[tuple, int] = {}
    for m in members:
        ct = m.ctype
        idx = []
        for s, slot_name in enumerate(ct.slots):
            ref: NodeRef | None = m.shared.get(s)
            if ref is None:
                nodes.append(Node(f"{m.name}.{slot_name}", s in ct.point_slots))
                n = len(nodes) - 1
            elif ref.member.is_ground:
                key = tuple(np.round(ref.position, 12))
                if key not in ground_nodes:
                    nodes.append(Node(f"ground{list(ref.position)}", True, fixed=np.asarray(ref.position, float)))
                    ground_nodes[key] = len(nodes) - 1
                n = ground_nodes[key]
            else:
                n = slots[ref.member.name][ref.slot]
            nodes[n].owners.append((m.name, s))
            idx.append(n)
        slots[m.name] = idx
    nq = 0
    for node in nodes:
        if node.fixed is None:
            node.index = nq
            nq += dim
    return Layout(dim, nodes, slots, nq)
