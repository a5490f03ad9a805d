"""ncgen.assembly"""
