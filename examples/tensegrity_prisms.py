"""Snelson's prisms (3 and 4 struts): self-stress, mechanisms, inverse statics, prestress
optimisation, and the realised structure checked by ncgen's own statics.  Run:
python examples/tensegrity_prisms.py

For each prism at its equilibrium twist (90° + 180°/n between a strut's ends): the states of
self-stress and infinitesimal mechanisms (Calladine's rule), the force densities against
the closed form 1 : 2 sin(π/n) : −2 sin(π/n), the least prestress with every cable at
10 N or more, the rest lengths that give it with cables of 2000 N/m, the prestress that
makes the mechanisms stiffest with no cable above 50 N, and the model built from those
rest lengths, whose equilibrium (Newton on natural coordinates) must be the same shape.
"""
import numpy as np

import ncgen as nc
from ncgen.analysis.tensegrity_shapes import prism

for n in (3, 4):
    nodes, struts, cables = prism(n, radius=0.3, height=0.5)
    an = nc.self_stress(nodes, struts, cables)
    print(f"--- {n}-strut prism")
    print(an.table(), end="")
    q = an.self_stresses[:, 0] / an.framework.lengths()
    print(f"force densities ring : vertical : strut = 1 : {q[2 * n] / q[0]:.6f} : {q[3 * n] / q[0]:.6f} "
          f"(closed form 2 sin(pi/n) = {2 * np.sin(np.pi / n):.6f})")

    inv = nc.inverse_statics(nodes, struts, cables, cable_min=10.0)
    stability, ev = an.prestress_stability(inv.forces)
    print(f"least prestress: cables {inv.tensions.min():.4g}..{inv.tensions.max():.4g} N, struts "
          f"{inv.strut_forces.min():.4g} N; {stability} (mechanism stiffness {ev.min():.4g} N/m)")
    k = 2000.0
    l0 = inv.rest_lengths(k)[:len(cables)]
    print("rest lengths (m):", np.array2string(l0, precision=5))

    best = nc.optimize_prestress(nodes, struts, cables, cable_min=10.0, cable_max=50.0)
    print(f"stiffest prestress with cables <= 50 N: mechanism stiffness {best.min_stiffness:.4g} N/m "
          f"(largest cable {best.max_cable:.4g} N, {best.iterations} IPOPT iterations)")

    model = nc.tensegrity_system(nodes, struts, cables, l0, k, supports={0: "xyz", 1: "xyz", 2: "z"}).build()
    guess = model.q0 + 1e-3 * np.random.default_rng(0).normal(size=model.nq)
    eq = nc.equilibrium(model, guess)
    T = np.array([T for _, T, _, _ in eq.springs])            # cable 0 joins two supports: not modelled
    design = inv.tensions[[int(name[1:]) for name, *_ in eq.springs]]
    X = np.array([[eq.coordinate(f"n{i}.r_i.{c}") for c in "xyz"] for i in range(2, len(nodes))])
    print(f"realised: back to the shape within {np.abs(X - nodes[2:]).max():.1e} m, tensions within "
          f"{np.abs(T - design).max():.1e} N of the design; {eq.stability}")
