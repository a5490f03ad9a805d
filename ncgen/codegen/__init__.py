"""ncgen.codegen: C code generation, compilation and loading.

Two parts.  Generic, for any CasADi functions: ``write_package`` turns functions plus
documentation into a C package directory (:mod:`~ncgen.codegen.package`),
``compile_package`` builds it into a shared library cached by content
(:mod:`~ncgen.codegen.compile_cache`) and ``load_functions`` returns callable CasADi
functions backed by it or by CasADi's virtual machine (:mod:`~ncgen.codegen.load`).
For models: :func:`~ncgen.codegen.model_package.generate` assembles a model's package from
sections — its system functions and the compiled stepper
(:mod:`~ncgen.codegen.stepper_package`).
"""
from importlib import import_module

#: public name -> module defining it (imported on first use, so that reading a stored model
#: through :mod:`~ncgen.codegen.model_cache` does not import the generator and Jinja2)
_NAMES = {"ArgDoc": "doc", "FunctionDoc": "doc", "PackageDoc": "doc", "ExtraSource": "package",
          "Package": "package", "write_package": "package", "BuildResult": "compile_cache",
          "compile_package": "compile_cache", "NoCompilerWarning": "load", "load_functions": "load"}

__all__ = list(_NAMES)


def __getattr__(name: str):
    if name not in _NAMES:
        raise AttributeError(f"module 'ncgen.codegen' has no attribute {name!r}")
    value = getattr(import_module(f"ncgen.codegen.{_NAMES[name]}"), name)
    globals()[name] = value
    return value
