"""A rigid-body tensegrity: two bodies held by cables alone (a "tensegrity table").  Run:
python examples/tensegrity_bodies.py

The lower body is a triangle on the floor with a hook rising to 0.6 m; the upper body an
inverted copy, its triangle at 0.8 m and its hook hanging down to 0.2 m, below the lower
hook.  A central cable joins the hooks (it holds the upper body up); three outer cables join
the triangles' corners (they hold it down).  Its self-stress (the central cable carries
three times an outer one), mechanisms (the bodies' relative sway and twist) and their
stiffness under the least prestress with cables of at least 5 N; the structure realised as
two 3D bodies with cables of 5000 N/m and ncgen's own statics back at the design.
"""
import numpy as np

import ncgen as nc


def table(radius: float = 0.3):
    """``(nodes, cables, bodies)``: nodes 0-2 the lower triangle, 3 its hook; 4-6 the upper
    triangle, 7 its hook; cable 0 the central one, 1-3 the outer ones."""
    a = 2 * np.pi * np.arange(3) / 3
    ring = np.column_stack([radius * np.cos(a), radius * np.sin(a), np.zeros(3)])
    nodes = np.vstack([ring, [[0, 0, 0.6]], ring + [0, 0, 0.8], [[0, 0, 0.2]]])
    cables = [(3, 7), (0, 4), (1, 5), (2, 6)]
    return nodes, cables, [[0, 1, 2, 3], [4, 5, 6, 7]]


if __name__ == "__main__":
    nodes, cables, bodies = table()
    an = nc.self_stress(nodes, [], cables, bodies=bodies)
    print(an.table(), end="")
    inv = nc.inverse_statics(nodes, [], cables, cable_min=5.0, bodies=bodies)
    print(f"tensions: central {inv.tensions[0]:.6g} N, outer {np.round(inv.tensions[1:], 6)} N "
          f"(ratio {inv.tensions[0] / inv.tensions[1]:.6f}, by hand 3)")
    stability, ev = an.prestress_stability(inv.forces)
    print(f"prestress stability: {stability}; mechanism stiffnesses {np.round(ev, 4)} (N/m, N·m)")
    k = 5000.0
    model = nc.tensegrity_system(nodes, [], cables, inv.rest_lengths(k), k, bodies=bodies).build()
    eq = nc.equilibrium(model)
    T = np.array([t for _, t, _, _ in eq.springs])
    print(f"realised: back at the design within {np.abs(eq.q - model.q0).max():.1e} m, "
          f"tensions within {np.abs(T - inv.tensions).max():.1e} N; {eq.stability}")
