"""The Unitree A1 quadruped (stock URDF of example-robot-data) landing on the floor and
standing on its own collision geometry, held by joint PD feedback on the nonsmooth stepper.

``nc.System.from_urdf(..., floating_base=True, collisions={"mu": 0.8})`` turns every
``<collision>`` box, cylinder and sphere of the moving links into a contact with the floor:
22 elements, 148 contact points (trunk and IMU boxes, hip and shoulder cylinders, thigh and
calf boxes, the four foot spheres of radius 0.02 m); all of them are kept, none filtered.

The floor is the plane z = −``FLOOR`` (m; 0: the world's z = 0).  The URDF's zero
configuration (base at the origin, legs straight down, feet 0.42 m below it) reaches through
it; ``build()`` checks the contacts' gaps where the run starts, in the initial joint state.  The
robot starts with the base at z = ``DROP`` (m), so that the feet are
``CLEARANCE`` above the floor, in the standing posture ``STAND`` (hips 0, thighs 0.8 rad,
calves −1.6 rad) at rest.  A joint PD law ``τ = K_p (q* − q_j) − K_d q̇_j`` (a Python feedback
``u(t, qj, vj)``, held over each 1 ms output interval) holds the posture: the robot falls
5 mm, lands on its feet, sags where the PD torques carry the weight and stands for the rest
of ``T`` = 2 s.

Checks (tests/test_quadruped_standing.py, slow): after settling, with the last torques held
open loop for ``HOLD`` s (:func:`held`), the feet's normal forces sum to m g (m from the URDF's ``<inertial>`` masses) within 1 %; no contact penetrates more than
1e-6 m; the work of the contacts (normal, friction, push-out) never adds energy; the base
height equals what the measured joint angles give through the legs' kinematics, read from
the URDF's joint origins, with the feet's spheres on the floor (1e-3 m).

Needs the robots extra:  pip install 'ncgen[robots]'
Run:  python examples/quadruped_standing.py   (writes quadruped_standing.png and .html)
"""
import numpy as np

import ncgen as nc

FLOOR, CLEARANCE, T, DT, HOLD = 0.0, 0.005, 2.0, 1e-3, 0.1
THIGH, CALF, FOOT_RADIUS = 0.8, -1.6, 0.02          # rad, rad, m (the A1's foot spheres)
LEG = 0.2                                            # m: thigh and calf lengths of the A1
KP, KD = 80.0, 4.0                                   # N·m/rad, N·m·s/rad
LEGS = ("FR", "FL", "RR", "RL")
STAND = {f"{leg}_{j}_joint": a for leg in LEGS for j, a in (("hip", 0.0), ("thigh", THIGH), ("calf", CALF))}
#: base height (m, world z) at which the feet of the standing posture are CLEARANCE above the floor
DROP = -FLOOR + 2 * LEG * np.cos(THIGH) + FOOT_RADIUS + CLEARANCE


def build():
    """The A1 with its collision geometry against the floor z = −FLOOR, standing posture."""
    s = nc.System.from_urdf(nc.robots.urdf_path("a1"), floating_base=True, collisions={"mu": 0.8})
    for c in s.contacts:                           # the floor through (0, 0, −FLOOR)
        c.point = np.array([0.0, 0.0, -FLOOR])
        c.check(s)
    s.initial_joints = {**STAND, "root": [0.0, 0.0, DROP, 0.0, 0.0, 0.0, 1.0]}
    return s.build(contacts="nonsmooth")


def pd(model):
    """The joint PD feedback ``u(t, qj, vj)`` towards ``STAND`` (actuated joints, in order)."""
    target = np.array([STAND[name] for name in model.joint_names[1:]])

    def u(t, qj, vj):
        return KP * (target - qj[7:]) - KD * vj[6:]
    return u


def run(model):
    return nc.simulate(model, T, DT, u=pd(model), method="stepper")


def held(model, traj, duration=HOLD):
    """The run continued open loop from its last state for ``duration`` (s), the last PD
    torques held: a still posture under constant torques, whose feet must carry m g."""
    return nc.simulate(model, duration, DT, q0=traj.q[-1], v0=traj.v[-1], u=traj.u[-1], method="stepper")


if __name__ == "__main__":
    import matplotlib.pyplot as plt

    model = build()
    traj = run(model)
    print(traj.summary())
    rest = held(model, traj)
    feet = [i for i, name in enumerate(rest.contact_names) if "foot" in name]
    support = rest.contact_normal[1:, feet].sum(axis=1)
    print(f"held {HOLD:g} s more: feet carry {support.min():.4f} ... {support.max():.4f} N; "
          f"base {traj.qj[-1, 2] + FLOOR:.5f} m above the floor; "
          f"deepest penetration {max(0.0, -traj.gap.min()):.2e} m")

    fig, ax = plt.subplots(1, 3, figsize=(14, 4), layout="constrained")
    ax[0].plot(traj.t, traj.qj[:, 2] + FLOOR)
    ax[0].set(xlabel="t (s)", ylabel="base height above the floor (m)", title="A1 landing and standing")
    ax[1].plot(T + rest.t[1:], support)
    ax[1].set(xlabel="t (s)", ylabel="sum of the feet's normal forces (N)", title="support (torques held)")
    for name in model.joint_names[1:4]:
        ax[2].plot(traj.t, traj.joint(name)[0], label=name)
    ax[2].set(xlabel="t (s)", ylabel="joint angle (rad)", title="front right leg (PD held)")
    ax[2].legend(fontsize=7)
    fig.savefig("quadruped_standing.png", dpi=100)
    traj.to_html("quadruped_standing.html")
    print("wrote quadruped_standing.png, quadruped_standing.html")
