"""Exceptions raised by ncgen.

Every error a user can trigger is a subclass of :class:`NcgenError`, itself a
``ValueError``, and its message says *what* was wrong (which member, joint, key or
argument), *what was expected* and *what was found*.
"""
import os
import sys

#: Where to report an unexpected internal error (printed by the command line).
REPORT_TO = "the ncgen issue tracker (the repository named in the README), with the command and this message"


#: The door the user came through, ``"python"`` or ``"cli"`` (set by :func:`ncgen.cli.main`),
#: so that messages name options as the user spells them (:func:`option`).
_door = ["python"]


def use_cli_names(on: bool = True) -> None:
    """Make :func:`option` name command-line flags (``True``) or Python arguments."""
    _door[0] = "cli" if on else "python"


def option(python: str, cli: str) -> str:
    """``python`` (e.g. ``"method='stepper'"``) or ``cli`` (e.g. ``"--method stepper"``),
    as the user calls ncgen."""
    return cli if _door[0] == "cli" else python


def user_stacklevel() -> int:
    """The ``stacklevel`` of :func:`warnings.warn`, called by the function that warns, at
    which the warning names the first caller outside the ncgen package (the user's line,
    however deep inside ncgen the warning was raised)."""
    inside = os.path.dirname(os.path.abspath(__file__)) + os.sep
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(inside):
        frame, level = frame.f_back, level + 1
    return level


class NcgenError(ValueError):
    """Base class of the errors ncgen raises for bad input."""


class ModelError(NcgenError):
    """An invalid model: names, references, geometry or initial state."""


class CoordinateTypeError(NcgenError):
    """Unknown natural-coordinate type, or one that does not exist in the requested dimension."""


class InvalidName(NcgenError):
    """A name that is not a short ASCII identifier (:func:`ncgen.validation.name`)."""


class ShapeError(NcgenError):
    """An array argument has the wrong shape."""


class InertiaError(NcgenError):
    """Non-positive mass, or an inertia tensor that is not symmetric positive definite or
    violates the triangle inequality."""


class BasisError(NcgenError):
    """Degenerate local basis: coplanar or zero base vectors, or a point off a bar's axis."""


class RotationError(NcgenError):
    """A matrix given as a rotation is not orthonormal with determinant +1."""


class CodegenError(NcgenError):
    """Generating, compiling or loading a C package failed; the message says which file or command."""


class CompilerNotFound(CodegenError):
    """No usable C compiler: ``$CC`` does not run and none of cc, gcc, clang is on PATH."""


class OptimizationError(NcgenError):
    """An optimal-control problem that is ill-posed, or that IPOPT did not solve.  The
    message gives IPOPT's status and names the likely culprit (the condition, bound or
    constraint group violated most at the last iterate); ``.result`` holds that iterate
    when there is one."""

    def __init__(self, message: str, result=None, status: str | None = None):
        super().__init__(message)
        self.result = result
        self.status = status


class ProblemFileError(NcgenError):
    """A bad optimal-control problem file: the message names the key path (``final.v``)
    and what was expected."""


class SimulationError(NcgenError):
    """The integrator could not continue.  ``time`` is the last output time reached (s),
    ``trajectory`` the :class:`~ncgen.runtime.trajectory.Trajectory` up to that time, and
    the message names the likely cause and what to try."""

    def __init__(self, message: str, *, time: float, trajectory=None):
        super().__init__(message)
        self.time = time
        self.trajectory = trajectory


class SimulationInterrupted(KeyboardInterrupt):
    """A run stopped by Ctrl-C (SIGINT).  ``time`` is the last output time reached (s),
    ``trajectory`` the :class:`~ncgen.runtime.trajectory.Trajectory` up to that time (marked
    incomplete).  A ``KeyboardInterrupt``, so that code that stops on Ctrl-C still does."""

    def __init__(self, message: str, *, time: float, trajectory=None):
        super().__init__(message)
        self.time = time
        self.trajectory = trajectory


class BranchWarning(UserWarning):
    """A run that passed close to a singular configuration of its constraints (where ``A``
    loses rank and two branches of ``Φ = 0`` meet) and left it on another branch than the one
    it came on: the time and the branch test in the message."""


class AccuracyWarning(UserWarning):
    """A run that completed but whose own error estimate says it is less accurate than its
    tolerances ask (e.g. the stepper with ``rtol`` on a motion along which errors grow)."""
