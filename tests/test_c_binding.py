"""The stepper's C interface is written once (ncgen/codegen/stepper_abi.py) and every loader
binds from it: the table is checked here against the prototypes and the options struct of
the committed packages' headers (generated from templates/c/stepper.h.j2; the packages with
contacts, which ship ncgen_contact.h, have the trailing impulse arguments)."""
from __future__ import annotations

import ctypes
import ctypes.util
import re
from pathlib import Path

import pytest

from ncgen.codegen.c_binding import Signature, bind, c_type, ctypes_of, open_library
from ncgen.codegen.stepper_abi import FUNCTIONS, RUN_OPTIONS, STEP_OPTIONS, RunOptions, StepOptions, signature
from ncgen.errors import CodegenError

ROOT = Path(__file__).resolve().parents[1]
HEADERS = sorted((ROOT / "generated").glob("*/*_stepper.h"))


def prototypes(text: str, name: str) -> dict[str, tuple[str, list[str]]]:
    """``{suffix: (return type, [(argument type, name)])}`` of the functions ``name_<suffix>``
    declared in ``text``."""
    code = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    found = {}
    for returns, suffix, args in re.findall(rf"^(\w[\w ]*?)\s+{name}_(\w+)\(([^)]*)\);", code, flags=re.M | re.S):
        args = [] if args.strip() == "void" else [a for a in args.split(",")]
        found[suffix] = (returns.strip(), [(c_type(re.sub(r"\w+\s*$", "", a)), a.split()[-1].lstrip("*"))
                                           for a in args])
    return found


def options_struct(text: str, name: str, struct: str = "step_options") -> list[tuple[str, str]]:
    """The fields ``(C type, name)`` of the struct ``{name}_{struct}`` declared in ``text``."""
    body = re.search(r"typedef struct \{([^{}]*)\}\s*" + name + "_" + struct + ";", text).group(1)
    body = re.sub(r"/\*.*?\*/", " ", body, flags=re.S)
    return [(c_type(m.group(1)), m.group(2)) for m in re.finditer(r"([\w ]+?\s*\*?)\s*(\w+);", body)]


def test_the_committed_packages_have_stepper_headers_with_and_without_contacts():
    kinds = {(h.parent / "ncgen_contact.h").exists() for h in HEADERS}
    assert len(HEADERS) >= 2 and kinds == {True, False}


@pytest.mark.parametrize("header", HEADERS, ids=lambda h: h.parent.name)
def test_table_matches_the_generated_header(header):
    name = header.name[:-len("_stepper.h")]
    contacts = (header.parent / "ncgen_contact.h").exists()
    declared = prototypes(header.read_text(), name)
    assert set(declared) == set(FUNCTIONS), "the header's functions and the table's differ"
    for suffix, (returns, args) in declared.items():
        sig = signature(suffix, contacts)
        assert c_type(sig.returns.format(name=name)) == returns, suffix
        assert list(zip(sig.types(name), [n for _, n in sig.args])) == args, suffix
    assert options_struct(header.read_text(), name) == [(c_type(t), f) for t, f in STEP_OPTIONS]
    assert options_struct(header.read_text(), name, "run_options") == [(c_type(t), f) for t, f in RUN_OPTIONS]


def test_the_run_options_struct_matches_the_stepper_headers():
    """``{name}_run_options`` (the options of an error-controlled run, passed to C whole) as
    the stepper header template and the element library declare it is RUN_OPTIONS, and
    RunOptions is made from it."""
    from ncgen.codegen.element_kernels import PACKAGE

    expected = [(c_type(t), f) for t, f in RUN_OPTIONS]
    header = (ROOT / "templates" / "c" / "stepper.h.j2").read_text().replace("{{ name }}", "m")
    assert options_struct(header, "m", "run_options") == expected
    assert options_struct(template("element_tables.c.j2", name=PACKAGE), PACKAGE, "run_options") == expected
    assert [(f, t) for f, t in RunOptions._fields_] == [(f, ctypes_of(t, {}, False)) for t, f in RUN_OPTIONS]


def test_ctypes_of_binds_typed_pointers_or_addresses():
    structs = {"m_step_options": StepOptions}
    assert ctypes_of("const casadi_real *", structs, False) is ctypes.POINTER(ctypes.c_double)
    assert ctypes_of("long *", structs, False) is ctypes.POINTER(ctypes.c_long)
    assert ctypes_of("const m_step_options *", structs, False) is ctypes.POINTER(StepOptions)
    assert ctypes_of("const m_step_options *", structs, True) is ctypes.c_void_p
    assert ctypes_of("volatile int *", structs, False) is ctypes.POINTER(ctypes.c_int)
    assert ctypes_of("size_t", structs, True) is ctypes.c_size_t
    assert [f for f, _ in StepOptions._fields_] == [f for _, f in STEP_OPTIONS]
    with pytest.raises(CodegenError, match=r"C type 'float \*': expected one of"):
        ctypes_of("float *", structs, False)


def test_a_library_or_symbol_that_is_not_there_is_named(tmp_path):
    with pytest.raises(CodegenError, match=r"cannot load the compiled library .*nothing\.so"):
        open_library(tmp_path / "nothing.so")
    libc = open_library(ctypes.util.find_library("c") or "libc.so.6")
    with pytest.raises(CodegenError, match=r"no function 'm_simulate'"):
        bind(libc, "m_simulate", FUNCTIONS["simulate"], name="m")
    strlen = bind(libc, "strlen", Signature("size_t", (("const void *", "s"),)))
    assert strlen(b"natural") == 7


def test_joint_run_matches_the_joint_loop_template():
    """``<name>_joint_run`` and ``<name>_joint_work_size`` as templates/c/joint_loop.c.j2 (the
    model's glue around runtime/ncgen_joint_loop.h) defines them are JOINT_RUN and JOINT_WORK_SIZE."""
    from ncgen.codegen.joint_loop import JOINT_RUN, JOINT_WORK_SIZE

    declared = definitions(template("joint_loop.c.j2", name="m"), "m_joint_")
    assert_table_matches({"run": JOINT_RUN, "work_size": JOINT_WORK_SIZE}, declared)


def definitions(text: str, prefix: str) -> dict[str, tuple[str, list[tuple[str, str]]]]:
    """``{suffix: (return type, [(argument type, name)])}`` of the functions ``prefix<suffix>``
    declared or defined in the C ``text`` (a template with ``{{ name }}`` already replaced)."""
    code = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    found = {}
    for returns, suffix, args in re.findall(rf"^(\w[\w ]*?[\s*]+){prefix}(\w*)\(([^)]*)\)\s*[;{{]", code,
                                            flags=re.M | re.S):
        args = [] if args.strip() == "void" else args.split(",")
        found[suffix] = (c_type(returns), [(c_type(re.sub(r"\w+\s*$", "", a)), re.search(r"(\w+)\s*$", a).group(1))
                                           for a in args])
    return found


def assert_table_matches(table: dict, declared: dict, name: str = "m") -> None:
    """Every signature of ``table`` (by suffix) is declared so in ``declared``."""
    for suffix, sig in table.items():
        assert suffix in declared, f"{suffix}: not in the C source"
        returns, args = declared[suffix]
        assert c_type(sig.returns.format(name=name)) == returns, suffix
        assert list(zip(sig.types(name), [n for _, n in sig.args])) == args, suffix


def template(relative: str, **values) -> str:
    """templates/c/``relative`` with ``{{ key }}`` replaced by ``values[key]``."""
    text = (ROOT / "templates" / "c" / relative).read_text()
    for key, value in values.items():
        text = text.replace("{{ " + key + " }}", value)
    return text


def element_library_definitions(package: str, contacts: dict | None) -> dict:
    """:func:`definitions` of templates/c/element_tables.c.j2 rendered for the library
    ``package`` (with ``contacts``: the contact library's variant), the structs by full name."""
    import jinja2

    from ncgen.codegen.render import environment

    env = environment()
    env.undefined = jinja2.ChainableUndefined      # the numbers of the kinds do not matter here
    text = env.get_template("element_tables.c.j2").render(name=package, contacts=contacts, joint_kinds=[],
                                                          member_kinds=[], feature_force_kinds=[], torque_kinds=[])
    for struct in ("step_options", "run_options"):           # the template's short names of the structs
        alias = f"typedef {package}_{struct} {struct};"
        assert alias in text
        text = text.replace(alias, "").replace(f" {struct} *", f" {package}_{struct} *")
    return definitions(text, f"{package}_")


def test_the_element_library_tables_match_element_tables_template():
    """The element library's entry points (table_library.SIGNATURES), its stepper's
    (table_stepper.SIGNATURES) and its step Jacobians (table_step.SIGNATURE), as
    templates/c/element_tables.c.j2 defines them."""
    from ncgen.codegen.element_kernels import PACKAGE
    from ncgen.runtime import table_library, table_step, table_stepper

    declared = element_library_definitions(PACKAGE, None)
    assert_table_matches(table_library.SIGNATURES, declared, name=PACKAGE)
    assert_table_matches(table_stepper.SIGNATURES, declared, name=PACKAGE)
    assert_table_matches({"step_jacobians": table_step.SIGNATURE}, declared, name=PACKAGE)


def test_the_contact_library_tables_match_element_tables_template():
    """The contact library's entry points: the element library's, its stepper's loops with the
    trailing impulse arguments of a contact stepper (table_stepper._signatures(True)), no step
    Jacobians."""
    from ncgen.codegen.element_kernels import CONTACT_PACKAGE
    from ncgen.runtime import table_library, table_stepper

    declared = element_library_definitions(CONTACT_PACKAGE, {"kinds": []})
    assert_table_matches(table_library.SIGNATURES, declared, name=CONTACT_PACKAGE)
    assert_table_matches(table_stepper._signatures(True), declared, name=CONTACT_PACKAGE)
    assert "step_jacobians" not in declared


def test_the_tree_library_table_matches_tree_tables_template():
    from ncgen.runtime.tree_library import SIGNATURES

    declared = definitions(template("tree_tables.c.j2", name="m"), "m_")
    assert_table_matches(SIGNATURES, declared)


def test_the_contact_library_table_matches_contact_active_template():
    from ncgen.control.contact_active import SIGNATURES

    declared = definitions(template("contact_active.c.j2", name="m", **{"loop.index0": "0"}), "m_")
    assert_table_matches({"law_0": SIGNATURES["law"], "lu_columns": SIGNATURES["lu_columns"]}, declared)


def test_the_casadi_table_matches_a_generated_kernel_header():
    """casadi_abi.FUNCTIONS as CasADi declares a generated function (the first one of each
    committed kernels header)."""
    from ncgen.codegen.casadi_abi import FUNCTIONS

    headers = sorted((ROOT / "generated").glob("*/*_kernels_0.h"))
    assert headers
    for header in headers[:3]:
        text = header.read_text()
        fn = re.search(r"^int (\w+)\(const casadi_real\*\* arg", text, flags=re.M).group(1)
        assert_table_matches(FUNCTIONS, definitions(text, fn))


def test_a_bound_casadi_function_evaluates_and_sizes_its_work():
    """bind_casadi on a function compiled here: ``y = x₀ x₁`` and its gradient, against the
    product rule."""
    import casadi as ca
    import numpy as np

    from ncgen.codegen.casadi_abi import bind_casadi, work_arrays
    from ncgen.codegen.direct import compile_direct

    x = ca.SX.sym("x", 2)
    f = ca.Function("prod_grad", [x], [x[0] * x[1], ca.gradient(x[0] * x[1], x)])
    direct = compile_direct("cabi_prod", f)
    y, g = direct(np.array([3.0, -2.0]))
    assert y[0] == -6.0 and list(g) == [-2.0, 3.0]
    abi = bind_casadi(direct._lib, direct.c_name)
    iw, w = work_arrays(abi, direct.c_name)
    assert iw.dtype == np.int64 and iw.size >= 1 and w.size >= 1
    with pytest.raises(CodegenError, match=r"no function 'cabi_nothing'"):
        bind_casadi(direct._lib, "cabi_nothing")


def test_the_joint_options_struct_matches_the_joint_loop_header():
    """``ncgen_joint_options`` as templates/c/runtime/ncgen_joint_loop.h declares it is
    JOINT_OPTIONS (JointOptions is made from it; its stop flag an int pointer)."""
    from ncgen.codegen.joint_loop import JOINT_OPTIONS, JointOptions

    text = (ROOT / "templates" / "c" / "runtime" / "ncgen_joint_loop.h").read_text()
    body = re.sub(r"/\*.*?\*/", " ", re.search(r"typedef struct \{(.*?)\}\s*ncgen_joint_options;", text,
                                               flags=re.S).group(1), flags=re.S)
    declared = [(c_type(m.group(1)), m.group(2)) for m in re.finditer(r"([\w ]+?\s*\*?)\s*(\w+);", body)]
    assert declared == [(c_type(t), f) for t, f in JOINT_OPTIONS]
    assert JointOptions._fields_[-1][1] is ctypes.POINTER(ctypes.c_int)


def test_the_mpc_loop_table_matches_the_mpc_header_template():
    """The in-process controller's entry points (ncgen.control.mpc_c_loop.SIGNATURES), as
    templates/c/mpc/mpc.h.j2 declares them."""
    from ncgen.control.mpc_c_loop import SIGNATURES

    declared = definitions(template("mpc/mpc.h.j2", name="m"), "m_")
    assert_table_matches(SIGNATURES, declared)
