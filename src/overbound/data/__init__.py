"""Embedded data files (see PROVENANCE.md)."""
