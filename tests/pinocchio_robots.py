"""Shared helpers of the tests against Pinocchio on example-robot-data's URDFs: the robot
files, both engines' models and the maps between their joint vectors.

Pinocchio builds the URDF as shipped with its ``<mimic>`` joints (``mimic=True``: a follower
has no coordinate of its own, like ncgen's independent rates) and, for the algorithms it does
not support with mimic joints (ABA, the derivatives), without them: then ncgen's quantities
are the projections ``Gᵀ (·) G`` of Pinocchio's on the independent rates (``v = G v_i``)."""
from __future__ import annotations

import importlib.metadata as md
import re
from functools import cache
from pathlib import Path

import numpy as np
import pytest

pin = pytest.importorskip("pinocchio")

ROBOTS = {
    "panda": ("panda_description/urdf/panda.urdf", False),
    "ur5": ("ur_description/urdf/ur5_robot.urdf", False),
    "solo12": ("solo_description/robots/solo12.urdf", True),
    "talos": ("talos_data/robots/talos_reduced.urdf", True),
    "so101": ("so_arm_description/urdf/so101.urdf", False),
}


def robot_file(rel: str) -> Path:
    try:
        files = md.files("example-robot-data") or []
    except md.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    for f in files:
        if str(f).endswith(rel):
            return Path(f.locate())
    pytest.skip(f"example-robot-data has no {rel}")


def ident(s: str) -> str:
    return re.sub(r"\W", "_", s)


@cache
def urdf_text(name: str) -> str:
    return robot_file(ROBOTS[name][0]).read_text()


@cache
def pinocchio_models(name: str):
    """``(with mimic joints, without)``: Pinocchio models of the URDF as shipped."""
    text, floating = urdf_text(name), ROBOTS[name][1]
    args = (pin.JointModelFreeFlyer(),) if floating else ()
    return pin.buildModelFromXML(text, *args, mimic=True), pin.buildModelFromXML(text, *args)


class JointMap:
    """Maps between ncgen's joint vectors (``model.joint_names`` order) and Pinocchio's
    model without mimic joints (every joint its own coordinate)."""

    def __init__(self, model, pm):
        js = model.joint_space
        self.sq, self.sv = js.slices(), js.slices(rates=True)
        self.nq, self.nv = js.nq, js.nv
        self.joints = []
        for jid in range(1, pm.njoints):
            jm = pm.joints[jid]
            n = "root" if jm.shortname() == "JointModelFreeFlyer" else ident(pm.names[jid])
            self.joints.append((n, jm))
        assert sorted(n for n, _ in self.joints) == sorted(model.joint_names)
        self.P = np.zeros((pm.nv, js.nv))           # v_pin = P v_j
        for n, jm in self.joints:
            s = self.sv[n]
            self.P[jm.idx_v:jm.idx_v + jm.nv, s.start:s.stop] = np.eye(jm.nv)

    def q_to_ncgen(self, qp):
        qj = np.zeros(self.nq)
        for n, jm in self.joints:
            qj[self.sq[n]] = qp[jm.idx_q:jm.idx_q + jm.nq]
        return qj

    def q_to_pin(self, qj, nq_pin):
        qp = np.zeros(nq_pin)
        for n, jm in self.joints:
            qp[jm.idx_q:jm.idx_q + jm.nq] = qj[self.sq[n]]
        return qp


def random_configuration(pm, rng, bound: float = 1.5) -> np.ndarray:
    """A random configuration of Pinocchio model ``pm`` from NumPy's ``rng`` (joint values in
    ``[−bound, bound]``, a free flyer's position too and a uniform unit quaternion) — not
    ``pinocchio.randomConfiguration``, whose global generator other tests' states depend on."""
    q = pin.neutral(pm)
    for jid in range(1, pm.njoints):
        jm = pm.joints[jid]
        if jm.shortname() == "JointModelFreeFlyer":
            quat = rng.normal(size=4)
            q[jm.idx_q:jm.idx_q + 7] = np.concatenate([rng.uniform(-bound, bound, 3), quat / np.linalg.norm(quat)])
        elif jm.nq == 1:
            q[jm.idx_q] = rng.uniform(-bound, bound)
        elif jm.nq:
            raise NotImplementedError(f"random_configuration: joint {pm.names[jid]} ({jm.shortname()})")
    return q
