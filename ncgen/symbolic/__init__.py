"""ncgen.symbolic"""
