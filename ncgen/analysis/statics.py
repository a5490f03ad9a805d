"""``equilibrium``: static equilibrium of a model, its reactions and its stability.

Solves ``G(q, λ) = F(t, q, 0, u, p) − Aᵀ λ = 0``, ``Φ(t, q) = 0`` by Newton's method on the
KKT system

    [ −K   −Aᵀ ] [Δq]     [G]
    [  A    0  ] [Δλ] = − [Φ],      K = −∂G/∂q  (tangent stiffness, :mod:`ncgen.assembly.statics_functions`),

with a backtracking line search on ``½(|G|² + |Φ|²)``; steps are least-squares solutions,
so zero-stiffness directions (a free-floating structure's rigid motions) leave the
configuration where it is.  Stability is judged from the *reduced tangent stiffness*
``K_r = Nᵀ K_s N`` (``K_s`` the symmetric part of K, ``N`` an orthonormal basis of
``null A``, :mod:`ncgen.assembly.manifold`): positive definite (stable), singular
(neutral: zero-stiffness motions) or indefinite (unstable).
Units: q in m, forces in N, λ in N per unit of Φ, K in N/m (N·m for base-vector rows).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ncgen.blas_threads import one_blas_thread
from ncgen.assembly.statics_functions import statics_function
from ncgen.errors import ModelError, NcgenError
from ncgen.model.rolling import refuse_rolling
from ncgen.analysis.reactions import unshared_state
from ncgen.analysis.stability import cached, classify
from ncgen.assembly.manifold import newton, null_basis
from ncgen.validation import as_scalar, as_vector

#: Largest step of ``method="descent"``, relative to the system's extent ``|q|∞``.
MAX_DESCENT_STEP = 0.25
#: Forces are converged to this times the largest stiffness times the system's size too
#: (the round-off of ``k (l − l₀)`` with stiff springs).
ROUNDOFF = 100 * np.finfo(float).eps


@dataclass
class Equilibrium:
    """Result of :func:`equilibrium`.

    * ``q`` (m), ``lam`` (one per constraint, ``model.constraint_names``), ``u``, ``p``, ``t``;
    * ``force_residual = |F − Aᵀλ|∞`` (N), ``constraint_residual = |Φ|∞``, ``iterations``;
    * ``reaction``: the generalised constraint force ``−Aᵀλ`` (N), per coordinate;
    * ``K`` tangent stiffness (nq × nq), ``N`` null-space basis of A, ``K_reduced = Nᵀ K_s N``
      and its ``stiffness_eigenvalues`` (ascending); ``stability`` ``"stable"``,
      ``"neutral"`` or ``"unstable"``, with ``n_zero`` and ``n_negative`` eigenvalues;
      ``asymmetry = |K_r − K_rᵀ| / |K_r|`` (non-zero with non-conservative loads);
    * ``springs``: per spring or cable, ``(name, tension N, length m, slack)``; a cable is
      slack when its stretch ``k (l − l₀)`` is not positive (it then exerts no force).
    """

    model: object = field(repr=False)
    q: np.ndarray
    lam: np.ndarray
    t: float
    u: np.ndarray
    p: np.ndarray
    force_residual: float
    constraint_residual: float
    iterations: int
    reaction: np.ndarray
    K: np.ndarray = field(repr=False)
    N: np.ndarray = field(repr=False)
    K_reduced: np.ndarray = field(repr=False)
    stiffness_eigenvalues: np.ndarray
    stability: str
    n_zero: int
    n_negative: int
    asymmetry: float
    springs: list = field(default_factory=list)

    @property
    def slack(self) -> list[str]:
        """Names of the slack cables."""
        return [name for name, _, _, slack in self.springs if slack]

    def coordinate(self, name: str) -> float:
        """The value (m) of coordinate ``name`` at the equilibrium: one of the model's or one
        as written before coordinate sharing re-based its member (``model.coordinate``)."""
        s, c = self.model.coordinate(name)
        return float(s @ self.q + c)

    def save(self, path) -> None:
        """Write the equilibrium: ``.npz`` (q, λ, u, p, K_reduced, stiffness eigenvalues and
        the coordinate and constraint names) or ``.csv`` (``name,value`` rows: ``q:<coordinate>``,
        ``lambda:<constraint>``, ``tension:<spring>`` in N). Written atomically."""
        from pathlib import Path

        from ncgen.files import atomic_path
        path = Path(path)
        model = self.model
        with atomic_path(path) as tmp:
            if path.suffix.lower() == ".npz":
                with open(tmp, "wb") as fh:
                    np.savez(fh, q=self.q, lam=self.lam, u=self.u, p=self.p, K_reduced=self.K_reduced,
                             stiffness_eigenvalues=self.stiffness_eigenvalues,
                             coordinate_names=np.array(model.coordinate_names),
                             constraint_names=np.array(model.constraint_names))
            else:
                rows = ["name,value"] + [f"q:{n},{x:.17g}" for n, x in zip(model.coordinate_names, self.q)]
                rows += [f"lambda:{n},{x:.17g}" for n, x in zip(model.constraint_names, self.lam)]
                rows += [f"tension:{n},{T:.17g}" for n, T, _, _ in self.springs]
                tmp.write_text("\n".join(rows) + "\n")

    def joint_reactions(self) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
        """``(joint, member, force, moment)`` for every joint and member it acts on: the
        resultant force (N, world axes) and moment about the member's centre of mass (N·m;
        a scalar in 2D) that the joint's constraints exert on the member, from the virtual
        work of ``−A_jᵀλ_j`` on the member's coordinates (see :func:`joint_reactions`).  Joints
        that coordinate sharing eliminated (wholly or in part) are included, from the model's
        ``share=False`` form (:func:`ncgen.analysis.reactions.unshared_state`)."""
        model = self.model
        out = joint_reactions(model, self.q, self.lam, t=self.t, p=self.p)
        plan = model.sharing
        names = set() if plan is None else {*plan.eliminated, *plan.partial}
        if not names:
            return out
        A = model.A(self.q, t=self.t, p=self.p).reshape(model.nc, model.nq)
        um, q_u, _, lam_u = unshared_state(model, self.q, self.lam, A, np.zeros(model.nq), self.t, self.u,
                                           self.p, sorted(names))
        out = [r for r in out if r[0] not in names] + \
            [r for r in joint_reactions(um, q_u, lam_u, t=self.t, p=self.p) if r[0] in names]
        order = {j.name: k for k, j in enumerate(model.joints)}
        return sorted(out, key=lambda r: order.get(r[0], len(order)))

    def multipliers(self) -> dict[str, float]:
        """``λ`` by constraint name."""
        return dict(zip(self.model.constraint_names, map(float, self.lam)))

    def table(self) -> str:
        """A readable summary: residuals, stability, multipliers and spring tensions."""
        lines = [f"equilibrium of {self.model.name!r}: {self.iterations} Newton iteration(s), "
                 f"|F - A'lam| = {self.force_residual:.3g} N, |Phi| = {self.constraint_residual:.3g}",
                 f"stability: {self.stability} (reduced tangent stiffness: {len(self.stiffness_eigenvalues)} "
                 f"eigenvalues, {self.n_negative} negative, {self.n_zero} zero; smallest "
                 + (f"{self.stiffness_eigenvalues[0]:.6g})" if len(self.stiffness_eigenvalues) else "none)"),
                 ""]
        wq = max(map(len, ["coordinate", *self.model.coordinate_names])) + 2     # columns never run together
        lines += [f"{'coordinate':<{wq}}{'q':>14}"]
        lines += [f"{n:<{wq}}{x:>14.6g}" for n, x in zip(self.model.coordinate_names, self.q)]
        if self.lam.size:
            wc = max(map(len, ["constraint", *self.model.constraint_names])) + 2
            lines += ["", f"{'constraint':<{wc}}{'lambda':>14}"]
            lines += [f"{n:<{wc}}{x:>14.6g}" for n, x in zip(self.model.constraint_names, self.lam)]
        try:
            reactions, missing = self.joint_reactions(), None
        except ModelError as e:          # the unshared form of a shared model could not be made
            reactions, missing = joint_reactions(self.model, self.q, self.lam, t=self.t, p=self.p), str(e)
        if missing:
            lines += ["", f"reactions of the joints eliminated by coordinate sharing are not shown: {missing}"]
        if reactions:
            d = self.model.dim
            wj = max(len(j) for j, *_ in [("joint",), *reactions]) + 2
            wm = max(len(m) for _, m, *_ in [("", "on member"), *reactions]) + 2
            lines += ["", f"{'joint':<{wj}}{'on member':<{wm}}{'force (N)':>{13 * d}}   moment about COM (N m)"]
            lines += [f"{j:<{wj}}{m:<{wm}}" + "".join(f"{x:>13.5g}" for x in f) + "   "
                      + "".join(f"{x:>13.5g}" for x in np.atleast_1d(mo)) for j, m, f, mo in reactions]
        if self.springs:
            lines += ["", f"{'spring':<20}{'tension (N)':>14}{'length (m)':>14}  state"]
            lines += [f"{n:<20}{T:>14.6g}{length:>14.6g}  {'SLACK' if s else 'taut'}"
                      for n, T, length, s in self.springs]
        return "\n".join(lines) + "\n"


def statics(model):
    """The model's ``statics`` CasADi function (built once)."""
    return cached(model, "statics", lambda: statics_function(model.functions))


def evaluate(model, q, lam, t, u, p):
    """``(G, Φ, K, A)`` as NumPy arrays."""
    G, phi, K, A = statics(model)(t, q, lam, u, p)
    return (np.array(G, float).reshape(-1), np.array(phi, float).reshape(-1), np.array(K, float),
            np.array(A, float).reshape(-1, model.nq))


def _check_options(method: str, tol, max_iter) -> float:
    """:func:`equilibrium`'s ``tol`` as a number, after refusing an unknown method, a ``tol``
    that is not positive or a ``max_iter`` that is not a positive integer."""
    if method not in ("descent", "newton"):
        raise NcgenError(f"equilibrium: method: expected 'descent' or 'newton', got {method!r}")
    tol = as_scalar(tol, "equilibrium: tol")
    if tol <= 0:
        raise NcgenError(f"equilibrium: tol: expected a number > 0 (relative), got {tol:g}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise NcgenError(f"equilibrium: max_iter: expected an integer ≥ 1, got {max_iter!r}")
    return tol


def _descent_shift(Kr: np.ndarray, f: np.ndarray, f_tol: float, extent: float) -> tuple[np.ndarray, bool]:
    """``(K_r + μ I, True)`` where the reduced stiffness ``K_r`` is not positive definite along
    the unbalanced force ``f`` (negative, or zero along a direction ``f`` pushes, beyond
    ``f_tol``), ``μ`` large enough to make it so and to keep the step within
    ``MAX_DESCENT_STEP × extent``; else ``(K_r, False)``.  Zero-stiffness motions the force does
    not drive (rigid motions of a self-equilibrated structure) are left to the least-squares step."""
    ev, V = np.linalg.eigh(0.5 * (Kr + Kr.T)) if Kr.size else (np.zeros(1), np.ones((1, 1)))
    scale = float(np.abs(ev).max(initial=0))
    soft = ev <= 1e-6 * scale
    if ev.min(initial=np.inf) < -1e-6 * scale or np.linalg.norm(V[:, soft].T @ f) > 1e-6 * np.linalg.norm(f) + f_tol:
        mu = max(-ev.min() + 1e-3 * scale, np.linalg.norm(f) / (MAX_DESCENT_STEP * extent))
        return Kr + mu * np.eye(Kr.shape[0]), True
    return Kr, False


@one_blas_thread
def equilibrium(model, q_guess=None, u=None, p=None, *, t: float | None = None, method: str = "descent",
                tol: float = 1e-10, max_iter: int = 100) -> Equilibrium:
    """A static equilibrium of ``model`` near ``q_guess`` (default ``model.q0``) under the
    constant inputs ``u`` (default zeros) and parameters ``p`` (default the model's; an
    array or a dict by name), at time ``t`` (default ``model.t0``).

    Newton's method on the constraint manifold: at a configuration with ``Φ = 0`` the
    multipliers are the least-squares ``λ = (Aᵀ)⁺ F`` (so ``G = F − Aᵀλ`` is the unbalanced
    force, tangent to the manifold), the step ``Δz`` solves ``K_r Δz = Nᵀ G`` and
    ``q + N Δz`` is projected back onto ``Φ = 0`` (Gauss–Newton); a backtracking line search
    on ``|Nᵀ G|`` keeps it from diverging.  This is Newton on the KKT system restricted to
    the constraints.  ``method="descent"`` (default) shifts ``K_r`` by ``μ I`` wherever it is
    not positive definite and limits steps to ``MAX_DESCENT_STEP`` × ``|q|∞``, accepting a
    step while the unbalanced force still pushes along it, so that the steps go down the
    potential and end in a stable equilibrium; ``method="newton"`` takes plain Newton steps
    and finds the nearest equilibrium of any stability (give a ``q_guess`` near an unstable
    one, such as a pendulum upright, to get it).

    Converged when ``|F − Aᵀλ|∞ ≤ tol × s_F + ROUNDOFF × |K|max × s_q`` and
    ``|Φ|∞ ≤ tol × s_q²`` (``s_F`` the largest applied generalised force at the guess, at
    least 1 N; ``s_q`` the size of the system, at least 1 m; the middle term is the round-off
    of stiff springs).  Raises :class:`~ncgen.errors.NcgenError` if it does not converge.
    """
    refuse_rolling(model, "equilibrium", "not supported yet for rolling elements (the elements' heights "
                   "would be missing)")
    tol = _check_options(method, tol, max_iter)
    nq = model.nq
    t = model.t0 if t is None else float(t)
    q = np.array(model.q0 if q_guess is None else as_vector(q_guess, nq, "q_guess"), float)
    u = np.zeros(model.nu) if u is None else as_vector(u, model.nu, "u")
    p = _parameters(model, p)
    q_scale = max(1.0, float(np.abs(q).max()))
    extent = float(np.abs(q).max()) or 1.0
    phi_tol = tol * q_scale**2
    lam0 = np.zeros(model.nc)

    def at(q):
        """Everything at ``q`` projected onto the constraints, λ in the least-squares sense."""
        q = _project(model, q, t, u, p, phi_tol)
        F, phi, _, A = evaluate(model, q, lam0, t, u, p)
        lam = np.linalg.lstsq(A.T, F, rcond=None)[0] if model.nc else lam0
        G, phi, K, A = evaluate(model, q, lam, t, u, p)
        N = null_basis(A, nq)
        return q, lam, G, phi, K, A, N, N.T @ G

    q, lam, G, phi, K, A, N, f = at(q)
    f_scale = max(1.0, float(np.abs(evaluate(model, q, lam0, t, u, p)[0]).max(initial=0)))
    it = 0
    while not (np.abs(G).max(initial=0) <= tol * f_scale + ROUNDOFF * np.abs(K).max(initial=0) * q_scale
               and np.abs(phi).max(initial=0) <= phi_tol):
        if it >= max_iter or not np.all(np.isfinite(G)):
            raise NcgenError(
                f"equilibrium of {model.name!r}: Newton did not converge in {it} iterations "
                f"(|F - A'lam| = {np.abs(G).max(initial=0):.3g} N, |Phi| = {np.abs(phi).max(initial=0):.3g}); "
                "give a q_guess closer to the equilibrium, or check that one exists (loads a "
                "mechanism cannot resist have none)")
        Kr = N.T @ K @ N
        shifted = False
        if method == "descent":
            Kr, shifted = _descent_shift(Kr, f, tol * f_scale, extent)
        dz = np.linalg.lstsq(Kr, f, rcond=None)[0]
        if method == "descent" and np.linalg.norm(dz) > MAX_DESCENT_STEP * extent:
            dz *= MAX_DESCENT_STEP * extent / np.linalg.norm(dz)
            shifted = True
        q, lam, G, phi, K, A, N, f = _line_search(at, q, N @ dz, f, shifted)
        it += 1
    return _result(model, q, lam, t, u, p, G, phi, K, A, it)


def _line_search(at, q: np.ndarray, step: np.ndarray, f: np.ndarray, shifted: bool) -> tuple:
    """``at(q + α step)`` for the first ``α`` of 1, 1/2, 1/4, … (down to 1e-4) that decreases
    ``|Nᵀ G|²`` enough (Armijo); a descent step (``shifted``) is also accepted while the force
    still pushes along it: the potential keeps decreasing up to the new point."""
    merit, alpha = f @ f, 1.0
    while True:
        trial = at(q + alpha * step)
        if (trial[7] @ trial[7] <= (1 - 1e-4 * alpha) * merit or alpha < 1e-4
                or (shifted and trial[2] @ step >= 0)):
            return trial
        alpha *= 0.5


def _project(model, q, t, u, p, tol: float, max_iter: int = 50) -> np.ndarray:
    """``q`` moved onto ``Φ = 0`` by the manifold's Newton (minimum-norm steps ``Δq = −A⁺Φ``)."""
    q, _, res = newton(lambda x: model.phi(x, t=t, p=p), lambda x: model.A(x, t=t, p=p), q,
                       np.arange(model.nq), tol=tol, max_iter=max_iter)
    if not res <= tol:
        raise NcgenError(f"equilibrium of {model.name!r}: the constraints cannot be satisfied near the guess "
                         f"(|Phi| = {res:.3g} after {max_iter} Gauss-Newton steps)")
    return q


def _result(model, q, lam, t, u, p, G, phi, K, A, it) -> Equilibrium:
    N = null_basis(A, model.nq)
    Ks = 0.5 * (K + K.T)
    Kr = N.T @ Ks @ N
    Kr_full = N.T @ K @ N
    ev = np.linalg.eigvalsh(Kr) if Kr.size else np.zeros(0)
    scale = float(np.abs(np.diag(Ks)).max()) if Ks.size else 0.0
    stability, n_zero, n_neg = classify(ev, scale)
    norm = np.linalg.norm(Kr_full)
    asym = float(np.linalg.norm(Kr_full - Kr_full.T) / norm) if norm > 0 else 0.0
    return Equilibrium(model=model, q=q, lam=lam, t=t, u=u, p=p,
                       force_residual=float(np.abs(G).max(initial=0)),
                       constraint_residual=float(np.abs(phi).max(initial=0)), iterations=it,
                       reaction=-(A.T @ lam), K=K, N=N, K_reduced=Kr, stiffness_eigenvalues=ev,
                       stability=stability, n_zero=n_zero, n_negative=n_neg, asymmetry=asym,
                       springs=spring_states(model, q, np.zeros(model.nq), t, u, p))


def joint_reactions(model, q, lam, *, t=None, p=None) -> list[tuple[str, str, np.ndarray, np.ndarray]]:
    """Resultant force and moment of each joint on each member it acts on.

    The constraint rows of joint ``j`` are those labelled ``j.…`` (not a member's
    ``m.rigid.…``); their generalised force on member ``m`` is ``Q = −A[j, m]ᵀ λ_j``.  A
    virtual rigid motion ``δr = δp + δθ × r`` of the member's points and ``δu = δθ × u`` of
    its base vectors does the work ``δpᵀ f + δθᵀ μ_O`` with ``f = Σ_points Q_r`` and
    ``μ_O = Σ_points r × Q_r + Σ_vectors u × Q_u``; the moment about the centre of mass
    ``p_G`` is ``μ_O − p_G × f``.  Exact for any member type; members sharing a node carry
    no multiplier there and are not reported here (``Equilibrium.joint_reactions`` adds them)."""
    q = np.asarray(q, float)
    lam = np.asarray(lam, float)
    A = model.A(q, t=t, p=p).reshape(-1, model.nq)
    layout, d = model.layout, model.dim
    members = set(model.member_names)
    joints: dict[str, list[int]] = {}
    for i, label in enumerate(model.constraint_names):
        head, _, rest = label.partition(".")
        if head in members and rest.startswith("rigid."):
            continue
        joints.setdefault(head, []).append(i)
    _, com = model.poses(q)
    out = []
    for joint, rows in joints.items():
        for k, name in enumerate(model.member_names):
            idx = layout.member_indices(name)
            cols = [i for i in idx if i is not None]
            if not cols or not np.any(A[np.ix_(rows, cols)]):
                continue
            force = np.zeros(d)
            moment = np.zeros(3)
            for slot, n in enumerate(layout.slots[name]):
                node = layout.nodes[n]
                if node.fixed is not None:
                    continue
                sl = slice(node.index, node.index + d)
                Q = -(A[rows, sl].T @ lam[rows])
                x = q[sl]
                if node.is_point:
                    force += Q
                moment += np.cross(np.append(x, 0) if d == 2 else x, np.append(Q, 0) if d == 2 else Q)
            moment -= np.cross(np.append(com[k], 0) if d == 2 else com[k], np.append(force, 0) if d == 2 else force)
            out.append((joint, name, force, moment[2] if d == 2 else moment))
    return out


def spring_states(model, q, v, t, u, p) -> list[tuple[str, float, float, bool]]:
    """``(name, tension, length, slack)`` of every spring and cable of ``model``."""
    table = getattr(model, "springs", None)
    if table is None or not table.names:
        return []
    T, length, pull = (np.array(x, float).reshape(-1) for x in table.function(t, q, v, u, p))
    return [(n, float(T[i]), float(length[i]), bool(table.cable[i] and pull[i] <= 0))
            for i, n in enumerate(table.names)]


def _parameters(model, p) -> np.ndarray:
    """The parameter vector from ``p`` (None, an array, a dict by name): the rule of ``nc.simulate``."""
    from ncgen.runtime.inputs import parameter_values
    return model.p0 if p is None else parameter_values(p, model)
