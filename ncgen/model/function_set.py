"""``FunctionSet``: a model's whole-system CasADi functions (``model.functions``), each made on
its first access.

A read-only mapping ``name -> casadi.Function`` whose names are known from the start and
whose functions are made by their *makers* when first asked for: ``model.functions["A"]``
makes ``A`` and nothing else, so a consumer that needs only ``Φ``, ``A`` or ``M`` does not pay
for the composites (``ode``, ``alg``, ``dae``, ``energy``: common-subexpression elimination
of the inlined model), the inverse mass matrix (triangular solves expanded symbolically) or
the poses.  Iterating over the names makes nothing; ``values()``, ``items()`` and
``dict(functions)`` make every function.

A maker is ``maker(functions) -> casadi.Function`` (it may ask the set for other
functions).  Pickling (the store of built models, :mod:`ncgen.codegen.model_cache`) keeps a
maker lazy only when it is a :class:`functools.partial` of a module-level function (its
arguments numbers, arrays, CasADi matrices or functions, which pickle); any other maker (a
closure over the assembly's expressions) is run first, and every function made travels as
its CasADi serialisation, deserialised on its first access after reading.  A set may be
given a *store* (:meth:`FunctionSet.keep_in`, the store of built models: not pickled) that a
function still to make is first read from, and that each function made is written to.
"""
from __future__ import annotations

import functools
import threading
from collections.abc import Callable, Iterator, Mapping

#: Called with ``(name,)`` each time a function is made (tests and profiling count them).
HOOKS: list[Callable[[str], None]] = []


class FunctionSet(Mapping):
    """``name -> casadi.Function``, each made on first access (see the module docstring)."""

    def __init__(self, makers: Mapping[str, Callable], made: Mapping | None = None, names=None):
        made = dict(made or {})
        self._names = tuple(names) if names is not None else tuple(dict.fromkeys([*makers, *made]))
        missing = set(self._names) - set(makers) - set(made)
        if missing:
            raise ValueError(f"FunctionSet: no maker or function for {', '.join(sorted(missing))}")
        self._makers = {k: m for k, m in makers.items() if k not in made}
        self._made = made
        self._lock = threading.RLock()
        self._store = None

    def __getitem__(self, name: str):
        f = self._made.get(name)
        if f is not None:
            return f
        with self._lock:
            f = self._made.get(name)
            if f is None:
                maker = self._makers.get(name)
                if maker is None:
                    raise KeyError(name)
                store = None if isinstance(maker, functools.partial) and maker.func is deserialized else self._store
                f = None if store is None else store.read(name)
                if f is None:
                    f = maker(self)
                    for hook in HOOKS:
                        hook(name)
                    if store is not None:
                        store.write(name, f)
                self._made[name] = f
        return f

    def keep_in(self, store) -> None:
        """Read the functions still to make from ``store`` first (``store.read(name)``: the
        function or None) and write each function then made to it (``store.write(name, f)``);
        functions already made, or read back from this set's pickle, do not go through it."""
        self._store = store

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, name) -> bool:
        return name in self._names

    def made(self) -> tuple[str, ...]:
        """The names of the functions made so far, in the set's order."""
        return tuple(n for n in self._names if n in self._made)

    def __repr__(self) -> str:
        return f"FunctionSet({', '.join(self._names)}; made: {', '.join(self.made()) or 'none'})"

    def __reduce__(self):
        """Pickled as makers: portable ones as they are, the others run first; a function
        already made travels as its CasADi serialisation, read back on its first access."""
        return self.reduced()

    def reduced(self, texts: Mapping[str, str] | None = None):
        """:meth:`__reduce__`, taking the serialisations of ``texts`` (``{name: text}`` of
        functions made, serialised already) instead of serialising those functions again."""
        texts = texts or {}
        makers = {k: m for k, m in self._makers.items() if _portable(m) and k not in self._made}
        for name in self._names:
            if name not in makers:
                text = texts.get(name)
                makers[name] = functools.partial(deserialized, self[name].serialize() if text is None else text)
        return FunctionSet, ({k: makers[k] for k in self._names}, None, self._names)


def deserialized(text: str, _functions):
    """The CasADi function whose serialisation is ``text`` (a maker of a pickled set)."""
    import casadi
    return casadi.Function.deserialize(text)


def _portable(maker) -> bool:
    """Whether ``maker`` pickles as it is: a partial of a module-level function."""
    return (isinstance(maker, functools.partial) and getattr(maker.func, "__qualname__", "<")
            == getattr(maker.func, "__name__", ">"))
