"""Figures, JSON and the HTML report."""
