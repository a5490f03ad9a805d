"""Jinja2 templates shipped with ncgen (installed as the package ncgen._templates)."""
