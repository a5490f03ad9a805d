"""Names of the parts of a member's natural coordinates (the seed's notation)."""

POINT_NAMES = "ijkl"   # basic points r_i, r_j, r_k, r_l by slot
VECTOR_NAMES = "uvw"   # base vectors x_1, x_2, x_3
AXES = "xyz"
