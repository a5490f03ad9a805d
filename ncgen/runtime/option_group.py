"""The base of the integrators' option groups (:mod:`ncgen.runtime.options`): a frozen
dataclass of the fields of :class:`~ncgen.runtime.options.SimulationOptions` one integrator
reads, which checks those only it reads and names its method in the error."""
from __future__ import annotations

import dataclasses
import numbers
from typing import ClassVar, NoReturn

import numpy as np

from ncgen.errors import NcgenError


class OptionGroup:
    """One integrator's options: a frozen dataclass whose fields are those of
    :class:`SimulationOptions` it reads, ``METHOD`` its method; its ``__post_init__`` checks the
    fields only it reads, by :meth:`fail`."""

    METHOD: ClassVar[str]

    @classmethod
    def of(cls, opts):
        """The group's fields taken from ``opts`` (a :class:`~ncgen.runtime.options.SimulationOptions`), checked."""
        return cls(**{f.name: getattr(opts, f.name) for f in dataclasses.fields(cls)})

    @classmethod
    def names(cls) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(cls))

    def fail(self, name: str, expected: str) -> NoReturn:
        """Raise the error of option ``name``: ``expected``, the value given, the method."""
        raise NcgenError(f"{name}: expected {expected}, got {getattr(self, name)!r} (an option of "
                         f"method={self.METHOD!r})")


def is_real(x) -> bool:
    """A real number, not a bool."""
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def is_count(x, lowest: int) -> bool:
    """An int (not a bool) of at least ``lowest``."""
    return isinstance(x, int) and not isinstance(x, bool) and x >= lowest
