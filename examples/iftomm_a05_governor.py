"""The stiff flyball governor (IFToMM benchmark A05; González, Dopico, Lugrís, Cuadrado 2006).

A vertical shaft turns freely about z on the ground; a sleeve slides along it; two rods hinge
at the shaft's top, 0.05 m either side of its axis, about axes normal to the plane of the
shaft and the rod, and each carries a 5 kg point mass at its far end.  The links a Watt
governor has between the rods and the sleeve are replaced by two stiff spring-dampers from
the sleeve (0.05 m off the axis) to the rods' middles.  Data of the benchmark as the MBS-BOS
OpenSim model (RehabEngGroup/MBSbenchmarksInOpenSim) gives them:

* shaft and rods 1.0 × 0.01 × 0.01 m, sleeve 0.1 m cube, density 3000 kg/m³ (0.3 kg, 3 kg);
* spring-dampers k = 8e5 N/m, c = 4e4 N s/m, rest length 0.5 m;
* start: sleeve at s = 0.5 m, rods 30° below the horizontal (α), so each spring is at its
  rest length (the hinge, the sleeve's point and the rod's middle form an equilateral
  triangle of side 0.5 m), everything turning at ω = 2π rad/s about z; gravity 9.81 along −z.

The benchmark follows s, the sleeve's height.  Run:  python examples/iftomm_a05_governor.py
"""
import numpy as np

import ncgen as nc

G = 9.81
DENSITY, ROD_LENGTH, SECTION, CUBE = 3000.0, 1.0, 0.01, 0.1
ROD_MASS = DENSITY * ROD_LENGTH * SECTION ** 2            # 0.3 kg: shaft and rods
SLEEVE_MASS = DENSITY * CUBE ** 3                         # 3 kg
BALL_MASS = 5.0
K, C, REST = 8e5, 4e4, 0.5
#: Hinges' offset from the axis (m), the shaft's top (m), the rods' angle below the horizontal
#: (rad), the sleeve's start height s (m), the spin (rad/s).
OFFSET, TOP, ALPHA, S0, SPIN = 0.05, 1.0, np.radians(30.0), 0.5, 2 * np.pi


def rod_inertia(mass: float = ROD_MASS) -> np.ndarray:
    """Moments (kg m²) about the centre of a square-section rod, body x along it."""
    along = mass * 2 * SECTION ** 2 / 12
    across = mass * (ROD_LENGTH ** 2 + SECTION ** 2) / 12
    return np.diag([along, across, across])


def governor(spin: float = SPIN) -> nc.System:
    """The A05 system; rods ``rod1`` (on +x) and ``rod2`` (on −x), point masses ``ball1``,
    ``ball2``, sleeve ``sleeve``, shaft ``shaft``."""
    s = nc.System("iftomm_a05_governor", gravity=(0.0, 0.0, -G))
    w = np.array([0.0, 0.0, spin])

    def moving(p):
        return dict(velocity=np.cross(w, p), angular_velocity=w)

    shaft_c = np.array([0.0, 0.0, TOP / 2])
    shaft = s.add_body("shaft", mass=ROD_MASS, inertia=rod_inertia()[[1, 2, 0]][:, [1, 2, 0]],
                       position=shaft_c, **moving(shaft_c))
    s.add_joint(nc.Revolute(s.ground, shaft, at=(0, 0, 0), axis=(0, 0, 1), name="spin"))
    sleeve_c = np.array([0.0, 0.0, S0])
    sleeve = s.add_body("sleeve", mass=SLEEVE_MASS, inertia=SLEEVE_MASS * CUBE ** 2 / 6 * np.eye(3),
                        position=sleeve_c, **moving(sleeve_c))
    s.add_joint(nc.Prismatic(shaft, sleeve, at=sleeve_c, axis=(0, 0, 1), name="slide"))
    for k, side in ((1, 1.0), (2, -1.0)):
        hinge = np.array([side * OFFSET, 0.0, TOP])
        d = np.array([side * np.cos(ALPHA), 0.0, -np.sin(ALPHA)])
        R = np.column_stack([d, [0.0, 1.0, 0.0], np.cross(d, [0.0, 1.0, 0.0])])
        centre = hinge + ROD_LENGTH / 2 * d
        rod = s.add_body(f"rod{k}", mass=ROD_MASS, inertia=rod_inertia(), position=centre, rotation=R,
                         **moving(centre))
        s.add_joint(nc.Revolute(shaft, rod, at=hinge, axis=(0, 1, 0), name=f"hinge{k}"))
        end = hinge + ROD_LENGTH * d
        ball = s.add_point(f"ball{k}", mass=BALL_MASS, position=end, velocity=np.cross(w, end))
        s.add_joint(nc.Spherical(rod, ball, at=end, name=f"weld{k}"))
        s.add_force(nc.Spring(sleeve, (side * OFFSET, 0.0, 0.0), rod, (0.0, 0.0, 0.0), k=K, rest_length=REST,
                              damping=C, name=f"spring{k}"))
    return s


def sleeve_height(traj) -> np.ndarray:
    """s (m) per output: the sleeve's centre's height."""
    return traj.point("sleeve", (0.0, 0.0, 0.0))[:, 2]


if __name__ == "__main__":
    model = governor().build()
    print(f"degrees of freedom: {model.dof}")
    traj = nc.simulate(model, t_end=2.0, dt=0.01, rtol=1e-10, atol=1e-12)
    s = sleeve_height(traj)
    for t in (0.0, 0.5, 1.0, 1.5, 2.0):
        print(f"t = {t:3.1f} s   s = {s[int(round(t / 0.01))]:.9f} m")
    balance = traj.info.get("energy", {})
    print(f"energy change {traj.energy[-1] - traj.energy[0]:.6e} J, dampers' work "
          f"{balance.get('parts', {}).get('dampers', float('nan')):.6e} J")
