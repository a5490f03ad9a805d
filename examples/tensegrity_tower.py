"""A two-stage tensegrity tower (two 3-strut prisms stacked ring on ring: a class-2
structure, each middle node ends two struts) standing on its three bottom nodes.  Run:
python examples/tensegrity_tower.py

Its states of self-stress and mechanisms; the stiffest prestress with cables between 10 and
60 N (IPOPT on the mechanisms' stiffness); the structure realised with cables of 5000 N/m and
loaded by 2 N down on each top node; each loaded equilibrium (Newton on natural coordinates)
checked against the equilibrium matrix of its own deformed shape, |A t − f|; the top's sag
for the least and for the stiffest prestress.
"""
import numpy as np

import ncgen as nc
from ncgen.analysis.tensegrity_model import strut_forces
from ncgen.analysis.tensegrity_shapes import stacked_prisms

nodes, struts, cables = stacked_prisms(3, stages=2, radius=0.3, height=0.5)
support = [0, 1, 2]
an = nc.self_stress(nodes, struts, cables, supports=support)
print(an.table(), end="")        # the 3 bottom cables join supports: each is a state of self-stress of its own

designs = {"least": nc.inverse_statics(nodes, struts, cables, supports=support, cable_min=10.0),
           "stiffest": nc.optimize_prestress(nodes, struts, cables, supports=support, cable_min=10.0,
                                             cable_max=60.0)}
loads = np.zeros_like(nodes)
loads[6:, 2] = -2.0
k = 5000.0
for name, d in designs.items():
    ev = an.prestress_stability(d.forces)[1]
    model = nc.tensegrity_system(nodes, struts, cables, d.rest_lengths(k)[:len(cables)], k, loads,
                                 support).build()
    eq = nc.equilibrium(model)
    X = nodes.copy()
    for i in range(3, len(nodes)):
        X[i] = [eq.coordinate(f"n{i}.r_i.{c}") for c in "xyz"]
    T = {n: T for n, T, _, _ in eq.springs}
    t = np.concatenate([[T.get(f"c{e}", 0.0) for e in range(len(cables))],
                        strut_forces(model, eq, X, struts, support)])
    deformed = nc.self_stress(X, struts, cables, supports=support)
    residual = np.abs(deformed.A @ t - loads[3:].reshape(-1)).max()
    print(f"{name:>8} prestress: cables {d.tensions.min():.4g}..{d.tensions.max():.4g} N, smallest mechanism "
          f"stiffness {ev.min():.4g} N/m; loaded: top sags {1e3 * (nodes[6:, 2] - X[6:, 2]).mean():.3f} mm, "
          f"|A t - f| = {residual:.1e} N, {eq.stability}")
