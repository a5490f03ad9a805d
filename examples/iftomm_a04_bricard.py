"""Bricard's mechanism (IFToMM benchmark A04): five rods and six hinges in one closed loop,
overconstrained (Grübler's count gives no degree of freedom, the hinges' directions leave one).

Five rods of 1 m and 1 kg with a square cross-section of 0.1 m (moments m (L² + a²)/12 across,
m a²/6 along) run along edges of the unit cube, a closed path with the ground as the sixth
link; each hinge's axis is normal to the two rods it joins.  Gravity 9.81 N/kg along −y,
released at rest; the benchmark follows P3, the far end of rod 2 (starting at (1, −1, 0)):

    ground ─(0,0,0) y─ rod1 ─(1,0,0) z─ rod2 ─(1,−1,0) x─ rod3 ─(1,−1,1) y─ rod4 ─(0,−1,1) z─ rod5 ─(0,0,1) x─ ground

The loop's 6 × 5 hinge equations on the rods' 5 × 6 freedoms are dependent: ``build()`` finds
the implied ones and drops them (with a warning), leaving one degree of freedom.
Run:  python examples/iftomm_a04_bricard.py   (P3 over 10 s, energy drift)
"""
import warnings

import numpy as np

import ncgen as nc

MASS, LENGTH, SECTION, G = 1.0, 1.0, 0.1, 9.81
#: The loop's corners in order from the ground hinge at the origin, and each hinge's axis.
CORNERS = ((0, 0, 0), (1, 0, 0), (1, -1, 0), (1, -1, 1), (0, -1, 1), (0, 0, 1))
AXES = ((0, 1, 0), (0, 0, 1), (1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 0, 0))
#: P3: the second end of rod 2 in its body frame (x along the rod from its first end).
P3 = (LENGTH / 2, 0.0, 0.0)


def rod_inertia(mass=MASS, length=LENGTH, a=SECTION) -> np.ndarray:
    """Moments (kg m²) about the centre of a rod with a square section ``a`` (body x along it)."""
    return np.diag([mass * a * a / 6, mass * (length ** 2 + a * a) / 12, mass * (length ** 2 + a * a) / 12])


def frame_along(d) -> np.ndarray:
    """A rotation whose first column is the unit vector ``d``."""
    d = np.asarray(d, float)
    e = np.cross(d, [0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.cross(d, [1.0, 0.0, 0.0])
    e /= np.linalg.norm(e)
    return np.column_stack([d, e, np.cross(d, e)])


def bricard() -> nc.System:
    s = nc.System("iftomm_a04_bricard", gravity=(0.0, -G, 0.0))
    corners = [np.array(c, float) for c in CORNERS]
    rods = []
    for k in range(5):
        a, b = corners[k], corners[k + 1]
        rods.append(s.add_body(f"rod{k + 1}", mass=MASS, inertia=rod_inertia(), position=(a + b) / 2,
                               rotation=frame_along(b - a)))
    links = [s.ground, *rods, s.ground]
    for k in range(6):
        s.add_joint(nc.Revolute(links[k], links[k + 1], at=CORNERS[k], axis=AXES[k], name=f"hinge{k + 1}"))
    return s


def build():
    """The built model; the loop's implied hinge equations are dropped (their warning silenced)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", ".*dropping redundant constraints", UserWarning)
        return bricard().build()


if __name__ == "__main__":
    model = build()
    print(f"degrees of freedom: {model.dof}")
    traj = nc.simulate(model, t_end=10.0, dt=0.01, rtol=1e-10, atol=1e-12)
    p3 = traj.point("rod2", P3)
    for t in (0.0, 2.5, 5.0, 7.5, 10.0):
        print(f"t = {t:4.1f} s   P3 = {np.round(p3[int(round(t / 0.01))], 6)}")
    print(f"energy drift over 10 s: {np.ptp(traj.energy):.2e} J")
