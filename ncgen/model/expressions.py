"""Values that may vary: numbers, text expressions, CasADi SX and callables.

Drives, forces, stiffnesses and every other "value" of a model accept

* a number, or a sequence of numbers (a vector);
* a string such as ``"k"`` or ``"0.5*sin(2*t)"``, parsed *safely* — Python's :mod:`ast` with
  a whitelist of nodes, names and functions, never ``eval`` — into CasADi SX.  Names: ``t``
  (time, s), ``pi``, the system's parameter and input names (a vector one is indexed
  ``k[0]``), and, where a value may depend on the state (generalised forces), ``q`` and ``v``.
  Functions: :data:`FUNCTIONS`.  Operators: ``+ - * / **``, comparisons, ``and``, ``or``,
  ``not`` and ``a if c else b``;
* a CasADi SX expression of the system's parameter and input symbols;
* a sequence mixing numbers, strings, SX scalars and callables (one per component);
* a callable ``f(t)`` returning any of the above.

:func:`to_text` prints an SX expression back in the same syntax, so that a model given with
CasADi expressions or callables can still be written to TOML.
"""
from __future__ import annotations

import ast
import difflib
import math
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ncgen.errors import ModelError
from ncgen.validation import MAX_MAGNITUDE

#: Longest text expression accepted (characters).
MAX_TEXT = 10_000

#: Whitelisted functions: name -> (CasADi implementation, number of arguments).
FUNCTIONS: dict[str, tuple] = {
    **{n: (getattr(ca, n), 1) for n in (
        "sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "asinh", "acosh",
        "atanh", "exp", "log", "log10", "log1p", "expm1", "sqrt", "floor", "ceil", "sign", "erf",
        "fabs")},
    "abs": (ca.fabs, 1),
    "sq": (lambda a: a**2, 1),
    **{n: (getattr(ca, n), 2) for n in ("atan2", "fmin", "fmax", "hypot", "fmod", "copysign")},
    "min": (ca.fmin, 2),
    "max": (ca.fmax, 2),
    "pow": (lambda a, b: a**b, 2),
    "if_else": (ca.if_else, 3),
}

CONSTANTS = {"pi": math.pi}

#: Names a parameter or input may not take, because expressions reserve them.
RESERVED = frozenset({"t", "q", "v", "u", "p", *CONSTANTS, *FUNCTIONS})


class ExpressionError(ModelError):
    """A value expression that cannot be parsed, printed or used where it is given."""


@dataclass
class Scope:
    """The names an expression may use and the symbols it may depend on.

    ``names`` maps a text name to its SX symbol (column); ``allowed`` collects the element
    hashes of every symbol the value may depend on.  ``labels`` maps an element hash back to
    its text (``k``, ``k[1]``, ``t``) for :func:`to_text`.
    """

    names: dict[str, ca.SX] = field(default_factory=dict)

    @property
    def t(self) -> ca.SX:
        return self.names["t"]

    @property
    def allowed(self) -> set[int]:
        return set(self.labels())

    def labels(self) -> dict[int, str]:
        out = {}
        for name, sym in self.names.items():
            n = sym.numel()
            for i in range(n):
                out[sym[i].element_hash()] = name if n == 1 else f"{name}[{i}]"
        return out


def scope(t: ca.SX, parameters: dict, inputs: dict | None = None, **state) -> Scope:
    """A :class:`Scope` with ``t``, the ``parameters`` and ``inputs`` (name -> SX) and any
    extra named symbols (``q=..., v=...``)."""
    names = {"t": t, **parameters, **(inputs or {}), **state}
    return Scope(names)


# ------------------------------------------------------------------------ parsing
def parse(text: str, names: dict[str, ca.SX], what: str) -> ca.SX:
    """The SX expression of ``text`` over ``names``; raises :class:`ExpressionError`
    naming ``what`` and the offending part."""
    if not isinstance(text, str):
        raise ExpressionError(f"{what}: expected an expression string, got {text!r}")
    if len(text) > MAX_TEXT:
        raise ExpressionError(f"{what}: expression longer than {MAX_TEXT} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as e:
        raise ExpressionError(f"{what}: invalid expression {text!r}: {e.msg}") from None
    try:
        e = ca.SX(_Parser(names, what, text).visit(tree.body))
    except RecursionError:
        raise ExpressionError(f"{what}: expression {text!r} is nested too deeply") from None
    check_constant(e, what, text)
    return e


def check_constant(e: ca.SX, what: str, text: str | None = None) -> None:
    """Refuse an expression whose constant components are not finite real numbers of
    magnitude at most :data:`~ncgen.validation.MAX_MAGNITUDE` (``1/0``, ``sqrt(-1)``,
    ``9**9**9**9``): they would only show up as NaN or inf when simulating."""
    for i in range(e.numel()):
        x = e[i]
        if not x.is_constant():
            continue
        v = float(ca.DM(x))
        if not math.isfinite(v) or abs(v) > MAX_MAGNITUDE:
            given = f" {text!r}" if text is not None else ""
            raise ExpressionError(f"{what}: the expression{given} evaluates to {v:g}"
                                  + ("" if math.isfinite(v) else " (not a finite real number)")
                                  + (f", larger than {MAX_MAGNITUDE:g}" if math.isfinite(v) else ""))


class _Parser:
    def __init__(self, names, what, text):
        self.names, self.what, self.text = names, what, text

    def fail(self, msg):
        raise ExpressionError(f"{self.what}: {msg} in {self.text!r}")

    def visit(self, node):
        method = getattr(self, "visit_" + type(node).__name__, None)
        if method is None:
            self.fail(f"{_describe_node(node)} is not allowed")
        return method(node)

    def visit_Constant(self, node):
        if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
            self.fail(f"constant {node.value!r} is not a number")
        try:
            value = float(node.value)
        except OverflowError:
            value = math.inf
        if not abs(value) <= MAX_MAGNITUDE:
            self.fail(f"constant {_short(node.value)} is too large (more than {MAX_MAGNITUDE:g})")
        return value

    def checked(self, what, f, *args):
        """``f(*args)`` with folded constants kept finite and real."""
        try:
            out = f(*args)
        except ZeroDivisionError:
            self.fail(f"{what}: division by zero")
        except OverflowError:
            self.fail(f"{what}: the result is too large")
        except (ValueError, TypeError) as e:
            self.fail(f"{what}: {e}")
        if isinstance(out, complex):
            self.fail(f"{what}: the result is complex ({out:g})")
        if isinstance(out, float) and not (math.isfinite(out) and abs(out) <= MAX_MAGNITUDE):
            self.fail(f"{what}: the result is {out:g}, not a finite real number"
                      + (f" of magnitude at most {MAX_MAGNITUDE:g}" if math.isfinite(out) else ""))
        return out

    def visit_Name(self, node):
        if node.id in self.names:
            return self.names[node.id]
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        if node.id in FUNCTIONS:
            self.fail(f"{node.id} is a function; call it: {node.id}(...)")
        known = sorted(self.names) + sorted(CONSTANTS)
        self.fail(f"unknown name {node.id!r}{did_you_mean(node.id, known)} (known names: {', '.join(known)})")

    def visit_BinOp(self, node):
        ops = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b, ast.Mult: lambda a, b: a * b,
               ast.Div: lambda a, b: a / b, ast.Pow: lambda a, b: a ** b}
        f = ops.get(type(node.op))
        if f is None:
            self.fail(f"operator {type(node.op).__name__} is not allowed")
        return self.checked(f"'{ast.unparse(node)}'", f, self.visit(node.left), self.visit(node.right))

    def visit_UnaryOp(self, node):
        x = self.visit(node.operand)
        if isinstance(node.op, ast.USub):
            return -x
        if isinstance(node.op, ast.UAdd):
            return x
        if isinstance(node.op, ast.Not):
            return ca.logic_not(x)
        self.fail(f"operator {type(node.op).__name__} is not allowed")

    def visit_Compare(self, node):
        if len(node.ops) != 1:
            self.fail("chained comparisons are not allowed; combine them with 'and'")
        ops = {ast.Lt: lambda a, b: a < b, ast.LtE: lambda a, b: a <= b, ast.Gt: lambda a, b: a > b,
               ast.GtE: lambda a, b: a >= b, ast.Eq: lambda a, b: a == b, ast.NotEq: lambda a, b: a != b}
        f = ops.get(type(node.ops[0]))
        if f is None:
            self.fail(f"comparison {type(node.ops[0]).__name__} is not allowed")
        return f(ca.SX(self.visit(node.left)), self.visit(node.comparators[0]))

    def visit_BoolOp(self, node):
        f = ca.logic_and if isinstance(node.op, ast.And) else ca.logic_or
        out = ca.SX(self.visit(node.values[0]))
        for v in node.values[1:]:
            out = f(out, self.visit(v))
        return out

    def visit_IfExp(self, node):
        return ca.if_else(self.visit(node.test), self.visit(node.body), self.visit(node.orelse))

    def visit_Call(self, node):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            self.fail(f"unknown function {name!r}{did_you_mean(name, FUNCTIONS)} "
                      f"(functions: {', '.join(sorted(FUNCTIONS))})")
        if node.keywords:
            self.fail(f"{node.func.id}() takes positional arguments only")
        f, n = FUNCTIONS[node.func.id]
        if len(node.args) != n:
            self.fail(f"{node.func.id}() takes {n} argument{'s' * (n != 1)}, got {len(node.args)}")
        args = [self.visit(a) for a in node.args]
        if all(isinstance(a, float) for a in args):      # constants: fold and check
            return self.checked(f"'{ast.unparse(node)}'", lambda *x: float(ca.DM(f(*map(ca.DM, x)))), *args)
        return f(*(ca.SX(a) for a in args))

    def visit_Subscript(self, node):
        if not isinstance(node.value, ast.Name):
            self.fail("only names can be indexed, as in k[0]")
        base = self.visit(node.value)
        idx = node.slice
        neg = isinstance(idx, ast.UnaryOp) and isinstance(idx.op, ast.USub)
        inner = idx.operand if neg else idx
        if not (isinstance(inner, ast.Constant) and type(inner.value) is int):
            self.fail(f"index of {node.value.id}: expected an integer")
        i = -inner.value if neg else inner.value
        n = ca.SX(base).numel()
        if not -n <= i < n:
            self.fail(f"index {i} out of range: {node.value.id} has {n} component{'s' * (n != 1)}")
        return ca.SX(base)[i % n]


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 30 else f"{text[:12]}...({len(text)} digits)"


def _describe_node(node) -> str:
    return {"Attribute": "attribute access", "Lambda": "lambda", "List": "a list",
            "Tuple": "a tuple", "Dict": "a dict", "NamedExpr": "assignment"}.get(
        type(node).__name__, type(node).__name__)


def did_you_mean(word: str, options) -> str:
    """`` (did you mean 'x'?)`` when ``word`` is close to one of ``options``, else ``""``."""
    close = difflib.get_close_matches(str(word), [str(o) for o in options], n=1, cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


# ----------------------------------------------------------------------- printing
_INFIX = {"OP_ADD": "+", "OP_SUB": "-", "OP_MUL": "*", "OP_DIV": "/", "OP_POW": "**",
          "OP_CONSTPOW": "**", "OP_LT": "<", "OP_LE": "<=", "OP_EQ": "==", "OP_NE": "!=",
          "OP_AND": "and", "OP_OR": "or"}
_CALL = {"OP_SIN": "sin", "OP_COS": "cos", "OP_TAN": "tan", "OP_ASIN": "asin", "OP_ACOS": "acos",
         "OP_ATAN": "atan", "OP_SINH": "sinh", "OP_COSH": "cosh", "OP_TANH": "tanh",
         "OP_ASINH": "asinh", "OP_ACOSH": "acosh", "OP_ATANH": "atanh", "OP_EXP": "exp",
         "OP_LOG": "log", "OP_LOG1P": "log1p", "OP_EXPM1": "expm1", "OP_SQRT": "sqrt",
         "OP_SQ": "sq", "OP_FLOOR": "floor", "OP_CEIL": "ceil", "OP_SIGN": "sign", "OP_ERF": "erf",
         "OP_FABS": "fabs", "OP_ATAN2": "atan2", "OP_FMIN": "fmin", "OP_FMAX": "fmax",
         "OP_HYPOT": "hypot", "OP_FMOD": "fmod", "OP_COPYSIGN": "copysign"}
_OPS = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}
#: Longest text :func:`to_text` produces (a tree print of a large shared graph would explode).
MAX_PRINT = 100_000


def to_text(expr, labels: dict[int, str], what: str) -> str:
    """Print the scalar SX ``expr`` in the syntax :func:`parse` reads; ``labels`` maps the
    element hash of each symbol to its name (:meth:`Scope.labels`)."""
    e = ca.SX(expr)
    if e.numel() != 1:
        raise ExpressionError(f"{what}: to_text prints scalars, got shape {e.shape}")
    out = _print(e[0], labels, what, [0])
    return out[1:-1] if out.startswith("(") and _balanced(out[1:-1]) else out


def _balanced(s: str) -> bool:
    depth = 0
    for ch in s:
        depth += (ch == "(") - (ch == ")")
        if depth < 0:
            return False
    return depth == 0


def _number(x: float, what: str) -> str:
    if not math.isfinite(x):
        raise ExpressionError(f"{what}: the constant {x} cannot be written as an expression")
    return repr(float(x)) if x >= 0 else f"({float(x)!r})"


def _print(e, labels, what, count) -> str:
    count[0] += 1
    if count[0] > MAX_PRINT:
        raise ExpressionError(f"{what}: expression too large to print; give it as a string")
    op = _OPS.get(e.op(), "?")
    if op == "OP_CONST":
        return _number(float(e), what)
    if op == "OP_PARAMETER":
        h = e.element_hash()
        if h not in labels:
            raise ExpressionError(f"{what}: symbol {e.name()!r} is not one of the system's names")
        return labels[h]
    args = [_print(e.dep(i), labels, what, count) for i in range(e.n_dep())]
    if op in _INFIX:
        return f"({args[0]} {_INFIX[op]} {args[1]})"
    if op in _CALL:
        return f"{_CALL[op]}({', '.join(args)})"
    if op == "OP_NEG":
        return f"(-{args[0]})"
    if op == "OP_NOT":
        return f"(not {args[0]})"
    if op == "OP_TWICE":
        return f"(2.0 * {args[0]})"
    if op == "OP_INV":
        return f"(1.0 / {args[0]})"
    if op == "OP_IF_ELSE_ZERO":
        return f"if_else({args[0]}, {args[1]}, 0)"
    raise ExpressionError(f"{what}: the operation {op} has no text form; give the value as a string")


# ----------------------------------------------------------------------- values
def evaluate(value, sc: Scope, size: int, what: str, *, call=None) -> ca.SX:
    """``value`` (see the module docstring) as an SX column of ``size`` components that
    depends only on the symbols of ``sc``.  ``call(f)`` evaluates a callable (default
    ``f(t)``)."""
    v = value
    if callable(v) and not isinstance(v, (ca.SX, ca.MX, ca.DM)):
        v = call(v) if call is not None else v(sc.t)
    e = _as_sx(v, sc, what)
    if e.numel() != size:
        raise ExpressionError(f"{what}: expected {size} component{'s' * (size != 1)}, got {e.numel()}"
                              + (f" (shape {e.shape})" if e.numel() > 1 else ""))
    e = ca.reshape(e, size, 1)
    allowed = sc.allowed
    for s in ca.symvar(e):
        if s.element_hash() not in allowed:
            names = ", ".join(n for n in sc.names)
            raise ExpressionError(f"{what}: depends on the symbol {s.name()!r}, which is not one of "
                                  f"the names usable here ({names})")
    return e


def _called(x, sc: Scope):
    """A component given as a callable ``f(t)``, evaluated."""
    return x(sc.t) if callable(x) and not isinstance(x, (ca.SX, ca.MX, ca.DM)) else x


def _as_sx(v, sc: Scope, what: str) -> ca.SX:
    if isinstance(v, str):
        return parse(v, sc.names, what)
    if isinstance(v, ca.MX):
        raise ExpressionError(f"{what}: MX expressions are not supported; use SX symbols")
    if isinstance(v, (ca.SX, ca.DM)):
        return ca.SX(v)
    if isinstance(v, (list, tuple)) or (isinstance(v, np.ndarray) and v.dtype == object):
        parts = [_as_sx(_called(x, sc), sc, f"{what}[{i}]") for i, x in enumerate(v)]
        for i, p in enumerate(parts):
            if p.numel() != 1:
                raise ExpressionError(f"{what}[{i}]: expected a scalar, got {p.numel()} components")
        return ca.vertcat(*parts) if parts else ca.SX(0, 1)
    try:
        a = np.asarray(v, dtype=float)
    except OverflowError:
        raise ExpressionError(f"{what}: a number is too large (more than {MAX_MAGNITUDE:g})") from None
    except (TypeError, ValueError):
        raise ExpressionError(f"{what}: expected a number, a string expression, a CasADi SX "
                              f"expression or a callable, got {v!r}") from None
    if not np.all(np.isfinite(a)) or (a.size and np.max(np.abs(a)) > MAX_MAGNITUDE):
        raise ExpressionError(f"{what}: expected finite numbers of magnitude at most {MAX_MAGNITUDE:g}, "
                              f"got {a.tolist() if a.size <= 12 else 'a non-finite or huge value'}")
    return ca.SX(ca.DM(a.reshape(-1)))


def check_name(name: str, what: str) -> None:
    """Refuse a parameter or input name that expressions reserve."""
    if name in RESERVED:
        raise ExpressionError(f"{what} {name!r}: the name is reserved in expressions "
                              f"({', '.join(sorted(RESERVED - set(FUNCTIONS)))} and function names)")


def value_to_toml(value, sc: Scope, what: str, *, call=None):
    """A TOML-writable form of ``value``: a number, a string, or a list of them.
    Numbers and strings are kept as given; SX and callables are printed."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, str):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value)
    if callable(value) and not isinstance(value, (ca.SX, ca.MX, ca.DM)):
        value = call(value) if call is not None else value(sc.t)
    if isinstance(value, (list, tuple)) or (isinstance(value, np.ndarray) and value.dtype == object):
        return [value_to_toml(_called(x, sc), sc, f"{what}[{i}]") for i, x in enumerate(value)]
    if isinstance(value, (ca.SX, ca.DM)):
        e = ca.SX(value)
        labels = sc.labels()
        parts = []
        for i in range(e.numel()):
            x = e[i]
            parts.append(float(x) if x.is_constant() else to_text(x, labels, f"{what}[{i}]"))
        return parts[0] if e.numel() == 1 and e.shape == (1, 1) else parts
    if isinstance(value, ca.MX):
        raise ExpressionError(f"{what}: MX expressions cannot be written to TOML; use SX")
    a = np.asarray(value, dtype=float)
    return float(a) if a.ndim == 0 else a.tolist()
