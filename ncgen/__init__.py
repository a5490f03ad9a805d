"""ncgen: rigid multibody dynamics in natural coordinates."""
__version__ = "0.1.0"
