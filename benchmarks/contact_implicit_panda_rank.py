"""Why the planar Panda's push stalls: the rank of the active constraints' Jacobian at the
iterate where IPOPT stops, and the rows that depend on others (issue 39, deliverable 3).

The problem is ``benchmarks/contact_implicit_panda.py --locked`` (same options).  IPOPT runs
``--max-iter`` iterations of the first σ stage; at its last iterate the script takes every
equality row (dynamics, invariants, final conditions), every inequality within ``--active`` of
its bound (the relaxed products ``a c ≤ σ``, the sides ``a ≥ 0`` and ``c ≥ 0`` of the
complementarity pairs, the joint limits), scales each row to unit norm, and prints the SVD's
rank (singular values above ``1e-9 · s_max``) and, from a QR with column pivoting of the
transposed rows, each dependent row with the rows that span it (weights above 1 %), grouped
by kind.

Run:  python benchmarks/contact_implicit_panda_rank.py [--task push] [--pusher arm|point]
             [--feet corners|tripod] [--max-iter 60] [--active 1e-6] [--guess rest|point]
             [--point-cache FILE.npz] [--final q|pose|soft]
"""
from __future__ import annotations

import argparse
import collections
import importlib.util
import re
from pathlib import Path

import casadi as ca
import numpy as np
import scipy.linalg

from ncgen.errors import OptimizationError


def _benchmark():
    path = Path(__file__).resolve().parent / "contact_implicit_panda.py"
    spec = importlib.util.spec_from_file_location("contact_implicit_panda", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def labelled_rows(result):
    """``[(label, expr, lower, upper)]``: every constraint of the NLP with a name per row."""
    nlp = result.nlp
    rows = []
    for g in nlp.groups:
        n = ca.MX(g.expr).numel()
        lb, ub = np.broadcast_to(np.asarray(g.lb, float).reshape(-1), (n,)), np.broadcast_to(np.asarray(g.ub, float).reshape(-1), (n,))
        rows += [(f"{g.label}[{i}]", g.expr[i], lb[i], ub[i]) for i in range(n)]
    tr = nlp.ocp.transcription
    names = [c["name"] for c in tr.contacts]
    seen = set()
    sigma = tr.sigma
    for pair in tr.pairs:
        a, c = ca.MX(pair.a), ca.MX(pair.c)
        n = a.numel()
        for i in range(n):
            contact = names[i % len(names)] if n % len(names) == 0 else str(i)
            label = f"{pair.label} [{contact}]"
            if ca.symvar(a[i] * c[i]):
                rows.append((f"product  {label}", a[i] * c[i] - sigma, -np.inf, 0.0))
            for side, which in ((a[i], "a"), (c[i], "c")):
                key = str(side)
                if ca.symvar(side) and key not in seen:
                    seen.add(key)
                    rows.append((f"side {which} ≥ 0  {label}", side, 0.0, np.inf))
    return rows


def active_jacobian(result, tol):
    """Row-normalised Jacobian of the rows active at the solver's last iterate, their labels."""
    nlp = result.nlp
    opti = nlp.opti
    x = nlp.x_opt
    p = np.array(nlp.value(opti.p), float).reshape(-1)
    rows = labelled_rows(result)
    G = ca.vertcat(*[r[1] for r in rows])
    F = ca.Function("F", [opti.x, opti.p], [G, ca.jacobian(G, opti.x)])
    g, J = F(x, p)
    g, J = np.array(g, float).reshape(-1), np.array(ca.densify(J), float)
    lb, ub = np.array([r[2] for r in rows]), np.array([r[3] for r in rows])
    active = (lb == ub) | (np.abs(g - lb) <= tol) | (np.abs(g - ub) <= tol)
    J = J[active]
    norms = np.linalg.norm(J, axis=1)
    keep = norms > 0
    labels = [r[0] for r, a in zip(rows, active) if a]
    return J[keep] / norms[keep, None], [l for l, k in zip(labels, keep) if k], int(np.sum(~keep))


def kind(label):
    """A row's label without node, interval and index numbers (to group rows)."""
    return re.sub(r"\d+", "#", label)


def report(J, labels, rtol=1e-9, shown=12):
    s = np.linalg.svd(J, compute_uv=False)
    rank = int(np.sum(s > rtol * s[0]))
    print(f"  active rows {J.shape[0]}, variables {J.shape[1]}, rank {rank} (deficiency {J.shape[0] - rank}); "
          f"smallest singular values {np.array2string(s[-6:], precision=2)}")
    _, R, piv = scipy.linalg.qr(J.T, mode="economic", pivoting=True)
    d = np.abs(np.diag(R))
    r = int(np.sum(d > rtol * d[0]))
    basis, dependent = piv[:r], piv[r:]
    counts = collections.Counter(kind(labels[i]) for i in dependent)
    print("  dependent rows by kind:")
    for k, n in counts.most_common():
        print(f"    {n:4d}  {k}")
    for i in dependent[:shown]:
        w, *_ = np.linalg.lstsq(J[basis].T, J[i], rcond=None)
        big = np.argsort(-np.abs(w))[:6]
        terms = ", ".join(f"{w[j]:+.2f} {labels[basis[j]]}" for j in big if abs(w[j]) > 1e-2)
        print(f"    {labels[i]}  =  {terms}")
    return rank


def largest_multipliers(result, shown=10):
    """The constraint rows with the largest multipliers at the solver's last iterate (CasADi's
    description of each: the source line that imposed it and its expression, shortened)."""
    opti = result.nlp.opti
    lam = np.abs(np.array(result.nlp.value(opti.lam_g), float).reshape(-1))
    order = np.argsort(-lam)[:shown]
    print(f"  largest multipliers (of {lam.size} rows; median {np.median(lam):.1e}):")
    for i in order:
        text = " ".join(opti.debug.g_describe(int(i)).split())
        print(f"    {lam[i]:.2e}  row {i}: {text[:160]}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--task", choices=("push", "reach"), default="push")
    ap.add_argument("--feet", choices=("corners", "tripod"), default="corners")
    ap.add_argument("--pusher", choices=("arm", "point"), default="arm")
    ap.add_argument("--N", type=int, default=10)
    ap.add_argument("--weight", type=float, default=0.01)
    ap.add_argument("--max-iter", type=int, default=60)
    ap.add_argument("--active", type=float, nargs="+", default=[1e-6])
    ap.add_argument("--guess", choices=("rest", "point"), default="rest",
                    help="the arm's push from rest or from the point pusher's optimum (contact_implicit_panda.py)")
    ap.add_argument("--final", choices=("q", "pose", "soft"), default="q",
                    help="the arm's final configuration, or only the box's pose (contact_implicit_panda.py)")
    ap.add_argument("--point-cache", help="--guess point: an .npz file for the point pusher's solution")
    args = ap.parse_args(argv)
    bench = _benchmark()
    ocp, model = bench.locked_problem(args.N, args.task, args.feet, args.weight, args.pusher,
                                      {"sigma_final": 1e-3, "polish": False}, args.final)  # the first σ stage only
    guess = "rest"
    if args.guess == "point":
        point, point_model = bench.point_solution(args.N, args.feet, 1000, args.point_cache)
        guess = bench.guess_from_point(model, point, point_model)
    try:
        result = ocp.solve(guess, max_iter=args.max_iter, diagnose=False)
    except OptimizationError as exc:
        result = exc.result
    it = result.nlp.opti.stats().get("iterations", {})
    print(f"{args.pusher} pusher, {args.task}, box on {args.feet}, N = {args.N}: stopped after "
          f"{result.stats.iterations} iterations ({result.stats.status}); last primal / dual infeasibility "
          f"{it['inf_pr'][-1]:.1e} / {it['inf_du'][-1]:.1e}")
    largest_multipliers(result)
    for tol in args.active:
        J, labels, empty = active_jacobian(result, tol)
        print(f"rows within {tol:g} of their bound ({empty} rows with a zero gradient left out):")
        report(J, labels)


if __name__ == "__main__":
    main()
