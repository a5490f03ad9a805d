"""Write a generated C package: CasADi kernels, documented header, build files, manifest.

A package directory ``out_dir`` holds (for package name ``name``)::

    <name>.h               the API: every function documented, metadata as macros/arrays
    <name>_kernels_<k>.c/.h CasADi's code, C symbol of function f is <name>_<f>
    <name>_meta.c          definitions of the metadata arrays
    <name>_data.c          the model's data (initial state): metadata listed in PackageDoc.data
    <extra sources>        hand-written templates rendered next to the kernels
    main.c                 evaluates one function at the default inputs and prints it
    <programs>.c           extra sources marked ``program``: stand-alone example programs
    Makefile, CMakeLists.txt   build lib<name>.so, <name>_main and one executable per program
    manifest.json          signatures, hashes, versions (see ncgen.codegen.manifest)

The output depends only on the inputs (no time, path or host), so it is byte-for-byte
reproducible.  It is rendered completely in a temporary sibling and renamed into place;
an existing ``out_dir`` is replaced only if it is an ncgen package (or empty), and then
only what ncgen wrote there is replaced: the files its manifest lists and what its
Makefile builds.  Anything else in it (notes, results) is kept; generated files edited
by hand make the write refuse rather than lose the edits.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import casadi as ca

from ncgen.codegen import cnames, fsutil, manifest
from ncgen.codegen.doc import PackageDoc, check_identifier
from ncgen.codegen.kernels import c_function, casadi_options, generate_kernels, group_functions, max_function_size
from ncgen.codegen.render import copy_source, render
from ncgen.codegen.reroll import REROLL_INSTRUCTIONS
from ncgen.codegen.signature import function_signature
from ncgen.errors import CodegenError

#: Default bound on SX instructions per kernel file (see ncgen.codegen.kernels).
MAX_FILE_INSTRUCTIONS = 20_000
#: A kernel file holding a function longer than this (SX instructions; functions that an MX
#: function calls included, :func:`~ncgen.codegen.kernels.max_function_size`), or any kernel file
#: of a package longer than LARGE_PACKAGE_INSTRUCTIONS, is listed in the manifest's
#: ``build.large_sources``: gcc's -O2 passes grow faster than linearly with the length of
#: one function and give no faster code than -O1 there (the 31 k-instruction KKT solve of
#: the 40-bar chain's stepper: 4.6 s CPU at -O1, ~9 s at -O2, same speed), so the builds
#: compile those files with ``-O1`` (never ``-O0``, ~3x slower code) unless the user chooses the flags (:func:`ncgen.codegen.compile_cache.
#: compile_package`, the Makefile's ``LARGE_CFLAGS``, CMake).  Long functions are rerolled
#: first (``reroll_instructions``), so this only concerns those with nothing that repeats
#: (or a package written with ``reroll_instructions=None``).
LARGE_FUNCTION_INSTRUCTIONS = 20_000
#: Above this many SX instructions in all, every kernel file is a large source: -O2 costs
#: ~0.5 ms per instruction even for short functions.
LARGE_PACKAGE_INSTRUCTIONS = 200_000
#: Files rendered from the template of the same name plus ".j2".
_FIXED_FILES = ("main.c", "Makefile", "CMakeLists.txt")


@dataclass(frozen=True)
class ExtraSource:
    """A template rendered into the package as ``output``, with ``context`` (plain JSON data)
    added to the common template variables.  ``.c`` outputs are compiled into the library,
    ``.h`` outputs are included at the end of ``<name>.h``.  With ``program=True`` a ``.c``
    output is instead a stand-alone program (it has ``main``): the Makefile and
    CMakeLists.txt build it into the executable named by its stem, linked with the
    library's objects; :func:`~ncgen.codegen.compile_cache.compile_package` ignores it.
    With ``included=True`` the template is a plain C file (no Jinja, e.g. the stepper's
    ``runtime/ncgen_rattle.h``), copied as it is under the banner: a ``.h`` output that
    another source of the package includes, listed among the build's headers (so the
    Makefile and the compile cache depend on it) but not included by ``<name>.h``.
    With ``fatrop=True`` a ``.c`` output of the library includes Fatrop's and BLASFEO's
    headers: the Makefile and CMakeLists.txt compile it with ``-I$FATROP_DIR/include`` and
    link the package with ``libfatrop`` and ``libblasfeo`` from ``FATROP_DIR`` (default: the
    installed CasADi wheel's directory, which ships both)."""

    template: str
    output: str
    context: Mapping = field(default_factory=dict)
    program: bool = False
    included: bool = False
    fatrop: bool = False


@dataclass(frozen=True)
class Package:
    """A package on disk; ``functions`` are the original CasADi functions by name when the
    package was just written (``None`` when opened from disk)."""

    name: str
    path: Path
    manifest: dict
    functions: Mapping[str, ca.Function] | None = None

    @classmethod
    def open(cls, path: str | os.PathLike) -> "Package":
        """The package in directory ``path`` (its manifest is read, files are not checked)."""
        data = manifest.read_manifest(Path(path))
        return cls(name=data["name"], path=Path(path), manifest=data)

    @property
    def content_hash(self) -> str:
        return self.manifest["content_hash"]

    @property
    def function_names(self) -> list[str]:
        return [f["name"] for f in self.manifest["functions"]]

    def c_name(self, function: str) -> str:
        """The exported C symbol of ``function``."""
        for f in self.manifest["functions"]:
            if f["name"] == function:
                return f["c_name"]
        raise CodegenError(f"package {self.name!r} has no function {function!r}; "
                           f"it has {self.function_names}")

    def verify(self) -> None:
        """Raise if a file listed in the manifest is missing or was modified."""
        bad = manifest.modified_files(self.path, self.manifest)
        if bad:
            raise CodegenError(f"package {self.path} was modified after generation (files {bad}); "
                               f"regenerate it instead of editing generated files")


def write_package(name: str, functions: Sequence[ca.Function], out_dir: str | os.PathLike, *,
                  doc: PackageDoc = PackageDoc(),
                  max_file_instructions: int | None = MAX_FILE_INSTRUCTIONS,
                  extra_sources: Sequence[ExtraSource] = (),
                  template_dirs: Sequence[str | os.PathLike] = (),
                  codegen_options: Mapping | None = None,
                  jacobians: Sequence[str] = (),
                  reroll_instructions: int | None = REROLL_INSTRUCTIONS) -> Package:
    """Generate the C package ``name`` for ``functions`` into ``out_dir`` (see module docstring).

    ``max_file_instructions`` bounds the SX instructions per kernel file (``None``: one
    file, ``0``: one file per function).  ``template_dirs`` are searched before the shipped
    templates (for ``extra_sources``).  ``codegen_options`` are extra CasADi CodeGenerator
    options (``with_header``, ``main``, ``mex``, ``cpp`` are fixed by ncgen).
    ``jacobians`` names functions whose Jacobian (CasADi's ``f.jacobian()``: the inputs of
    ``f``, then its nominal outputs; one block ``jac_<out>_<in>`` per output/input pair) is
    generated too, as C symbol ``jac_<name>_<f>``: the symbol ``casadi.external`` looks up to
    differentiate ``<name>_<f>``, so functions loaded from the compiled package have exact
    derivatives (IDAS needs them, for instance).  Functions (and Jacobians) longer than
    ``reroll_instructions`` SX instructions are generated as loops over short kernels where
    they repeat alike blocks (:mod:`ncgen.codegen.reroll`; ``None``: always straight-line).
    """
    out_dir = Path(out_dir)
    check_identifier("package name", name)
    functions = _checked_functions(functions)
    _check_doc(doc, functions)
    _check_extra_sources(name, extra_sources)
    fsutil.check_target(out_dir, check_replaceable)
    options = {"max_file_instructions": max_file_instructions, "reroll_instructions": reroll_instructions,
               "casadi_options": casadi_options(codegen_options),
               "extra_sources": [[s.template, s.output, dict(s.context)] + (["program"] if s.program else [])
                                 + (["included"] if s.included else []) + (["fatrop"] if s.fatrop else [])
                                 for s in extra_sources]}
    if jacobians:
        options["jacobians"] = _checked_jacobians(jacobians, functions)
    files = _render_files(name, functions, doc, options, extra_sources, template_dirs)
    with fsutil.temporary_sibling(out_dir) as tmp:
        for rel, blob in files.items():
            (tmp / rel).write_bytes(blob)
        fsutil.default_mode_dir(tmp)
        written = manifest.read_manifest(tmp)
        publish(tmp, out_dir)
    return Package(name=name, path=out_dir, manifest=written, functions={f.name(): f for f in functions})


def _render_files(name: str, functions: list[ca.Function], doc: PackageDoc, options: dict,
                  extra_sources: Sequence[ExtraSource], template_dirs) -> dict[str, bytes]:
    """Every file of the package, relative name -> bytes, manifest last."""
    c_funcs, kernel_funcs, kernels = _kernels(name, functions, options)
    with_jac = set(options.get("jacobians", ()))
    file_of = {c: k.stem + ".c" for k in kernels for c in k.functions}
    header = f"{name}.h"
    fn_info = [_function_info(name, f, c, file_of[c.name()], doc, f.name() in with_jac)
               for f, c in zip(functions, c_funcs)]
    qp_sources = sorted({file_of[c.name()] for f, c in zip(functions, c_funcs) if f.class_name() == "Qrqp"})
    build = _build_section(name, kernels, kernel_funcs, qp_sources, bool(doc.data), extra_sources)
    context = {
        "name": name, "NAME": name.upper(), "header": header, "summary": cnames.c_comment(doc.summary),
        "casadi_version": ca.__version__, "functions": fn_info, "build": build,
        "metadata": _metadata_info(name, doc), "main_function": doc.main_function or functions[0].name(),
        "included_headers": [s.output for s in extra_sources if s.included],
    }
    cnames.unique_macros([m["macro"] + suffix for m in context["metadata"]
                          for suffix in (("", "_LEN") if "len" in m else ("",))]
                         + [a["macro"] for f in fn_info for a in f["inputs"] + f["outputs"]])
    files = _rendered(kernels, context, extra_sources, template_dirs)
    data = {rel: text.encode() for rel, text in files.items()}
    data[manifest.FILENAME] = manifest.manifest_text(
        name=name, content_hash=manifest.content_hash(name, data, doc.to_json(), options),
        functions=[_manifest_entry(f) for f in fn_info], build=build, metadata=dict(doc.metadata),
        files=data).encode()
    return data


def _kernels(name: str, functions: list[ca.Function], options: dict):
    """``(C functions, kernel functions, kernel files)``: each function as the C function
    ``<name>_<f>`` (rerolled beyond ``reroll_instructions``), with its Jacobian
    ``jac_<name>_<f>`` where ``options["jacobians"]`` names it, grouped into files of at most
    ``max_file_instructions``."""
    limit = options["reroll_instructions"]
    c_funcs = [c_function(f, f"{name}_{f.name()}", limit) for f in functions]
    with_jac = set(options.get("jacobians", ()))
    kernel_funcs = []
    for f, c in zip(functions, c_funcs):
        kernel_funcs.append(c)
        if f.name() in with_jac:
            kernel_funcs.append(c_function(f.jacobian(), f"jac_{c.name()}", limit))
    kernels = generate_kernels(name, kernel_funcs,
                               group_functions(kernel_funcs, options["max_file_instructions"]),
                               options["casadi_options"])
    return c_funcs, kernel_funcs, kernels


def _build_section(name: str, kernels, kernel_funcs, qp_sources: list[str], with_data: bool,
                   extra_sources: Sequence[ExtraSource]) -> dict:
    """The manifest's ``build`` table: sources, headers, main, library and executable names,
    the large sources (compiled at a lower optimisation), the files holding CasADi's qrqp,
    the data source and the extra programs."""
    data_c = f"{name}_data.c" if with_data else None
    build = {"sources": [k.stem + ".c" for k in kernels] + [f"{name}_meta.c"] + ([data_c] if data_c else [])
             + [s.output for s in extra_sources if s.output.endswith(".c") and not s.program],
             "headers": [f"{name}.h"] + [k.stem + ".h" for k in kernels]
             + [s.output for s in extra_sources if s.output.endswith(".h")],
             "main": "main.c", "library": f"lib{name}.so", "executable": f"{name}_main"}
    largest = {k.stem + ".c": max(max_function_size(f) for f in kernel_funcs if f.name() in k.functions)
               for k in kernels}
    huge = sum(f.n_instructions() for f in kernel_funcs) > LARGE_PACKAGE_INSTRUCTIONS
    build["large_sources"] = [src for src, n in largest.items() if huge or n > LARGE_FUNCTION_INSTRUCTIONS]
    if qp_sources:                  # files holding CasADi's qrqp: a gcc warning off (templates/c/Makefile.j2)
        build["qp_sources"] = qp_sources
    fatrop = [s.output for s in extra_sources if s.fatrop]
    if fatrop:                      # files including Fatrop's headers, the package linked to it (templates/c/Makefile.j2)
        build["fatrop_sources"] = fatrop
    if data_c:
        build["data"] = [data_c]
    programs = [s.output for s in extra_sources if s.program]
    if programs:
        build["programs"] = programs
    return build


def _rendered(kernels, context: dict, extra_sources: Sequence[ExtraSource], template_dirs) -> dict[str, str]:
    """The package's text files from their templates: the kernel files, the metadata (and
    data) sources, the extra sources, the header and the fixed files."""
    name, header = context["name"], context["header"]
    files: dict[str, str] = {}
    for k in kernels:
        files[k.stem + ".c"] = render("kernels.c.j2", k.stem + ".c",
                                      {**context, "code": k.c_code, "kernel_functions": k.functions})
        files[k.stem + ".h"] = render("kernels.h.j2", k.stem + ".h",
                                      {**context, "code": k.h_code, "guard": k.stem.upper() + "_H"})
    entries = context["metadata"]
    meta_c = f"{name}_meta.c"
    files[meta_c] = render("meta.c.j2", meta_c, {**context, "metadata": [m for m in entries if not m["data"]],
                                                 "data": False})
    if "data" in context["build"]:
        data_c = f"{name}_data.c"
        files[data_c] = render("meta.c.j2", data_c, {**context, "metadata": [m for m in entries if m["data"]],
                                                     "data": True})
    for s in extra_sources:
        files[s.output] = (copy_source(s.template, s.output) if s.included else
                           render(s.template, s.output, {**context, **s.context}, template_dirs))
    files[header] = render("header.h.j2", header, context)
    for fixed in _FIXED_FILES:
        files[fixed] = render(fixed + ".j2", fixed, context)
    return files


def _check_extra_sources(name: str, extra_sources: Sequence[ExtraSource]) -> None:
    """Outputs must be new plain file names; contexts must be plain JSON data."""
    taken = {*_FIXED_FILES, f"{name}.h", f"{name}_meta.c", f"{name}_data.c", manifest.FILENAME}
    for s in extra_sources:
        if s.output in taken or Path(s.output).name != s.output or s.output.startswith(f"{name}_kernels_"):
            raise CodegenError(f"extra source output {s.output!r} must be a plain file name, not one of "
                               f"{sorted(taken)} nor {name}_kernels_*, and not used twice")
        taken.add(s.output)
        if s.included and (s.program or not s.output.endswith(".h") or s.context):
            raise CodegenError(f"extra source {s.output!r} is included by another source: its output must "
                               f"be a .h file, not a program, and it takes no context (it is copied as it is)")
        if s.fatrop and (s.program or s.included or not s.output.endswith(".c")):
            raise CodegenError(f"extra source {s.output!r} includes Fatrop's headers: its output must be a .c "
                               f"file of the library, not a program nor an included file")
        if s.program and (not s.output.endswith(".c") or s.output[:-2] in (f"{name}_main", "main")):
            raise CodegenError(f"extra source {s.output!r} is a program: its output must be a .c file "
                               f"whose stem names the executable (not {name}_main)")
        try:
            manifest.canonical_json(dict(s.context))
        except (TypeError, ValueError) as e:
            raise CodegenError(f"context of extra source {s.output!r} must be plain JSON data: {e}") from None


def _checked_functions(functions) -> list[ca.Function]:
    functions = list(functions)
    if not functions:
        raise CodegenError("write_package needs at least one casadi.Function, found none")
    seen = set()
    for f in functions:
        if not isinstance(f, ca.Function):
            raise CodegenError(f"expected casadi.Function objects, found {type(f).__name__} {f!r}")
        check_identifier("function name", f.name())
        if f.name() in seen:
            raise CodegenError(f"two functions are named {f.name()!r}; names must be unique")
        seen.add(f.name())
        for i in range(f.n_in()):
            check_identifier(f"input {i} name of {f.name()}", f.name_in(i))
        for i in range(f.n_out()):
            check_identifier(f"output {i} name of {f.name()}", f.name_out(i))
    return functions


def _check_doc(doc: PackageDoc, functions: list[ca.Function]) -> None:
    """Every name the doc mentions must exist; defaults must have the right length."""
    by_name = {f.name(): f for f in functions}
    if doc.main_function is not None and doc.main_function not in by_name:
        raise CodegenError(f"PackageDoc.main_function is {doc.main_function!r}, not one of the "
                           f"functions {list(by_name)}")
    for fname, fdoc in doc.functions.items():
        f = by_name.get(fname)
        if f is None:
            raise CodegenError(f"PackageDoc.functions documents {fname!r}, which is not one of the "
                               f"functions {list(by_name)}")
        for kind, names in (("inputs", f.name_in()), ("outputs", f.name_out())):
            for arg in getattr(fdoc, kind):
                if arg not in names:
                    raise CodegenError(f"PackageDoc.functions[{fname!r}].{kind} documents {arg!r}, "
                                       f"which is not one of the {kind} of {fname}: {list(names)}")
    for f in functions:
        for i, arg in enumerate(f.name_in()):
            key = doc.defaults.get(arg)
            if key is not None and len(doc.metadata[key]) != f.nnz_in(i):
                raise CodegenError(f"default of input {arg!r} of {f.name()} (metadata {key!r}) has "
                                   f"{len(doc.metadata[key])} values, expected nnz = {f.nnz_in(i)}")


def check_replaceable(out_dir: Path) -> None:
    """Raise unless ``out_dir`` is absent, an empty directory or an ncgen package whose
    generated files are as generated (an edited one would be lost)."""
    if not out_dir.exists():
        return
    if not out_dir.is_dir():
        raise CodegenError(f"refusing to write the package to {out_dir}: it exists and is not a directory")
    if not any(out_dir.iterdir()):
        return
    try:
        data = manifest.read_manifest(out_dir)
    except CodegenError as e:
        raise CodegenError(f"refusing to replace {out_dir}: it exists and is not an ncgen package "
                           f"({e}); remove it yourself or choose another output directory") from None
    edited = [rel for rel in manifest.modified_files(out_dir, data) if (out_dir / rel).exists()]
    if edited:
        raise CodegenError(f"refusing to replace {out_dir}: its generated files {', '.join(edited)} were "
                           f"edited after generation and would be lost; move them elsewhere (or delete "
                           f"them) first")


def generated_entries(out_dir: Path, data: dict) -> set[str]:
    """Top-level names in the package ``out_dir`` that ncgen wrote: the manifest and its
    files, and what the package's Makefile builds from them (objects, library, programs)."""
    build = data.get("build", {})
    names = {manifest.FILENAME, *(rel.split("/")[0] for rel in data.get("files", {}))}
    names |= {rel[:-2] + ".o" for rel in data.get("files", {}) if rel.endswith(".c")}
    names |= {build.get("library", ""), build.get("executable", "")}
    names |= {prog[:-2] for prog in build.get("programs", ())}
    return names - {""}


def user_entries(out_dir: Path) -> list[str]:
    """Top-level entries of the package ``out_dir`` that ncgen did not write (the user's
    notes, results, a CMake build folder): kept when the package is regenerated."""
    data = manifest.read_manifest(out_dir)
    ours = generated_entries(out_dir, data)
    return sorted(p.name for p in out_dir.iterdir() if p.name not in ours)


def publish(new: Path, out_dir: Path) -> None:
    """Put the complete package ``new`` in place of ``out_dir``, replacing only what ncgen
    wrote there (:func:`user_entries` are moved into the new package); refuses (before
    touching anything) if a user's entry has the name of a new generated file."""
    def carry(target: Path) -> list[str]:
        names = user_entries(target) if any(target.iterdir()) else []
        clash = [n for n in names if (new / n).exists()]
        if clash:
            raise CodegenError(f"refusing to replace {target}: {', '.join(clash)} was not written by "
                               f"ncgen but the new package writes a file of that name; move it away")
        return names
    fsutil.replace_dir(new, out_dir, check_replaceable, carry)


def _checked_jacobians(jacobians: Sequence[str], functions: list[ca.Function]) -> list[str]:
    names = [jacobians] if isinstance(jacobians, str) else list(jacobians)
    known = [f.name() for f in functions]
    bad = [n for n in names if n not in known]
    if bad or len(set(names)) != len(names):
        raise CodegenError(f"jacobians must name distinct functions of the package, found {names}; "
                           f"the functions are {known}")
    return names


def _function_info(name: str, f: ca.Function, c: ca.Function, file: str, doc: PackageDoc,
                   with_jacobian: bool = False) -> dict:
    """Template data of one function: signature plus documentation."""
    fdoc = doc.functions.get(f.name())
    sig = function_signature(f)
    cname = c.name()

    def args(kind: str, io: str) -> list[dict]:
        out = []
        for i, a in enumerate(sig[kind]):
            adoc = getattr(fdoc, kind).get(a["name"]) if fdoc else None
            default = doc.defaults.get(a["name"]) if kind == "inputs" else None
            if default is not None and not doc.metadata[default]:
                default = None          # an empty array has no C definition: zeros (of nothing)
            out.append({**a, "index": i, "meaning": cnames.c_comment(adoc.meaning) if adoc else "",
                        "units": cnames.c_comment(adoc.units) if adoc else "",
                        "default": f"{name}_{default}" if default else None,
                        "macro": f"{cname}_{io}_{a['name']}_NNZ".upper()})
        return out

    return {"name": f.name(), "c_name": cname, "file": file, "n_instructions": c.n_instructions(),
            "purpose": cnames.c_comment(fdoc.purpose) if fdoc else "",
            "jacobian": f"jac_{cname}" if with_jacobian else None,
            "inputs": args("inputs", "in"), "outputs": args("outputs", "out")}


def _manifest_entry(info: dict) -> dict:
    keep = ("name", "shape", "nnz", "dense", "colind", "row")
    entry = {"name": info["name"], "c_name": info["c_name"], "file": info["file"],
             "n_instructions": info["n_instructions"],
             "inputs": [{k: a[k] for k in keep} for a in info["inputs"]],
             "outputs": [{k: a[k] for k in keep} for a in info["outputs"]]}
    if info["jacobian"]:
        entry["jacobian"] = info["jacobian"]
    return entry


def _metadata_info(name: str, doc: PackageDoc) -> list[dict]:
    """Template data of the metadata: macro name, C spelling and kind of each entry."""
    out = []
    for key, value in doc.metadata.items():
        item = {"key": key, "macro": f"{name}_{key}".upper(), "c_name": f"{name}_{key}",
                "doc": cnames.c_comment(doc.metadata_doc.get(key, "")), "data": key in doc.data}
        if isinstance(value, int):
            item.update(kind="int", literal=str(value))
        elif isinstance(value, float):
            item.update(kind="real", literal=cnames.c_real(value))
        elif isinstance(value, str):
            item.update(kind="string", literal=cnames.c_string(value))
        elif value and isinstance(value[0], str):
            item.update(kind="string_array", len=len(value),
                        lines=cnames.wrap([cnames.c_string(v) for v in value], 4))
        else:
            item.update(kind="real_array", len=len(value), lines=cnames.wrap([cnames.c_real(v) for v in value], 4))
        out.append(item)
    return out
