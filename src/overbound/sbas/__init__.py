"""DO-229 SBAS user engine (issue 6)."""
