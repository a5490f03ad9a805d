"""ncgen.codegen"""
