"""ncgen.viz"""
