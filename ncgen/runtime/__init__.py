"""ncgen.runtime"""
