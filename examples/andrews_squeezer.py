"""Andrews' squeezing mechanism (IFToMM benchmark A03; Hairer & Wanner, Solving ODEs II,
§VII.7; the "andrews" problem of the Test Set for IVP solvers, Mazzia et al.) in natural
coordinates.

Seven planar bodies, no gravity, driven by a constant torque (0.033 N·m) on the crank and
pulled by a spring (4530 N/m, rest length 0.07785 m) from a fixed point C to the triangle.
The published model writes it in seven relative angles β, Θ, γ, Φ, δ, Ω, ε; here every
body is a planar ``ruv`` body at its absolute angle (crank β, rod β + Θ, triangle γ,
links Φ + δ, δ, Ω + ε, ε), hinged as in the paper's figure:

    O = (0, 0) ─ crank ─ F ─ rod ─ E ─┬─ triangle ─ B (ground)         D on the triangle ─ spring ─ C
                                      ├─ link 4 ─ G ─ link 5 ─ A (ground)
                                      └─ link 6 ─ H ─ link 7 ─ A (ground)

Ten hinges (twenty equations) on seven bodies leave one degree of freedom.  Released at
rest from the published consistent initial angles; :func:`angles` reads the seven angles
of the published coordinates back from a trajectory.
Run:  python examples/andrews_squeezer.py   (prints the angles at t = 0.03 s)
"""
import numpy as np

import ncgen as nc

#: Hairer & Wanner's data (SI units): masses (kg), moments about the centres of mass (kg m²).
MASS = (0.04325, 0.00365, 0.02373, 0.00706, 0.07050, 0.00706, 0.05498)
INERTIA = (2.194e-6, 4.410e-7, 5.255e-6, 5.667e-7, 1.169e-5, 5.667e-7, 1.912e-5)
XA, YA, XB, YB, XC, YC = -0.06934, -0.00227, -0.03635, 0.03273, 0.014, 0.072
D, DA, E, EA = 28e-3, 115e-4, 2e-2, 1421e-5
RR, RA = 7e-3, 92e-5
SS, SA, SB, SC, SD = 35e-3, 1874e-5, 1043e-5, 18e-3, 2e-2
TA, TB = 2308e-5, 916e-5
U, UA, UB = 4e-2, 1228e-5, 449e-5
ZF, ZT, FA = 2e-2, 4e-2, 1421e-5
TORQUE, C0, L0 = 0.033, 4530.0, 0.07785
#: The published consistent initial angles β, Θ, γ, Φ, δ, Ω, ε (rad); at rest.
ANGLES0 = (-0.0617138900142764496358948458001, 0.0, 0.455279819163070380255912382449,
           0.222668390165885884674473185609, 0.487364979543842550225598953530,
           -0.222668390165885884674473185609, 1.23054744454982119249735015568)
BODIES = ("crank", "rod", "triangle", "link4", "link5", "link6", "link7")


def _e(a):
    return np.array([np.cos(a), np.sin(a)])


def _n(a):
    """The unit vector (sin a, −cos a): ``_e(a)`` turned by −90°."""
    return np.array([np.sin(a), -np.cos(a)])


def body_angles(beta, theta, gamma, phi, delta, omega, epsilon):
    """The seven bodies' absolute angles (rad) from the published relative ones."""
    return (beta, beta + theta, gamma, phi + delta, delta, omega + epsilon, epsilon)


def squeezer(torque=TORQUE) -> nc.System:
    """The mechanism at the published initial angles, at rest (an ``nc.System``)."""
    beta, theta, gamma, phi, delta, omega, epsilon = ANGLES0
    O, A, B, C = np.zeros(2), np.array([XA, YA]), np.array([XB, YB]), np.array([XC, YC])
    F = RR * _e(beta)
    E_ = F - D * _e(beta + theta)
    G = A + ZT * _e(delta)
    H = A + U * _n(epsilon)
    Dp = B + SD * _e(gamma) + SC * _n(gamma)
    # centres of mass: on the published distances from each body's pivot (the squeezer has
    # no gravity, so only the distance enters the motion of a body turning about a fixed pivot)
    com = (RA * _e(beta), F - DA * _e(beta + theta), B + SA * _n(gamma) + SB * _e(gamma),
           G + (E - EA) * _n(phi + delta), A + TA * _e(delta) + TB * _n(delta),
           H + (ZF - FA) * _e(omega + epsilon), A + UA * _n(epsilon) + UB * _e(epsilon))
    s = nc.System("andrews_squeezer", gravity=(0.0, 0.0))
    b = [s.add_body(name, "ruv", mass=m, inertia=i, position=c, rotation=a)
         for name, m, i, c, a in zip(BODIES, MASS, INERTIA, com, body_angles(*ANGLES0))]
    crank, rod, triangle, link4, link5, link6, link7 = b
    for name, (p, q), at in (("O", (s.ground, crank), O), ("F", (crank, rod), F), ("B", (s.ground, triangle), B),
                             ("E3", (rod, triangle), E_), ("E4", (rod, link4), E_), ("E6", (rod, link6), E_),
                             ("A5", (s.ground, link5), A), ("G", (link5, link4), G),
                             ("A7", (s.ground, link7), A), ("H", (link7, link6), H)):
        s.add_joint(nc.Revolute(p, q, at=tuple(at), name=name))
    R3 = np.array([[np.cos(gamma), -np.sin(gamma)], [np.sin(gamma), np.cos(gamma)]])
    s.add_force(nc.Spring(triangle, tuple(R3.T @ (Dp - com[2])), s.ground, tuple(C), k=C0, rest_length=L0,
                          name="spring"))
    s.add_force(nc.Torque(crank, torque, name="drive"))
    return s


def angles(traj) -> np.ndarray:
    """``(n_t, 7)``: β, Θ, γ, Φ, δ, Ω, ε (rad) of a trajectory of :func:`squeezer`, each
    absolute angle unwrapped over the outputs (so the output step must be short enough that a
    body turns by less than π between outputs)."""
    R, _ = traj.poses()
    names = list(traj.model.member_names)
    a = np.column_stack([np.unwrap(np.arctan2(R[:, names.index(n), 1, 0], R[:, names.index(n), 0, 0]))
                         for n in BODIES])
    a += np.round((np.array(body_angles(*ANGLES0)) - a[0]) / (2 * np.pi)) * 2 * np.pi
    beta, rod, gamma, link4, delta, link6, epsilon = a.T
    return np.column_stack([beta, rod - beta, gamma, link4 - delta, delta, link6 - epsilon, epsilon])


if __name__ == "__main__":
    model = squeezer().build()
    traj = nc.simulate(model, t_end=0.03, dt=1e-4, rtol=1e-12, atol=1e-14)
    for name, value in zip(("beta", "Theta", "gamma", "Phi", "delta", "Omega", "epsilon"), angles(traj)[-1]):
        print(f"{name:8s} {value: .12f} rad")
