"""Compiled code and its registry: the bottom floor of the package (table below, filled in the next commit)."""
