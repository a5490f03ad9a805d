"""ncgen.codegen: model-agnostic C code generation, compilation and loading.

``write_package`` turns CasADi functions plus documentation into a C package directory,
``compile_package`` builds it into a cached shared library and ``load_functions`` returns
callable CasADi functions backed by it (or by CasADi's virtual machine).
"""
from ncgen.codegen.build import BuildResult, compile_package
from ncgen.codegen.doc import ArgDoc, FunctionDoc, PackageDoc
from ncgen.codegen.load import NoCompilerWarning, load_functions
from ncgen.codegen.package import ExtraSource, Package, write_package

__all__ = ["ArgDoc", "FunctionDoc", "PackageDoc", "ExtraSource", "Package", "write_package",
           "BuildResult", "compile_package", "NoCompilerWarning", "load_functions"]
