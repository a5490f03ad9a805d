"""Teaching output: the rigid-motion algebra, step by step (``ncgen derive se3``).

Every matrix shown is computed by :mod:`ncgen.symbolic.rigid_motion` or
:mod:`ncgen.symbolic.spatial_inertia` on symbolic arguments, and every identity the prose
states (``H H⁻¹ = 1``, ``d/dt Ad = Ad ad``, the Newton–Euler bias at the centre of mass...)
is checked symbolically while the report is built; a failed check raises
:class:`IdentityError`.  The prose only explains.
"""
from __future__ import annotations

import sympy as sp

from ncgen.symbolic import rigid_motion as rm
from ncgen.symbolic import spatial_inertia as si
from ncgen.symbolic.report import Report

_t = sp.Symbol("t", real=True)


class IdentityError(RuntimeError):
    """An identity the report states does not hold for the formulas (a bug)."""


def _check_zero(what: str, expr) -> None:
    """Symbolic check of an identity that holds given ``sin² + cos² = 1``: every ``cos(u)`` is
    replaced by ``√(1 − sin²(u))`` and the result must expand to zero."""
    circle = sp.Matrix(expr).replace(lambda e: isinstance(e, sp.cos),
                                     lambda e: sp.sqrt(1 - sp.sin(e.args[0]) ** 2))
    if not sp.expand(circle).is_zero_matrix:
        raise IdentityError(f"se3 report: {what} does not hold")


def _check_small(what: str, expr: sp.Matrix) -> None:
    """Numeric check of an identity at a sample point (``expr`` evaluates to numbers)."""
    if max(abs(complex(e)) for e in sp.Matrix(expr).evalf()) > 1e-12:
        raise IdentityError(f"se3 report: {what} does not hold")


def _vec(name: str, parts=("x", "y", "z")) -> sp.Matrix:
    return sp.Matrix([sp.Symbol(f"{name}_{c}", real=True) for c in parts])


def _rotation_symbols() -> sp.Matrix:
    return sp.Matrix(3, 3, lambda i, j: sp.Symbol(f"r_{i + 1}{j + 1}", real=True))


def _rotations(rep: Report) -> None:
    a, az, ay, ax = sp.symbols("alpha a_z a_y a_x", real=True)
    st = rep.step(
        "Rotations",
        "A rotation matrix $R_{ab}$ has as columns the unit vectors of frame $b$ in the "
        "coordinates of frame $a$. Elementary rotations about the axes, and the yaw-pitch-roll "
        "composition $R = R_z(a_z) R_y(a_y) R_x(a_x)$ (yaw, pitch, roll about the moving axes z, y', x'').")
    st.eq(r"R_x(\alpha)", rm.rotx(a)).eq(r"R_y(\alpha)", rm.roty(a)).eq(r"R_z(\alpha)", rm.rotz(a))
    R = rm.rotzyx(az, ay, ax)
    st.eq(r"R_z(a_z) R_y(a_y) R_x(a_x)", R)
    angles = rm.zyx_angles(_rotation_symbols())
    _check_small("zyx_angles(rotzyx(a_z, a_y, a_x)) = (a_z, a_y, a_x) at a sample point",
                angles.subs(dict(zip(_rotation_symbols(), R))).subs({az: 0.3, ay: -0.4, ax: 1.1}).evalf()
                - sp.Matrix([0.3, -0.4, 1.1]))
    st = rep.step(
        "Angles from a rotation",
        "Inverse of the composition, read from the last row and the first two rows of "
        "$R = [r_{ij}]$: $a_y \\in [-\\pi/2, \\pi/2]$. At gimbal lock ($\\cos a_y = 0$) only "
        "$a_z - a_x$ (or $a_z + a_x$) is defined: $a_x$ is set to 0 and $a_z$ carries the whole "
        "rotation about the vertical. $a_z$ is computed from $R R_x(a_x)^T = R_z(a_z) R_y(a_y)$, so "
        "the angles always reproduce $R$.")
    st.eq("a_x", angles[2]).eq("a_y", angles[1]).eq("a_z", angles[0].xreplace({angles[2]: ax}))


def _poses(rep: Report) -> None:
    R, p, x = _rotation_symbols(), _vec("p"), _vec("x")
    H = rm.homogeneous(R, p)
    st = rep.step(
        "Poses: homogeneous matrices",
        "The pose of frame $b$ relative to frame $a$ is $H_{ab}$; $p_{ab}$ is the origin of $b$ "
        "in $a$. Points transform as $x_a = R_{ab} x_b + p_{ab}$ and the inverse pose uses "
        "$R^{-1} = R^T$.")
    st.eq("H_{ab}", H).eq("H_{ba} = H_{ab}^{-1}", rm.inverse(H))
    st.eq("x_a", rm.transform_point(H, x))
    H_sample = rm.homogeneous(rm.rotzyx(*sp.symbols("a_z a_y a_x", real=True)), p)
    _check_zero("H^-1 H = 1", rm.inverse(H_sample) * H_sample - sp.eye(4))


def _twists(rep: Report) -> None:
    w, v = _vec("omega"), _vec("v")
    T = w.col_join(v)
    st = rep.step(
        "Twists",
        "A twist $T = [\\omega; v]$ stacks an angular velocity and a linear velocity. The hat "
        "operator makes $\\hat\\omega x = \\omega \\times x$; in se(3) a twist is a 4x4 matrix.")
    st.eq(r"\hat{\omega}", rm.so3_hat(w)).eq(r"\hat{T}", rm.se3_hat(T))
    H = _moving_frame()
    body = (rm.inverse(H) * H.diff(_t)).applyfunc(sp.trigsimp)
    st = rep.step(
        "Body twist",
        "The body twist $T_b$ of frame $b$ relative to $a$ is expressed in $b$: "
        "$\\hat{T}_b = H_{ab}^{-1} \\dot{H}_{ab}$, so $\\omega$ is the angular velocity of $b$ "
        "and $v = R^T \\dot{p}$ the velocity of its origin, both in $b$'s axes. Example: a frame "
        "turning about z while its origin moves.")
    st.eq("H_{ab}(t)", H).eq(r"H_{ab}^{-1} \dot{H}_{ab}", body)


def _moving_frame():
    """``H_ab(t)``: a frame turning about z by θ(t) while its origin follows p(t)."""
    theta = sp.Function("theta", real=True)(_t)
    p_t = sp.Matrix([sp.Function(f"p_{c}", real=True)(_t) for c in "xyz"])
    return rm.homogeneous(rm.rotz(theta), p_t)


def _adjoints(rep: Report) -> None:
    w, v, p = _vec("omega"), _vec("v"), _vec("p")
    H_z = rm.homogeneous(rm.rotz(sp.Symbol("alpha", real=True)), p)
    st = rep.step(
        "Adjoint and adjacency",
        "$\\mathrm{Ad}(H_{ab}) = [[R, 0], [\\hat{p} R, R]]$ changes the frame a twist is expressed in: "
        "$T_a = \\mathrm{Ad}(H_{ab}) T_b$, and $\\mathrm{Ad}(H_{ab})^{-1} = \\mathrm{Ad}(H_{ba})$ "
        "(shown for a rotation about z). The adjacency $\\mathrm{ad}(T)$ is the derivative of the "
        "adjoint at the identity: $\\mathrm{ad}(T_1) T_2$ is the Lie bracket of two twists.")
    st.eq(r"\mathrm{Ad}(H_{ab})", rm.Ad(H_z))
    st.eq(r"\mathrm{Ad}(H_{ab})^{-1}", rm.Ad_inv(H_z).applyfunc(sp.trigsimp))
    _check_zero("Ad(H) Ad(H)^-1 = 1", rm.Ad(H_z) * rm.Ad_inv(H_z) - sp.eye(6))
    st.eq(r"\mathrm{ad}(T)", rm.ad(w.col_join(v)))
    H = _moving_frame()
    T_b = rm.se3_vee(rm.inverse(H) * H.diff(_t)).applyfunc(sp.trigsimp)
    _check_zero("d/dt Ad(H_ab) = Ad(H_ab) ad(T_b)", rm.Ad(H).diff(_t) - rm.Ad_dot(H, T_b))
    st = rep.step(
        "Derivative of the adjoint",
        "Differentiating $\\mathrm{Ad}(H_{ab})$ with $\\dot{R} = R \\hat{\\omega}$ and "
        "$\\dot{p} = R v$, where $T_b = [\\omega; v]$ is the body twist of $b$ relative to $a$, gives "
        "$\\frac{d}{dt} \\mathrm{Ad}(H_{ab}) = \\mathrm{Ad}(H_{ab})\\, \\mathrm{ad}(T_b)$. Checked "
        "symbolically on the moving frame of the body-twist step; its lower-left block is shown "
        "(the diagonal blocks are $\\dot{R}$, the upper-right block is zero).")
    st.eq("T_b", T_b)
    st.eq(r"\frac{d}{dt}(\hat{p} R)", lhs_text="d/dt (p̂ R)", rhs=rm.Ad_dot(H, T_b)[3:, :3].applyfunc(sp.trigsimp))


def _closed_form(expr, x_sq):
    """``expr`` with ``max(x_sq, SERIES_THRESHOLD)`` shown as ``x_sq`` (its value wherever the
    closed-form branch is selected)."""
    return expr.replace(lambda e: isinstance(e, sp.Max), lambda e: x_sq)


def _exponential(rep: Report) -> None:
    theta = sp.Symbol("theta", positive=True)
    st = rep.step(
        "Exponential",
        "$\\exp(\\hat{T})$ is the pose reached in unit time with the constant body twist "
        "$T = [\\omega; v]$. With $\\theta = |\\omega|$: "
        "$R = 1 + a(\\theta) \\hat{\\omega} + b(\\theta) \\hat{\\omega}^2$ (Rodrigues) and $p = V v$ with "
        "$V = 1 + b(\\theta) \\hat{\\omega} + c(\\theta) \\hat{\\omega}^2$. Each coefficient is "
        "a Taylor polynomial in $\\theta^2$ below $\\theta^2 = 10^{-4}$ (derived with sympy.series; "
        "the closed forms lose digits there) and the closed form above, evaluated at "
        "$\\max(\\theta^2, 10^{-4})$ so that neither branch is ever NaN (shown here as $\\theta^2$, "
        "its value wherever that branch is selected). Example: the screw motion about z.")
    for name, lhs, text in (("sinc", r"a(\theta) = \frac{\sin\theta}{\theta}", "a(θ) = sin θ / θ"),
                            ("cosc", r"b(\theta) = \frac{1 - \cos\theta}{\theta^2}", "b(θ) = (1 − cos θ) / θ²"),
                            ("sinc3", r"c(\theta) = \frac{\theta - \sin\theta}{\theta^3}", "c(θ) = (θ − sin θ) / θ³")):
        st.eq(lhs, _closed_form(rm.coefficient(name, theta ** 2), theta ** 2), lhs_text=text)
    v = _vec("v")
    screw = rm.exp_se3(sp.Matrix([0, 0, theta, *v])).subs(theta ** 2 < rm.SERIES_THRESHOLD, False)
    st.eq(r"\exp(\widehat{[0, 0, \theta, v_x, v_y, v_z]})", sp.simplify(_closed_form(screw, theta ** 2)),
          lhs_text="exp([0, 0, θ, v_x, v_y, v_z]^)")


def _logarithm(rep: Report) -> None:
    theta, s = sp.Symbol("theta", positive=True), sp.Symbol("s", positive=True)
    st = rep.step(
        "Logarithm",
        "Inverse of the exponential with $|\\omega| = \\theta \\in [0, \\pi]$. With "
        "$\\cos\\theta = (\\mathrm{tr} R - 1)/2$ and $a = (R - R^T)^\\vee / 2 = \\sin\\theta\\, u$ "
        "($u$ the unit axis): for $\\theta \\le \\pi/2$, $\\omega = (\\theta / \\sin\\theta)\\, a$, "
        "the factor being $\\arcsin(s)/s$ at $s = |a|$, a Taylor polynomial in $s^2$ near 0; for "
        "$\\theta > \\pi/2$, where $a$ vanishes at $\\pi$, the axis is read from the column of "
        "largest diagonal entry of $(R + R^T)/2 - \\cos\\theta\\, 1 = (1 - \\cos\\theta)\\, u u^T$, "
        "oriented so that $u \\cdot a \\ge 0$, and $\\theta = \\mathrm{atan2}(u \\cdot a, \\cos\\theta)$. "
        "Then $v = V^{-1} p$ with $V^{-1} = 1 - \\hat{\\omega}/2 + d(\\theta)\\, \\hat{\\omega}^2$.")
    st.eq(r"\frac{\arcsin s}{s}", lhs_text="arcsin(s) / s", rhs=rm.taylor_in_square("asinc", s ** 2) + sp.O(s ** (2 * rm.SERIES_TERMS)))
    st.eq(r"d(\theta) = \frac{1 - (\theta/2)\cot(\theta/2)}{\theta^2}",
          _closed_form(rm.coefficient("dlog", theta ** 2), theta ** 2), lhs_text="d(θ) = (1 − (θ/2) cot(θ/2)) / θ²")
    w = sp.Matrix([0, 0, theta])
    p = _vec("p")
    H = rm.exp_se3(w.col_join(rm.log_se3_translation(w, rm.rotz(theta), p)))
    _check_small("exp(log(H)) = H for a rotation about z",
                H.subs(theta, sp.Rational(7, 5)).evalf() - rm.homogeneous(rm.rotz(sp.Rational(7, 5)), p).evalf())


def _wrenches(rep: Report) -> None:
    f, x = _vec("f"), _vec("x")
    st = rep.step(
        "Wrenches",
        "A wrench $W = [\\tau; f]$ stacks a moment and a force. It changes frame with the "
        "transposed adjoint, $W_b = \\mathrm{Ad}(H_{ab})^T W_a$, so that the power $W^T T$ is the "
        "same in every frame: $W_b^T T_b = W_a^T \\mathrm{Ad}(H_{ab}) T_b = W_a^T T_a$. Example: a "
        "pure force $f$ applied at the point $x$ of frame $b$ is the wrench $[0; f]$ at a frame "
        "located at $x$; moved to $b$'s origin ($H$ the translation by $-x$) it gains the moment "
        "$x \\times f$.")
    st.eq(r"\mathrm{Ad}(H_{ab})^T [0; f]", rm.transport_wrench(rm.translation(-x), sp.zeros(3, 1).col_join(f)))


def _mass(rep: Report) -> None:
    m = sp.Symbol("m", positive=True)
    r = _vec("r")
    I_c = sp.Matrix(3, 3, lambda i, j: sp.Symbol(f"I_{min(i, j) + 1}{max(i, j) + 1}", real=True))
    st = rep.step(
        "Spatial mass matrix",
        "At a frame whose origin sees the centre of mass at $r$, the kinetic energy is "
        "$T^T M T / 2$ with $M = [[I_o, m \\hat{r}], [m \\hat{r}^T, m 1]]$ and $I_o$ the inertia "
        "about the origin (parallel axes: $I_o = I_c + m \\hat{r}^T \\hat{r}$). Invariance of the "
        "energy under $T_a = \\mathrm{Ad}(H_{ab}) T_b$ gives the transport "
        "$M_b = \\mathrm{Ad}(H_{ab})^T M_a \\mathrm{Ad}(H_{ab})$: here from the centre of mass "
        "(frame a) to a frame b at $-r$.")
    st.eq("I_o", si.inertia_about_point(m, r, I_c))
    M_b = si.mass_matrix(m, r, si.inertia_about_point(m, r, I_c))
    M_c = si.mass_matrix(m, sp.zeros(3, 1), I_c)
    _check_zero("transport of the centre-of-mass matrix", si.transport_mass_matrix(M_c, rm.translation(-r)) - M_b)
    I_o = sp.Matrix(3, 3, lambda i, j: sp.Symbol(f"I_o{min(i, j) + 1}{max(i, j) + 1}", real=True))
    st.eq("M", si.mass_matrix(m, r, I_o))
    a, b, c, l, rho = sp.symbols("a b c l rho", positive=True)
    st = rep.step(
        "Homogeneous solids",
        "Inertia tensors $I = \\mathrm{tr}(S)\\, 1 - S$ from the second moments $S = \\int x x^T dm$, "
        "integrated over a box of half extents $(a, b, c)$, a cylinder of radius $\\rho$ and length "
        "$l$ along z, and an ellipsoid of semi-axes $(a, b, c)$ (the unit ball, integrated in "
        "spherical coordinates, stretched by diag(a, b, c)); a ball is an ellipsoid with equal axes.")
    st.eq(r"I_{\mathrm{box}}", si.box((a, b, c), m)[:3, :3])
    st.eq(r"I_{\mathrm{cylinder}}", si.cylinder(l, rho, m)[:3, :3])
    st.eq(r"I_{\mathrm{ellipsoid}}", si.ellipsoid((a, b, c), m)[:3, :3])
    st.eq(r"I_{\mathrm{ball}}", si.sphere(rho, m)[:3, :3])


def _newton_euler(rep: Report) -> None:
    m = sp.Symbol("m", positive=True)
    w, v = _vec("omega"), _vec("v")
    T = w.col_join(v)
    I = sp.diag(*sp.symbols("I_1 I_2 I_3", positive=True))
    M = si.mass_matrix(m, sp.zeros(3, 1), I)
    bias = si.newton_euler_bias(M, T)
    N = sp.diag(rm.so3_hat(w) * I, m * rm.so3_hat(w))
    _check_zero("bias = [[w^ I, 0], [0, m w^]] T at the centre of mass", bias - N * T)
    st = rep.step(
        "Newton-Euler equations",
        "The momentum $h_b = M_b T_b$ of a body, expressed in the inertial frame g, is "
        "$h_g = \\mathrm{Ad}(H_{gb})^{-T} h_b$ and changes by the applied wrench: "
        "$\\dot{h}_g = \\mathrm{Ad}(H_{gb})^{-T} W_b$. From "
        "$\\frac{d}{dt}\\mathrm{Ad}^{-T} = -\\mathrm{Ad}^{-T} \\mathrm{ad}(T_b)^T$ (previous steps): "
        "$M_b \\dot{T}_b - \\mathrm{ad}(T_b)^T M_b T_b = W_b$, in body coordinates, for any "
        "body frame. At the centre of mass, with principal axes, the bias "
        "$-\\mathrm{ad}(T)^T M T$ is Euler's gyroscopic moment and the transport term of the "
        "linear momentum; in block form the equations read "
        "$[[I, 0], [0, m 1]] \\dot{T} + [[\\hat{\\omega} I, 0], [0, m \\hat{\\omega}]] T = W$ "
        "(the seed's block matrix, corrected).")
    st.eq(r"-\mathrm{ad}(T)^T M T", bias)
    st.eq(r"\begin{bmatrix} \hat{\omega} I & 0 \\ 0 & m \hat{\omega} \end{bmatrix}", N,
          lhs_text="[[ω̂ I, 0], [0, m ω̂]]")


def se3_report() -> Report:
    """The rigid-motion algebra (arboris conventions) as a teaching report."""
    rep = Report(
        "Rigid motion: poses, twists, wrenches and the Newton-Euler equations",
        "Conventions of arboris-python: $H_{ab} = [[R_{ab}, p_{ab}], [0, 1]]$ is the pose of frame "
        "$b$ relative to frame $a$; twists are $[\\omega; v]$, wrenches $[\\tau; f]$. Every formula "
        "below is the SymPy expression ncgen evaluates (NumPy, CasADi and C are generated from it).")
    _rotations(rep)
    _poses(rep)
    _twists(rep)
    _adjoints(rep)
    _exponential(rep)
    _logarithm(rep)
    _wrenches(rep)
    _mass(rep)
    _newton_euler(rep)
    return rep
