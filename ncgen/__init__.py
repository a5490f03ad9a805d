"""ncgen: rigid multibody dynamics in natural coordinates.

SymPy derives every coordinate type's matrices (``ncgen.symbolic``); a ``System`` of
bodies, bars and points with joints and forces is assembled into CasADi functions
(``System.build()``), turned into C, simulated and optimised.
"""
from ncgen import viz  # nc.viz.plot, nc.viz.animate (cheap: matplotlib loads on use)
from ncgen import robots  # nc.robots.urdf_path("panda"): example-robot-data's URDFs
from ncgen.assembly.kinematics import assemble, dof_report, project_velocity, solve_kinematics
from ncgen.codegen.model_package import generate
from ncgen.control import MPC, StepDidNotConverge, StepFunction, export_mpc, ilqr, step_function
from ncgen.errors import NcgenError
from ncgen.model.contacts import (BoxBox, BoxPlane, CapsulePlane, Contact, CylinderPlane, SphereBox, SpherePlane,
                                  SphereSphere)
from ncgen.model.controllers import PD, ComputedTorque, Controller
from ncgen.model.forces import Force, GeneralizedForce, PointForce, Spring, Torque, TorsionalSpring
from ncgen.model.joints import (
    CoordinateDriver, Cylindrical, Distance, Fixed, Free, Joint, Mimic, Planar, PointOnLine, PointOnPlane, Prismatic,
    Revolute, Spherical, Universal,
)
from ncgen.errors import ModelError
from ncgen.model.model import Model
from ncgen.model.shapes import Box, Capsule, Cylinder, Ellipsoid, Mesh, Shape, Sphere
from ncgen.model.system import System
from ncgen.optim import OptimalControl, OptimalTrajectory
from ncgen.runtime import SimulationOptions, Trajectory, simulate
from ncgen.runtime.batch import BatchResult, simulate_batch
from ncgen.runtime.samples import Samples
from ncgen.runtime.sweep import SweepResult, open_sweep, sweep
from ncgen.analysis.formfinding import Tensegrity, form_find
from ncgen.analysis.linearization import LinearModel, linearize
from ncgen.analysis.modes import Modes, modes
from ncgen.analysis.statics import Equilibrium, equilibrium
from ncgen.runtime.joint_dynamics import forward_dynamics, forward_dynamics_kernel, inverse_dynamics
from ncgen.runtime.tree_algorithms import aba, aba_derivatives, algorithm_kernel, crba, rnea, rnea_derivatives
from ncgen.runtime.tree_kernel import joint_forward_dynamics, joint_forward_dynamics_kernel
from ncgen.analysis.reactions import JointReaction, joint_reactions
from ncgen.symbolic.coordinates import coordinate_type
from ncgen.version import __version__


__all__ = [
    "BatchResult", "Box", "BoxBox", "BoxPlane", "Capsule", "CapsulePlane", "ComputedTorque", "Contact", "Controller", "CoordinateDriver", "Cylinder", "CylinderPlane", "Ellipsoid", "Mesh", "Shape", "Sphere", "Cylindrical", "Distance", "Equilibrium", "Fixed", "Force", "Free", "GeneralizedForce",
    "Joint", "JointReaction", "LinearModel", "MPC", "Mimic", "Model", "ModelError", "Modes", "NcgenError", "OptimalControl",
    "OptimalTrajectory", "PD", "Planar", "PointForce", "PointOnLine", "PointOnPlane", "Prismatic", "Revolute", "Samples", "SimulationOptions", "SphereBox", "SpherePlane", "SphereSphere", "Spherical",
    "Spring", "StepDidNotConverge", "StepFunction", "SweepResult", "System", "Tensegrity", "Torque", "TorsionalSpring", "Trajectory", "Universal",
    "assemble", "coordinate_type", "dof_report", "equilibrium", "export_mpc", "form_find", "forward_dynamics",
    "forward_dynamics_kernel", "generate", "ilqr", "inverse_dynamics", "joint_forward_dynamics",
    "joint_forward_dynamics_kernel", "joint_reactions", "linearize", "modes", "open_sweep",
    "aba", "aba_derivatives", "algorithm_kernel", "crba", "rnea", "rnea_derivatives",
    "project_velocity", "simulate", "simulate_batch", "solve_kinematics", "step_function", "sweep",
    "__version__", "robots", "viz",
]
