"""Rigid-motion algebra (arboris conventions), in every form ncgen uses; the formulas live once,
in SymPy (:mod:`ncgen.symbolic.rigid_motion`, :mod:`ncgen.symbolic.spatial_inertia`).

- :mod:`ncgen.rigid_motion.numeric` — NumPy functions with input validation (re-exported
  here: ``ncgen.rigid_motion.exp_se3``, ...);
- :mod:`ncgen.rigid_motion.casadi_forms` — CasADi SX functions of the same formulas;
- their C package: :func:`ncgen.codegen.rigid_motion_package.write_c_package`;
- :mod:`ncgen.rigid_motion.natural` — natural coordinates ↔ pose, twist, mass matrix, wrench.

Conventions: ``H_ab = [[R_ab, p_ab], [0, 1]]`` pose of frame b in frame a; twists ``[ω; v]``;
wrenches ``[τ; f]``; ``T_a = Ad(H_ab) T_b``; ``W_b = Ad(H_ab)ᵀ W_a``.  SI units.
"""
from ncgen.rigid_motion.numeric import (
    C_CORE, INERTIA_TOLERANCE, ROTATION_TOLERANCE, Ad, Ad_dot, Ad_inv, ad, box, check_homogeneous,
    check_mass_matrix, check_rotation, check_vector, cylinder, ellipsoid, exp_se3, exp_so3, homogeneous,
    inertia_about_point, inertia_from_second_moment, inverse, log_se3, log_so3, mass_matrix, mass_matrix_parts,
    newton_euler_acceleration, newton_euler_bias, power, principal_frame, rotx, roty, rotz, rotzyx, se3_hat,
    se3_vee, so3_hat, so3_vee, sphere, transform_point, transform_vector, translation, transport_mass_matrix,
    transport_twist, transport_wrench, zyx_angles,
)

__all__ = [
    "C_CORE", "INERTIA_TOLERANCE", "ROTATION_TOLERANCE", "Ad", "Ad_dot", "Ad_inv", "ad", "box", "check_homogeneous",
    "check_mass_matrix", "check_rotation", "check_vector", "cylinder", "ellipsoid", "exp_se3", "exp_so3",
    "homogeneous", "inertia_about_point", "inertia_from_second_moment", "inverse", "log_se3", "log_so3",
    "mass_matrix", "mass_matrix_parts", "newton_euler_acceleration", "newton_euler_bias", "power",
    "principal_frame", "rotx", "roty", "rotz", "rotzyx", "se3_hat", "se3_vee", "so3_hat", "so3_vee", "sphere",
    "transform_point", "transform_vector", "translation", "transport_mass_matrix", "transport_twist",
    "transport_wrench", "zyx_angles",
]
