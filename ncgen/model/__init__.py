"""ncgen.model"""
