"""Teaching output: the derivation of one natural-coordinate type, step by step.

:func:`coordinates_report` walks through a :class:`~ncgen.symbolic.coordinates.Derivation`
in the seed's order and notation.  Every matrix or formula shown is an object of the
derivation, or a factorisation of one that is checked when the report is built (for example
``Y = Ȳ ⊗ I_d``: ``Ȳ`` is read off ``Y`` and the Kronecker product is compared with ``Y``).
Block formulas are obtained the same way: ``u = r_j − r_i`` is read off ``Y``, the blocks of
``Φ_q`` off ``Φ_q``, and the block form of ``Φ`` is expanded and compared with ``Φ``.
The prose only explains.
"""
from __future__ import annotations

import sympy as sp
from sympy.matrices.expressions.kronecker import KroneckerProduct

from ncgen.symbolic.notation import VECTOR_NAMES
from ncgen.symbolic.report import Report

#: Expanded formulas with more terms than this per entry are described, not printed.
MAX_TERMS = 16


class FactorisationError(RuntimeError):
    """A derived matrix does not have the block structure the report displays (a bug)."""


# ----------------------------------------------------------------------------- helpers
def _is_zero(A: sp.Matrix) -> bool:
    return all(sp.expand(e) == 0 for e in A)


def kron_factor(A: sp.Matrix, d: int) -> sp.Matrix:
    """The small matrix ``Ā`` with ``A = Ā ⊗ I_d`` (read off ``A`` and checked)."""
    n, m = A.shape
    if n % d or m % d:
        raise FactorisationError(f"a {n}x{m} matrix is not a Kronecker product with I_{d}")
    Abar = sp.Matrix(n // d, m // d, lambda a, b: A[a * d, b * d])
    if not _is_zero(sp.kronecker_product(Abar, sp.eye(d)) - A):
        raise FactorisationError(f"the {n}x{m} matrix is not of the form Ā ⊗ I_{d}")
    return Abar


def _eye(d: int) -> sp.MatrixSymbol:
    return sp.MatrixSymbol(f"I_{d}", d, d)


def _kron(Abar: sp.Matrix, d: int) -> KroneckerProduct:
    return KroneckerProduct(sp.ImmutableMatrix(Abar), _eye(d))


def _block(name: str, d: int) -> sp.MatrixSymbol:
    return sp.MatrixSymbol(name, d, 1)


def _combination(coeffs, blocks, shape):
    """``Σ coeffs[s] blocks[s]`` as a matrix expression (a zero block if all vanish)."""
    terms = [c * b for c, b in zip(coeffs, blocks) if c != 0]
    if not terms:
        return sp.ZeroMatrix(*shape)
    return terms[0] if len(terms) == 1 else sp.MatAdd(*terms)


def _vector_blocks(ct):
    """Block symbols of the base vectors ``x_s`` and of their local values ``x̄_s``."""
    d = ct.dim
    return ([_block(VECTOR_NAMES[s], d) for s in range(ct.k)],
            [_block(f"{VECTOR_NAMES[s]}bar", d) for s in range(ct.k)])


def _reference_name(ct) -> str:
    """The seed's first type, to which ``Y`` converts: ``ruvw`` in 3D, ``ruv`` in 2D."""
    return "r" + VECTOR_NAMES[:ct.dim]


def _terms(M) -> int:
    return max((len(sp.Add.make_args(sp.expand(e))) for e in M), default=0)


def phi_q_blocks(ct, D) -> sp.BlockMatrix:
    """``Φ_q`` in ``1×d`` blocks, each a combination ``Σ a_s x_sᵀ`` of base vectors.

    Read off the derived ``Φ_q``: substitute ``q = Y⁻¹ q_ref`` (``q_ref = [r_i; x_1; ...]``),
    take the coefficients of the first component of each ``x_s`` and check every component.
    """
    d, k = ct.dim, ct.k
    z = sp.Matrix(sp.symbols(f"z0:{ct.nq}", real=True))
    sub = dict(zip(D.q, D.Y_inv * z))
    comps = [z[(s + 1) * d:(s + 2) * d, 0] for s in range(k)]
    xs, _ = _vector_blocks(ct)
    rows = []
    for row in range(ct.n_phi):
        blocks = []
        for b in range(len(ct.slots)):
            blk = D.Phi_q[row, b * d:(b + 1) * d].subs(sub).applyfunc(sp.expand)
            coeffs = [sp.diff(blk[0], comps[s][0]) for s in range(k)]
            rebuilt = sum((coeffs[s] * comps[s].T for s in range(k)), sp.zeros(1, d))
            if not _is_zero(blk - rebuilt):
                raise FactorisationError(f"{ct.name}: block ({row}, {b}) of Φ_q is not Σ a_s x_sᵀ")
            blocks.append(_combination(coeffs, [x.T for x in xs], (1, d)))
        rows.append(blocks)
    return sp.BlockMatrix(rows)


# ------------------------------------------------------------------------------- steps
def _coordinates(rep: Report, ct, D, Ybar: sp.Matrix):
    d = ct.dim
    slots = [_block(s, d) for s in ct.slots]
    st = rep.step(
        "Coordinates and base vectors",
        f"A {ct.label} member is described by {ct.nq} coordinates, in the seed's order "
        "(basic points first, then base vectors), all in world axes. "
        + ("The base vectors are the coordinates that are vectors and, for every other basic "
           "point, its offset from $r_i$; they span the member's affine frame $X$."
           if ct.k else "A point member has no base vector: its only coordinate is $r_i$."))
    st.eq("q", sp.BlockMatrix([[s] for s in slots]))
    st.eq("q^T", D.q.T)
    xs, _ = _vector_blocks(ct)
    for s in range(ct.k):
        expr = _combination(list(Ybar[s + 1, :]), slots, (d, 1))
        if expr != xs[s]:
            st.eq(sp.latex(xs[s]), expr)
    if ct.k:
        st.eq("X", D.X)


def _conversion(rep: Report, ct, D, Ybar: sp.Matrix):
    d, ref = ct.dim, _reference_name(ct)
    st = rep.step(
        "Conversion matrix Y",
        f"Stacking $r_i$ and the base vectors gives the coordinates $q_{{{ref}}}$ of the seed's "
        f"first type. They are linear in $q$, so $q_{{{ref}}} = Y q$ with the constant "
        f"$Y = \\partial q_{{{ref}}} / \\partial q$. Every ${d} \\times {d}$ block of $Y$ is a "
        f"multiple of $I_{d}$ (each component of a vector only involves the same component of "
        f"the slots), hence the seed's Kronecker form $Y = \\bar{{Y}} \\otimes I_{d}$ with a "
        f"small matrix $\\bar{{Y}}$ read off $Y$. The inverse is $Y^{{-1}} = \\bar{{Y}}^{{-1}} "
        f"\\otimes I_{d}$.")
    st.eq(f"q_{{{ref}}}^T", D.q_ruvw.T)
    st.eq(r"\bar{Y}", Ybar)
    st.eq("Y", _kron(Ybar, d))
    st.eq("Y", D.Y)
    st.eq(r"\bar{Y}^{-1}", kron_factor(D.Y_inv, d))


def _transformation(rep: Report, ct, D):
    d = ct.dim
    C_kron = kron_factor(D.C_kron, d)
    Cbar = kron_factor(D.C, d)
    if Cbar != C_kron:
        raise FactorisationError(f"{ct.name}: C(c) differs from ([1, cᵀ] ⊗ I) Y")
    st = rep.step(
        "Transformation C(c)",
        ("A body-fixed point has constant affine coordinates $c$ in the frame $(r_i, X)$: "
         "$r = r_i + X c$. Its position is linear in $q$, $r = C(c) q$, with "
         f"$C(c) = ([1, c^T] \\otimes I_{d}) Y = \\bar{{C}}(c) \\otimes I_{d}$ and "
         "$\\bar{C}(c) = [1, c^T] \\bar{Y}$. $C$ does not depend on $q$, so the velocity "
         "of the point is $C(c) \\dot{q}$." if ct.k else
         "The member is its basic point: $r = r_i = C q$ with a constant $C$."))
    if ct.k:
        st.eq("c", D.c)
    st.eq("r", D.r_c)
    st.eq(r"\bar{C}(c)" if ct.k else r"\bar{C}", Cbar)
    st.eq("C(c)" if ct.k else "C", _kron(Cbar, d))


def _constraints(rep: Report, ct, D):
    d = ct.dim
    xs, xbars = _vector_blocks(ct)
    st = rep.step(
        "Intrinsic constraints",
        "Rigidity keeps the lengths of the base vectors and the angles between them equal to "
        f"their values $\\bar{{x}}_s$ in the member's local frame: {ct.n_phi} quadratic "
        "constraint(s) $x_s^T x_t - \\bar{x}_s^T \\bar{x}_t = 0$, in the seed's order.")
    blocks = sp.BlockMatrix([[xs[s].T * xs[t] - xbars[s].T * xbars[t]] for s, t in ct.pairs])
    explicit = {**{x: sp.ImmutableMatrix(v) for x, v in zip(xs, D.x)},
                **{x: sp.ImmutableMatrix(v) for x, v in zip(xbars, D.xbar)}}
    if not _is_zero(sp.Matrix(blocks.xreplace(explicit).as_explicit()) - D.Phi):
        raise FactorisationError(f"{ct.name}: the block form of Φ differs from the derivation")
    st.eq(r"\Phi(q)", blocks)
    st.eq(r"\Phi(q)", D.Phi)
    st = rep.step(
        "Constraint Jacobian",
        f"$\\Phi_q = \\partial \\Phi / \\partial q$ is linear in $q$. In blocks of $1 \\times {d}$ "
        "(one per slot), each entry is a combination of the base vectors, read off the "
        "derived Jacobian:")
    st.eq(r"\Phi_q", phi_q_blocks(ct, D))
    if ct.nq <= 6:
        st.eq(r"\Phi_q", D.Phi_q)


def _hessians(rep: Report, ct, D):
    d = ct.dim
    st = rep.step(
        "Constant Hessians",
        f"Each constraint is quadratic, so its Hessian $H_k = \\partial^2 \\Phi_k / \\partial q^2$ "
        f"is a constant {ct.nq}x{ct.nq} matrix, of the form $H_k = \\bar{{H}}_k \\otimes I_{d}$ "
        "with a small symmetric $\\bar{H}_k$ read off $H_k$. Hence $\\Phi_q(q)$ is linear, "
        "$\\Phi_q(q) = [q^T H_k]_k$, and the velocity term of the constraint acceleration "
        "is $\\gamma = -\\dot{\\Phi}_q \\dot{q} = -[\\dot{q}^T H_k \\dot{q}]_k$.")
    for n, H in enumerate(D.hessians, 1):
        st.eq(f"H_{{{n}}}", _kron(kron_factor(H, d), d))


def _mass(rep: Report, ct, D):
    d = ct.dim
    st = rep.step(
        "Mass matrix",
        "Twice the kinetic energy, $2T = \\int \\rho \\dot{r}^T \\dot{r} = \\dot{q}^T M \\dot{q}$ "
        "with $\\dot{r} = C(c) \\dot{q}$, gives the constant mass matrix "
        f"$M = \\int \\rho C^T C = Y^T (G \\otimes I_{d}) Y$, where the generalised inertia "
        "$G = \\int \\rho [1, c^T]^T [1, c^T]$ holds the mass $m$, the affine coordinates "
        "$c_g$ of the centre of mass and $B = \\int \\rho c c^T$. "
        f"Hence $M = \\bar{{M}} \\otimes I_{d}$ with $\\bar{{M}} = \\bar{{Y}}^T G \\bar{{Y}}$.")
    st.eq("G", D.G)
    st.eq(r"\bar{M}", kron_factor(D.M, d))


def _inertia(rep: Report, ct, D):
    d = ct.dim
    what = {("body", 3): "the inertia tensor $\\bar{I}$ about the centre of mass, in body axes",
            ("body", 2): "the planar moment $\\bar{I}$ about the centre of mass; only "
                         "$\\mathrm{tr}\\,\\bar{J} = \\bar{I}$ enters rigid motions, so the "
                         "isotropic $\\bar{J}$ is used",
            ("bar", d): "the transverse moment $\\bar{I}_t = \\int \\rho \\bar{x}^2$ about the "
                        "centre of mass (a bar has no mass off its axis)"}[(ct.kind, d)]
    st = rep.step(
        "Inertia from mass, centre of mass and moments",
        "In the member's local frame (origin at the centre of mass, so $\\bar{r}_g = 0$) a point "
        "is $\\bar{r} = \\bar{r}_i + \\bar{X} c$, so $c = \\bar{X}^{+} (\\bar{r} - \\bar{r}_i)$ "
        "with the pseudo-inverse $\\bar{X}^{+}$. Integrating over the member gives $c_g$ and "
        "$B$ from $\\bar{J} = \\int \\rho \\bar{r} \\bar{r}^T$, itself from " + what + ".")
    st.eq(r"\bar{X}", D.Xbar)
    st.eq(r"\bar{X}^{+}", D.Xbar_pinv)
    st.eq("c_g", D.c_g_formula)
    st.eq("B", D.B_formula)
    st.eq(r"\bar{J}", D.Jbar_formula)
    if ct.kind == "bar":
        _bar_example(rep, ct, D)


def _bar_example(rep: Report, ct, D):
    d = ct.dim
    L, a = sp.symbols("L a", positive=True)
    ex = sp.zeros(d, 1)
    ex[0] = 1
    sub = {D.Xbar_sym: sp.ImmutableMatrix(L * ex), D.rbar_i_sym: sp.ImmutableMatrix(-a * ex),
           D.Jbar_sym: sp.ImmutableMatrix(D.Jbar_formula)}
    c_g = D.c_g_formula.subs(sub).doit().applyfunc(sp.simplify)
    B = D.B_formula.subs(sub).doit().applyfunc(sp.simplify)
    uniform = {a: L / 2, D.Ibar_sym: D.m * L**2 / 12}
    Mbar = kron_factor(D.M, d).subs({D.c_g[0]: c_g[0], D.B[0, 0]: B[0, 0]}).subs(uniform)
    st = rep.step(
        "Example: a bar of length L",
        "With $\\bar{x}$ along the bar, $\\bar{u} = L e_x$ and the first end $r_i$ at distance "
        "$a$ from the centre of mass, the formulas above give $c_g$ and $B$. For a uniform "
        "bar, $a = L/2$ and $\\bar{I}_t = m L^2/12$, the mass matrix follows.")
    st.eq("c_g", c_g)
    st.eq("B", B)
    st.eq(r"\bar{M}_{\mathrm{uniform}}", Mbar.applyfunc(sp.factor))


def _pose(rep: Report, ct, D):
    d = ct.dim
    if ct.kind == "body":
        Xbar = D.Xbar_sym
        st = rep.step(
            "Pose and angular velocity",
            "The world base vectors are the local ones rotated: $X = R \\bar{X}$, hence "
            "$R = X \\bar{X}^{-1}$; the centre of mass is $p = r_i + X c_g$. Differentiating, "
            "$\\dot{R} R^T = \\hat{\\omega}$ gives $\\hat{\\omega} = \\dot{X} \\bar{G} X^T$ with "
            "$\\bar{G} = (\\bar{X}^T \\bar{X})^{-1}$; $\\omega$ is taken from the skew-symmetric "
            "part of that product (exact on the constraint manifold).")
        st.eq("R", sp.MatMul(sp.ImmutableMatrix(D.X), Xbar.I))
        st.eq("p", D.p)
        st.eq(r"\dot{X}", D.Xdot)
        st.eq(r"\bar{G}", sp.Inverse(sp.MatMul(Xbar.T, Xbar)))
        st.eq(r"\hat{\omega}", sp.MatMul(sp.ImmutableMatrix(D.Xdot), sp.MatrixSymbol("Gbar", d, d),
                                          sp.ImmutableMatrix(D.X.T)))
    else:
        st = rep.step(
            "Pose and angular velocity",
            "A bar's orientation is its axis $e_1 = u / |u|$; a frame $R = [e_1, \\ldots]$ "
            "completes it (orthonormal, right-handed); the centre of mass is "
            "$p = r_i + c_g u$. Spin about the axis is not described: the angular velocity is "
            "the one normal to the axis, $\\omega = u \\times \\dot{u} / |\\bar{u}|^2$.")
        st.eq("e_1", D.R[:, 0])
        st.eq("p", D.p)
    n = _terms(D.omega)
    if n <= MAX_TERMS:
        st.eq(r"\omega", D.omega if d == 3 else D.omega[0])
    else:
        st.prose += (f" Expanded, each component of $\\omega$ has up to {n} terms "
                     "(`ct.derivation.omega`).")
    st.prose += (" $\\omega$ is linear in $\\dot{q}$, $\\omega = W(q) \\dot{q}$, and a torque "
                 "$\\tau$ acts through the generalised force $Q = W^T \\tau$.")


def _inverse(rep: Report, ct, D):
    if ct.kind == "point":
        text = "A point's coordinates are its position $p$ and their rates its velocity $v$."
    else:
        text = ("Given the pose $(R, p)$ and the twist $(\\omega, v)$ of the centre-of-mass "
                "frame, each slot follows from the local basis: $r_i = p + R \\bar{r}_i$, "
                "$x_s = R \\bar{x}_s$, $\\dot{r}_i = v + \\omega \\times (r_i - p)$, "
                "$\\dot{x}_s = \\omega \\times x_s$, then $q = Y^{-1} q_{\\mathrm{ref}}$.")
    st = rep.step("From pose and twist to coordinates", text)
    st.eq("q", D.q_of_pose)
    st.eq(r"\dot{q}", D.qd_of_twist)


def coordinates_report(ct) -> Report:
    """The derivation of coordinate type ``ct`` (a
    :class:`~ncgen.symbolic.coordinates.CoordinateType`) as a teaching report."""
    D = ct.derivation
    Ybar = kron_factor(D.Y, ct.dim)
    rep = Report(
        f"Natural coordinates: {ct.label}",
        f"{ct.nq} coordinates, {ct.n_phi} intrinsic constraint(s), {ct.dof} degrees of freedom. "
        "Notation of the seed (Rible.jl, NCF): basic points $r_i, r_j, \\ldots$, base vectors "
        f"${', '.join(VECTOR_NAMES[:ct.dim])}$; a bar over a symbol marks its constant value in the "
        "member's local frame.")
    _coordinates(rep, ct, D, Ybar)
    _conversion(rep, ct, D, Ybar)
    _transformation(rep, ct, D)
    if ct.n_phi:
        _constraints(rep, ct, D)
        _hessians(rep, ct, D)
    _mass(rep, ct, D)
    if ct.k:
        _inertia(rep, ct, D)
        _pose(rep, ct, D)
    _inverse(rep, ct, D)
    return rep


def jupyter_latex(rep: Report) -> str:
    """The report's equations as MathJax display math (Jupyter's ``text/latex``)."""
    out = []
    for s in rep.steps:
        out.append(f"$$\\textbf{{{s.title}}}$$")
        out += [f"$${e.lhs} = {sp.latex(e.rhs, mat_delim='[', mat_str='matrix')}$$" for e in s.equations]
    return "\n".join(out)


__all__ = ["FactorisationError", "coordinates_report", "jupyter_latex", "kron_factor", "phi_q_blocks"]
