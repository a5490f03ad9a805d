"""A planar T-bar (Skelton's compressive unit): a horizontal member made of two struts meeting
at the centre node, a vertical member of two struts through the same node (a class-4 node),
and four cables from the horizontal member's ends to the vertical member's ends.  Run:
python examples/tensegrity_tbar.py

Nodes (m): ends 0 = (−L/2, 0) and 1 = (L/2, 0), tips 2 = (0, h/2) and 3 = (0, −h/2), centre
4 = (0, 0).  Node 0 is held, node 1 slides along x; a compressive load F pushes node 1
towards node 0.  Statics by hand with every cable at tension t (cable length ℓ = √(L² + h²)/2):
the horizontal struts carry F + t L / ℓ, the vertical ones t h / ℓ (compression).  The example
prints the self-stress analysis (one state, Calladine's count), the least-norm forces with
every cable at 10 N or more against that closed form, and the model realised with cables of
5000 N/m, whose equilibrium (Newton on natural coordinates) must come back to the shape.
"""
import numpy as np

import ncgen as nc
from ncgen.analysis.tensegrity_model import strut_forces

L, h, F, T_MIN, K = 1.0, 0.4, 50.0, 10.0, 5000.0
nodes = np.array([[-L / 2, 0], [L / 2, 0], [0, h / 2], [0, -h / 2], [0, 0]])
struts = [(0, 4), (4, 1), (2, 4), (4, 3)]
cables = [(0, 2), (0, 3), (1, 2), (1, 3)]
supports = {0: "xy", 1: "y"}
loads = np.zeros_like(nodes)
loads[1, 0] = -F

an = nc.self_stress(nodes, struts, cables, supports=supports)
print(an.table(), end="")
inv = nc.inverse_statics(nodes, struts, cables, loads, supports, cable_min=T_MIN)
ell = np.hypot(L, h) / 2
by_hand = np.array([F + T_MIN * L / ell] * 2 + [T_MIN * h / ell] * 2)
print(f"cables {inv.tensions.min():.6f}..{inv.tensions.max():.6f} N; struts (compression) "
      f"{np.round(-inv.strut_forces, 6)} N; by hand {np.round(by_hand, 6)} N; "
      f"largest difference {np.abs(-inv.strut_forces - by_hand).max():.2e} N")
stability, ev = an.prestress_stability(inv.forces)
print(f"reaction at node 0: {np.round(inv.reactions[0], 6)} N; {stability}")

model = nc.tensegrity_system(nodes, struts, cables, inv.rest_lengths(K)[:len(cables)], K, loads, supports).build()
guess = model.q0 + 1e-3 * np.random.default_rng(0).normal(size=model.nq)
eq = nc.equilibrium(model, guess)
X = np.array([[eq.coordinate(f"n{i}.r_i.{c}") for c in "xy"] for i in range(1, len(nodes))])
T = np.array([T for _, T, _, _ in eq.springs])
print(f"realised: shape within {np.abs(X - nodes[1:]).max():.2e} m, tensions within "
      f"{np.abs(T - inv.tensions).max():.2e} N, struts within "
      f"{np.abs(strut_forces(model, eq, nodes, struts, supports) - inv.strut_forces).max():.2e} N "
      f"of the design; {eq.stability}")
