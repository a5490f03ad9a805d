"""ncgen: rigid multibody dynamics in natural coordinates.

SymPy derives every coordinate type's matrices (``ncgen.symbolic``); a ``System`` of
bodies, bars and points with joints and forces is assembled into CasADi functions
(``System.build()``), turned into C, simulated and optimised.

``import ncgen`` is cheap: every public name is imported from its module on first use
(PEP 562), so that a command or script loads only the layers it needs (no SymPy, SciPy or
matplotlib until something asks for them).
"""
from __future__ import annotations

import importlib

from ncgen.errors import ModelError, NcgenError
from ncgen.version import __version__

#: Where each public name lives: module -> names (``nc.robots`` and ``nc.viz`` are modules).
_HOMES: dict[str, tuple[str, ...]] = {
    "ncgen.analysis.formfinding": ("Tensegrity", "form_find"),
    "ncgen.analysis.inverse_statics": ("InverseStatics", "inverse_statics"),
    "ncgen.analysis.linearization": ("LinearModel", "linearize"),
    "ncgen.analysis.modes": ("Modes", "modes"),
    "ncgen.analysis.prestress": ("PrestressDesign", "optimize_prestress"),
    "ncgen.analysis.reactions": ("JointReaction", "joint_reactions"),
    "ncgen.analysis.self_stress": ("SelfStress", "self_stress"),
    "ncgen.analysis.statics": ("Equilibrium", "equilibrium"),
    "ncgen.analysis.tensegrity_model": ("tensegrity_system",),
    "ncgen.assembly.kinematics": ("assemble", "dof_report", "project_velocity", "solve_kinematics"),
    "ncgen.codegen.model_package": ("generate",),
    "ncgen.control": ("MPC", "StepDidNotConverge", "StepFunction", "export_mpc", "ilqr", "step_function"),
    "ncgen.control.joint_mpc": ("JointMPC",),
    "ncgen.control.joint_step": ("JointStep",),
    "ncgen.model.cables": ("ClusteredCable",),
    "ncgen.model.capstan": ("CapstanCable", "add_capstan_cable"),
    "ncgen.model.capsule_contacts": ("CapsuleBox", "CapsuleCapsule", "CapsuleSphere", "CylinderSphere"),
    "ncgen.model.contact_pairs": ("contact_between",),
    "ncgen.model.contacts": ("BoxBox", "BoxPlane", "CapsulePlane", "Contact", "CylinderPlane", "MeshPlane",
                             "SphereBox", "SpherePlane", "SphereSphere"),
    "ncgen.model.controllers": ("ComputedTorque", "Controller", "PD"),
    "ncgen.model.forces": ("Force", "GeneralizedForce", "PointForce", "Spring", "Torque", "TorsionalSpring"),
    "ncgen.model.joints": ("CoordinateDriver", "Cylindrical", "Distance", "Fixed", "Free", "Joint", "JointSequence",
                           "Mimic", "Planar", "PointOnLine", "PointOnPlane", "Prismatic", "Revolute", "Spherical",
                           "Universal"),
    "ncgen.model.model": ("Model",),
    "ncgen.model.rolling": ("KnifeEdge", "RollingDisc", "RollingSphere"),
    "ncgen.model.shapes": ("Box", "Capsule", "Cylinder", "Ellipsoid", "Mesh", "Shape", "Sphere"),
    "ncgen.model.system": ("System",),
    "ncgen.optim": ("OptimalControl", "OptimalTrajectory"),
    "ncgen.runtime": ("SimulationOptions", "Trajectory", "simulate"),
    "ncgen.runtime.batch": ("BatchResult", "simulate_batch"),
    "ncgen.runtime.dynamics_at_state": ("forward_dynamics", "forward_dynamics_kernel", "inverse_dynamics"),
    "ncgen.runtime.samples": ("Samples",),
    "ncgen.runtime.sweep": ("SweepResult", "open_sweep", "sweep"),
    "ncgen.runtime.tree_algorithm_kernels": ("aba", "aba_derivatives", "algorithm_kernel", "algorithm_kernels", "crba",
                                      "rnea", "rnea_derivatives"),
    "ncgen.runtime.tree_kernel": ("joint_forward_dynamics", "joint_forward_dynamics_kernel"),
    "ncgen.symbolic.coordinates": ("coordinate_type",),
}
_MODULES = ("robots", "viz")
_HOME = {name: module for module, names in _HOMES.items() for name in names}

__all__ = sorted([*_HOME, *_MODULES, "ModelError", "NcgenError", "__version__"])


def __getattr__(name: str):
    """A public name, imported from its module on first use and kept (PEP 562)."""
    if name in _MODULES:
        value = importlib.import_module(f"ncgen.{name}")
    elif name in _HOME:
        value = getattr(importlib.import_module(_HOME[name]), name)
    else:
        raise AttributeError(f"module 'ncgen' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
