"""ncgen: rigid multibody dynamics in natural coordinates.

SymPy derives every coordinate type's matrices (``ncgen.symbolic``); a ``System`` of
bodies, bars and points with joints and forces is assembled into CasADi functions
(``System.build()``), turned into C, simulated and optimised.
"""
from ncgen.errors import NcgenError
from ncgen.model.forces import Force, PointForce, Spring, Torque
from ncgen.model.joints import Joint, Revolute, Spherical
from ncgen.model.members import ModelError
from ncgen.model.model import Model
from ncgen.model.system import System
from ncgen.symbolic.coordinates import coordinate_type

__version__ = "0.1.0"

__all__ = [
    "Force", "Joint", "Model", "ModelError", "NcgenError", "PointForce", "Revolute", "Spherical",
    "Spring", "System", "Torque", "coordinate_type", "__version__",
]
