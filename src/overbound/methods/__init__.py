"""The papers' procedures, one module each, and the counting KPIs."""
