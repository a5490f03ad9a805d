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
from ncgen.codegen.compile_cache import BuildResult, compile_package
from ncgen.codegen.doc import ArgDoc, FunctionDoc, PackageDoc
from ncgen.codegen.load import NoCompilerWarning, load_functions
from ncgen.codegen.package import ExtraSource, Package, write_package

__all__ = ["ArgDoc", "FunctionDoc", "PackageDoc", "ExtraSource", "Package", "write_package",
           "BuildResult", "compile_package", "NoCompilerWarning", "load_functions"]
