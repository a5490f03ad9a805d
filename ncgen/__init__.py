"""ncgen: rigid multibody dynamics in natural coordinates.

SymPy derives every coordinate type's matrices (``ncgen.symbolic``); a ``System`` of
bodies, bars and points with joints and forces is assembled into CasADi functions
(``System.build()``), turned into C, simulated and optimised.
"""
from ncgen.assembly.kinematics import assemble, dof_report, project_velocity, solve_kinematics
from ncgen.codegen.model_package import generate
from ncgen.errors import NcgenError
from ncgen.model.contacts import Contact, SpherePlane, SphereSphere
from ncgen.model.forces import Force, GeneralizedForce, PointForce, Spring, Torque, TorsionalSpring
from ncgen.model.joints import (
    CoordinateDriver, Cylindrical, Distance, Fixed, Joint, Planar, PointOnLine, PointOnPlane, Prismatic,
    Revolute, Spherical, Universal,
)
from ncgen.model.members import ModelError
from ncgen.model.model import Model
from ncgen.model.system import System
from ncgen.optim import OptimalControl, OptimalTrajectory
from ncgen.runtime import Trajectory, simulate
from ncgen.symbolic.coordinates import coordinate_type

__version__ = "0.1.0"

__all__ = [
    "Contact", "CoordinateDriver", "Cylindrical", "Distance", "Fixed", "Force", "GeneralizedForce", "Joint", "Model",
    "ModelError", "NcgenError", "OptimalControl", "OptimalTrajectory", "Planar", "PointForce", "PointOnLine", "PointOnPlane", "Prismatic",
    "Revolute", "SpherePlane", "SphereSphere", "Spherical", "Spring", "System", "Torque", "TorsionalSpring", "Trajectory", "Universal",
    "assemble", "coordinate_type", "dof_report", "generate", "project_velocity", "simulate", "solve_kinematics",
    "__version__",
]
