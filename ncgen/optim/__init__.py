"""ncgen.optim"""
