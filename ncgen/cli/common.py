"""What several subcommands share: writing text output, loading a model file."""
from __future__ import annotations

import os
import sys
from pathlib import Path

from ncgen.errors import NcgenError
from ncgen.files import atomic_path


def write_output(text: str, path: str | None) -> None:
    """``text`` to stdout, or to ``path`` atomically (temporary file in the same directory,
    then rename), so that a failed run never leaves a truncated file."""
    if path is None or path == "-":
        sys.stdout.write(text)
        return
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    print(f"wrote {path}", file=sys.stderr)


#: What every subcommand's MODEL argument accepts (its help text).
MODEL_HELP = "model file: TOML (.toml, see docs/model-format.md), a URDF robot (.urdf) or a MuJoCo MJCF model (.xml)"
#: Suffixes of --plot and --animate, the same in every subcommand.
PLOT_SUFFIXES = (".png", ".pdf", ".svg")
ANIMATE_SUFFIXES = (".gif", ".mp4")


def model_arguments(p) -> None:
    """MODEL, --param and --floating-base: the model options of every subcommand that loads one."""
    p.add_argument("model", metavar="MODEL", help=MODEL_HELP)
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="replace a parameter's default value (repeatable; a vector as NAME=1,2,3)")
    p.add_argument("--floating-base", action="store_true",
                   help="URDF only: the robot's base is free (a 6-DOF free joint to the ground) instead of "
                        "fixed to it")
    mjcf_contacts_argument(p)


def mjcf_contacts_argument(p) -> None:
    """--mjcf-contacts: an MJCF model's geoms as contact shapes (off by default, as in MuJoCo's
    import without a collision model)."""
    p.add_argument("--mjcf-contacts", action="store_true",
                   help="MJCF only (.xml): the geoms collide — each pair MuJoCo's filter lets through (not one "
                        "body, not parent and child, contype/conaffinity, <contact><exclude>) becomes a contact "
                        "with ncgen's compliant law (docs/mjcf.md); without it an MJCF model has no contacts "
                        "and a body falls through the floor")


def file_arguments(p, output: tuple[str, ...] | None, what: str, plot: str | None = None,
                   animate: str | None = None, html: str | None = None) -> None:
    """-o/--output, --plot and --animate with the same rules in every subcommand: each is
    optional, a file is written only when named (atomically, after the work succeeded), and
    the help names every accepted suffix."""
    if output is not None:
        p.add_argument("-o", "--output", metavar="FILE", default=None,
                       help=f"write {what} ({', '.join(output)})")
    if plot is not None:
        p.add_argument("--plot", metavar="FILE", default=None, help=f"also plot {plot} ({', '.join(PLOT_SUFFIXES)})")
    if animate is not None:
        p.add_argument("--animate", metavar="FILE", default=None,
                       help=f"also animate {animate} (.gif, or .mp4 with ffmpeg)")
    if html is not None:
        p.add_argument("--html", metavar="FILE", default=None, help=f"also write {html} (.html)")


def check_files(args, parser, output: tuple[str, ...] | None, directories: tuple[str, ...] = ()) -> None:
    """Usage errors in the output paths, found before any work: -o/--output (a file with one
    of the suffixes ``output``, ``()`` for any; or, when ``"output"`` is in ``directories``,
    a directory), --plot, --animate, --html (files with their suffixes).  A file's directory
    must exist and take a new file, and the path must not be a directory (an MP4 needs ffmpeg,
    checked here too); a directory output may be new (its parents are made) but its nearest existing ancestor must be a
    directory that takes new entries, and it must not be an existing file.  Each message
    names the path as given."""
    kinds = {"output": ("-o/--output", output), "plot": ("--plot", PLOT_SUFFIXES),
             "animate": ("--animate", ANIMATE_SUFFIXES), "html": ("--html", (".html",))}
    for kind, (option, suffixes) in kinds.items():
        name = getattr(args, kind, None)
        if not isinstance(name, str) or (suffixes is None and kind not in directories):
            continue
        if kind in directories:
            problem = directory_problem(name)
        else:
            if suffixes and Path(name).suffix.lower() not in suffixes:
                parser.error(f"{option} {name!r}: expected a file name ending in {' or '.join(suffixes)}")
            problem = file_problem(name)
        if problem:
            parser.error(f"{option} {name!r}: {problem}")
        if kind == "animate" and Path(name).suffix.lower() == ".mp4":
            from ncgen.viz.animation import ffmpeg_executable
            try:
                ffmpeg_executable(name)          # before the run, not after it
            except NcgenError as e:
                parser.error(f"--animate: {e}")


def file_problem(name: str) -> str | None:
    """Why a file cannot be written at ``name`` (a temporary sibling then renamed), or None."""
    path = Path(name)
    if path.is_dir():
        return "is a directory; give a file name"
    parent = path.parent
    if not parent.exists():
        return f"directory {str(parent)!r} does not exist"
    if not parent.is_dir():
        return f"{str(parent)!r} is not a directory"
    return _cannot_create_in(parent)


def directory_problem(name: str) -> str | None:
    """Why a directory cannot be written at ``name`` (made complete in a temporary sibling,
    its parents created), or None."""
    path = Path(name)
    if path.exists() and not path.is_dir():
        return "exists and is not a directory"
    ancestor = Path(os.path.abspath(path)).parent
    while not ancestor.exists():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"{str(ancestor)!r} is not a directory"
    return _cannot_create_in(ancestor)


def _cannot_create_in(directory: Path) -> str | None:
    """Whether a new entry can be made in ``directory``: tried (and removed) rather than
    judged from the permission bits, which a superuser, ACLs or a read-only mount override."""
    import tempfile
    try:
        with tempfile.TemporaryFile(dir=directory):
            pass
    except OSError as exc:
        return f"directory {str(directory)!r} is not writable ({exc.strerror or exc})"
    return None


def missing_model(origin: str, data: dict, command: str, alternative: str = "") -> NcgenError:
    """The error for a problem file ``data`` (read from ``origin``) that names no model: a
    model file given where ``ncgen <command>`` takes a problem file is said to be one."""
    from ncgen.errors import ProblemFileError

    if "system" in data or "members" in data:
        return ProblemFileError(f"{origin}: this is a model file (it has a [system] or [[members]] table), not an "
                                f"optimal-control problem: `ncgen {command}` takes a problem file that names its "
                                f"model (model = \"{Path(origin).name}\"; examples/cartpole_swingup.toml is one)"
                                f"{alternative}")
    return ProblemFileError(f"{origin}: model: missing; name the model file in the problem file "
                            f"(model = \"cartpole.toml\"){alternative}")


def load_model(path: str, params: list[str] | None = None, contacts: str = "smooth", share: bool = True,
               floating_base: bool = False, mjcf_contacts: bool = False):
    """Build the model in TOML file ``path``; ``params`` (``name=value`` strings, a vector as
    ``name=1,2,3``) replace default parameter values.  Raises NcgenError with a message
    naming the file (and the key path, for invalid models).  ``contacts``, ``share``: as in
    ``System.build``; ``floating_base``: for URDF files (``--floating-base``); ``mjcf_contacts``:
    for MJCF files (``--mjcf-contacts``).  A model built
    before from the same file and options is read from the store of built models
    (:mod:`ncgen.codegen.model_cache`; ``NCGEN_MODEL_CACHE=0`` turns it off)."""
    from ncgen.assembly.build import build_model
    from ncgen.codegen import model_cache

    key = None
    if Path(path).is_file() and model_cache.enabled():
        key = model_cache.file_key(path, params=list(params or []), contacts=contacts, share=share,
                                   floating_base=floating_base, mjcf_contacts=mjcf_contacts)

    def build():
        system = load_system(path, params, floating_base, mjcf_contacts)
        try:             # stored under the file's key (or, without one, under the system's by System.build)
            return (build_model(system, contacts=contacts, share=share) if key is not None
                    else system.build(contacts=contacts, share=share))
        except NcgenError as e:
            raise type(e)(f"{path}: model {system.name!r} cannot be built: {e}") from None

    return model_cache.cached(key, build)       # what a run makes is stored as made: a later run derives nothing


def load_system(path: str, params: list[str] | None = None, floating_base: bool = False,
                mjcf_contacts: bool = False):
    """The :class:`~ncgen.model.system.System` in model file ``path`` — a URDF robot
    (``.urdf``: fixed base, joint torques as the input ``tau``), an MJCF model (``.xml``,
    :meth:`~ncgen.model.system.System.from_mjcf`) or TOML (anything else) — with
    ``params`` as in :func:`load_model`; errors name the file."""
    from ncgen.errors import ModelError
    from ncgen.model.system import System

    file = Path(path)
    if not file.is_file():
        what = "is a directory, not" if file.is_dir() else "does not exist; expected"
        raise ModelError(f"model file {path!r} {what} a model file: TOML (.toml), URDF (.urdf) or MJCF (.xml); "
                         "see the examples/ directory")
    suffix = file.suffix.lower()
    urdf = suffix == ".urdf"
    if floating_base and not urdf:
        raise ModelError(f"--floating-base applies to URDF robots (.urdf); {path} is "
                         f"{'an MJCF' if suffix == '.xml' else 'a TOML'} model, whose "
                         "members say themselves how they are held")
    if mjcf_contacts and suffix != ".xml":
        raise ModelError(f"--mjcf-contacts applies to MJCF models (.xml); {path} is "
                         + ("a URDF robot (its <collision> shapes: System.from_urdf(path, collisions=True) in "
                            "Python)" if urdf else "a TOML model, whose [[contacts]] tables give its contacts"))
    try:
        if urdf:
            system = System.from_urdf(file, floating_base=floating_base)
        elif suffix == ".xml":
            system = System.from_mjcf(file, contacts=mjcf_contacts)
        else:
            system = System.from_toml(file)
    except NcgenError as e:
        text = str(e)
        raise type(e)(text if text.startswith(str(file)) else f"{path}: {text}") from None
    for name, value in _parameter_overrides(params or [], system):
        system.parameters[name] = (system.parameters[name][0], value)
    return system


def _parameter_overrides(params: list[str], system) -> list[tuple]:
    import numpy as np

    from ncgen.errors import ModelError

    out = []
    for item in params:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ModelError(f"--param {item!r}: expected NAME=VALUE, e.g. --param k=50")
        if name not in system.parameters:
            known = ", ".join(system.parameters) or "none"
            raise ModelError(f"--param {item!r}: model {system.name!r} has no parameter {name!r} "
                             f"(parameters: {known})")
        size = system.parameters[name][1].size
        try:
            value = np.array([float(x) for x in text.split(",")])
        except ValueError:
            value = np.zeros(0)
        if value.size != size or not np.all(np.isfinite(value)):
            raise ModelError(f"--param {item!r}: expected {size} finite number(s) for {name!r}, "
                             f"separated by commas, got {text!r}")
        out.append((name, value))
    return out
