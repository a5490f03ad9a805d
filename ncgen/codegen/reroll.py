"""Loop rerolling: a long SX function of a model made of many alike members becomes an MX
function that calls a few short kernels in loops.

The flat SX function of a 1000-bar chain is ~10⁵ instructions of straight-line C, and
C compilers spend ≥ 0.1 ms on each (more than linear in the length of one function when
optimising).  Yet the function is the same few formulas repeated per member and joint with
different constants.  :func:`reroll` recovers that repetition from the expression graph
alone, without any knowledge of the model:

1. every output nonzero ``y_r`` depends on a set of input nonzeros ``D(r)`` (the sparsity of
   ``∂y/∂x``); outputs with the same set form a *block* ``y_B = g_B(x_{D(B)})``;
2. each block's algorithm, with its numeric constants blanked, is its *shape*; blocks of
   one shape differ only in their constants ``c_B``;
3. each shape with at least ``min_instances`` blocks becomes one SX kernel
   ``k(x_loc, c) → y_loc`` with the constants lifted to an input, evaluated for all its
   blocks by ``Function.map(K, "serial")`` (a loop in C) on the gathered ``x`` and the
   constant matrix ``[c_1 … c_K]``;
4. outputs that depend on no input are constants, outputs that are an input are one
   gather; the remaining outputs (rare shapes, large dependency sets) stay one flat SX
   function.

The shape of a block is read from ``f``'s algorithm (CasADi's instruction API, one work
slot per instruction), walked depth-first from the block's outputs, so alike blocks read alike
wherever they sit in ``f``.  The result is exact: every block is evaluated by the same
operations on the same numbers as in ``f`` (the rerolled function is checked against
``f`` at a probe point before it is returned).
Generated C then grows with the number of shapes, not of members; the index and constant
tables grow linearly but are data, which compilers read quickly.  The loops cost speed on
small models (a call and a gather per block), so :data:`REROLL_INSTRUCTIONS` sets where
it pays.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np

#: Functions with more SX instructions than this are rerolled when a package is written:
#: from there on gcc's -O2 time grows faster than the length of a function (a 39 k
#: function takes 27 s), while shorter straight-line code runs 2–4× faster than loops
#: (``benchmarks/kernel.py --looped``).
REROLL_INSTRUCTIONS = 20_000
#: A shape needs this many blocks to get a kernel; rarer ones stay flat.
MIN_INSTANCES = 4
#: Blocks depending on more input nonzeros than this stay flat (a global coupling, such as
#: a dense solve, does not repeat).
MAX_BLOCK_INPUTS = 256



@dataclass
class _Shape:
    """Blocks sharing one algorithm up to constants: the first block's instructions, and
    for each block its output rows, gathered inputs and constants."""

    lines: list[int]
    rows: list[np.ndarray] = field(default_factory=list)
    deps: list[np.ndarray] = field(default_factory=list)
    consts: list[list[float]] = field(default_factory=list)


def reroll(f: ca.Function, *, min_instances: int = MIN_INSTANCES,
           max_block_inputs: int = MAX_BLOCK_INPUTS) -> ca.Function:
    """``f`` (an SX function) as an MX function of rerolled kernels (see the module
    docstring), with the same name, inputs, outputs and sparsity; ``f`` itself if it is
    not an SX function or has neither a shape repeated ``min_instances`` times nor
    constant outputs."""
    if not f.is_a("SXFunction"):
        return f
    xs = f.sx_in()
    X = ca.vertcat(*[ca.vec(x.nz[:]) for x in xs]) if xs else ca.SX(0, 1)
    outs = f.call(xs)
    Y = ca.vertcat(*[ca.vec(y.nz[:]) for y in outs]) if outs else ca.SX(0, 1)
    g = ca.Function("reroll", [X], [Y], {"live_variables": False})   # one work slot per instruction
    algorithm = _Algorithm(g)
    shapes, constant_rows, copied_rows, flat_rows = _shapes(algorithm, _dependencies(g), max_block_inputs)
    kept = [s for s in shapes if len(s.rows) >= min_instances]
    flat_rows += [r for s in shapes if len(s.rows) < min_instances for b in s.rows for r in b]
    if not kept and not constant_rows and not copied_rows:
        return f
    r = _assemble(f, X, Y, algorithm, kept, constant_rows, copied_rows, sorted(flat_rows))
    _check(f, r)
    return r


def _dependencies(g: ca.Function) -> list[np.ndarray]:
    """For each output nonzero of ``g``, the indices of the input nonzeros it depends on."""
    sp = g.sparsity_jac(0, 0).T                                       # nX × nY: column r = D(r)
    colind = np.array(sp.colind(), dtype=np.int64)
    row = np.array(sp.row(), dtype=np.int64)
    return [row[colind[r]:colind[r + 1]] for r in range(g.nnz_out(0))]


class _Algorithm:
    """The instructions of ``g`` (one work slot each, one input, one output) read through
    CasADi's instruction API: for instruction ``k``, ``op[k]`` its operation code,
    ``refs[k]`` the instructions it reads, ``input[k]`` the input nonzero it loads (or -1),
    ``const[k]`` whether it is a numeric constant; ``source[r]`` computes output ``r``."""

    def __init__(self, g: ca.Function):
        self.g = g
        at_slot: dict[int, int] = {}
        self.op, self.refs, self.input, self.const = [], [], [], []
        self.source = [-1] * g.nnz_out(0)
        for k in range(g.n_instructions()):
            op, args = g.instruction_id(k), list(g.instruction_input(k))
            if op == ca.OP_OUTPUT:
                self.source[g.instruction_output(k)[1]] = at_slot[args[0]]
            else:
                at_slot[g.instruction_output(k)[0]] = k
            self.op.append(op)
            self.refs.append([] if op in (ca.OP_INPUT, ca.OP_CONST) else [at_slot[a] for a in args]
                             if op != ca.OP_OUTPUT else [at_slot[args[0]]])
            self.input.append(args[1] if op == ca.OP_INPUT else -1)
            self.const.append(op == ca.OP_CONST)

    def cone(self, rows) -> list[int]:
        """The instructions output ``rows`` need, in the order of a depth-first walk from
        those outputs (operands first): alike blocks give alike orders wherever the
        instructions sit in ``g``."""
        done, order = set(), []
        for r in rows:
            stack = [(self.source[r], False)]
            while stack:
                k, expanded = stack.pop()
                if k in done:
                    continue
                if expanded:
                    done.add(k)
                    order.append(k)
                else:
                    stack.append((k, True))
                    stack.extend((j, False) for j in reversed(self.refs[k]) if j not in done)
        return order


def _shapes(algorithm: _Algorithm, deps_of: list[np.ndarray], max_block_inputs: int):
    """Blocks of outputs with one dependency set grouped by shape (in order of first
    appearance), the rows depending on nothing, the rows that copy an input, the rows that
    stay flat."""
    blocks: dict[bytes, list[int]] = {}
    constant_rows, copied_rows, flat_rows = [], [], []
    for r, d in enumerate(deps_of):
        if algorithm.input[algorithm.source[r]] >= 0:
            copied_rows.append(r)
        elif len(d) == 0:
            constant_rows.append(r)
        elif len(d) > max_block_inputs:
            flat_rows.append(r)
        else:
            blocks.setdefault(d.tobytes(), []).append(r)
    shapes: dict[tuple, _Shape] = {}
    op, refs, inputs, const = algorithm.op, algorithm.refs, algorithm.input, algorithm.const
    for rows in blocks.values():
        cone = algorithm.cone(rows)
        deps = sorted({inputs[k] for k in cone if inputs[k] >= 0})
        local = {k: i for i, k in enumerate(cone)}
        slot = {x: i for i, x in enumerate(deps)}
        key = tuple(("c",) if const[k] else ("x", slot[inputs[k]]) if inputs[k] >= 0
                    else (op[k], *[local[j] for j in refs[k]]) for k in cone) \
            + (tuple(local[algorithm.source[r]] for r in rows),)
        s = shapes.setdefault(key, _Shape(cone))
        s.rows.append(np.array(rows, dtype=np.int64))
        s.deps.append(np.array(deps, dtype=np.int64))
        s.consts.append([algorithm.g.instruction_constant(k) for k in cone if const[k]])
    return list(shapes.values()), constant_rows, copied_rows, flat_rows


def _kernel(name: str, algorithm: _Algorithm, s: _Shape) -> ca.Function:
    """``k(x, c) → y``: the shape's instructions with its constants as the input ``c``."""
    g = algorithm.g
    x = ca.SX.sym("x", len(s.deps[0]))
    c = ca.SX.sym("c", len(s.consts[0]))
    slot = {int(i): j for j, i in enumerate(s.deps[0])}
    value: dict[int, ca.SX] = {}
    n_const = 0
    for k in s.lines:
        if algorithm.const[k]:
            value[k] = c[n_const]
            n_const += 1
        elif algorithm.input[k] >= 0:
            value[k] = x[slot[algorithm.input[k]]]
        else:
            op, args = g.instruction_id(k), [value[j] for j in algorithm.refs[k]]
            if len(args) == 2:
                value[k] = ca.SX.binary(op, *args)
            elif len(args) == 1:
                value[k] = ca.SX.unary(op, *args)
            else:
                raise NotImplementedError(f"reroll: SX operation {op} with {len(args)} operands")
    y = [value[algorithm.source[r]] for r in s.rows[0]]
    return ca.Function(name, [x, c], [ca.vertcat(*y)], ["x", "c"], ["y"])


def _assemble(f: ca.Function, X: ca.SX, Y: ca.SX, algorithm: _Algorithm, shapes: list[_Shape],
              constant_rows: list[int], copied_rows: list[int], flat_rows: list[int]) -> ca.Function:
    """The MX function: gather, mapped kernels, constants and the flat rest, scattered back
    into the outputs' nonzeros."""
    ins = [ca.MX.sym(f.name_in(i), f.sparsity_in(i)) for i in range(f.n_in())]
    Xm = ca.vertcat(*[ca.vec(x.nz[:]) for x in ins]) if ins else ca.MX(0, 1)
    pieces, order = [], []
    for i, s in enumerate(shapes):
        kernel = _kernel(f"{f.name()}_k{i}", algorithm, s)
        K = len(s.rows)
        idx = np.stack(s.deps, axis=1)                                   # n_loc × K
        xg = ca.reshape(Xm[idx.ravel(order="F").tolist()], idx.shape[0], K)
        c = ca.DM(np.array(s.consts, dtype=float).T.reshape(-1, K))
        pieces.append(ca.vec(kernel.map(K, "serial")(xg, c)))
        order.append(np.stack(s.rows, axis=1).ravel(order="F"))
    if copied_rows:
        pieces.append(Xm[[algorithm.input[algorithm.source[r]] for r in copied_rows]])
        order.append(np.array(copied_rows, dtype=np.int64))
    if constant_rows:
        values = ca.Function("constants", [X], [Y[constant_rows]])(np.zeros(X.shape[0]))
        pieces.append(ca.MX(ca.DM(values)))
        order.append(np.array(constant_rows, dtype=np.int64))
    if flat_rows:
        flat = ca.Function(f"{f.name()}_flat", [X], [Y[flat_rows]], ["x"], ["y"])
        pieces.append(flat(Xm))
        order.append(np.array(flat_rows, dtype=np.int64))
    order = np.concatenate(order)
    position = np.empty(Y.shape[0], dtype=np.int64)
    position[order] = np.arange(order.size)
    Ym = ca.vertcat(*pieces)[position.tolist()]
    outs, start = [], 0
    for i in range(f.n_out()):
        sp = f.sparsity_out(i)
        outs.append(ca.MX(sp, Ym[start:start + sp.nnz()]) if sp.nnz() else ca.MX(sp))
        start += sp.nnz()
    return ca.Function(f.name(), ins, outs, f.name_in(), f.name_out())


def _check(f: ca.Function, r: ca.Function) -> None:
    """``r`` must reproduce ``f`` (same operations on the same numbers) at a probe point."""
    args = [np.linspace(0.3, 1.7, f.nnz_in(i)) for i in range(f.n_in())]
    args = [ca.DM(f.sparsity_in(i), a) for i, a in enumerate(args)]
    for i, (a, b) in enumerate(zip(f.call(args), r.call(args))):
        a, b = np.array(a.nonzeros()), np.array(b.nonzeros())
        same = (a == b) | (np.isnan(a) & np.isnan(b)) | np.isclose(a, b, rtol=1e-12, atol=1e-300)
        if not np.all(same):
            raise RuntimeError(f"reroll: output {f.name_out(i)} of {f.name()} is not reproduced")
