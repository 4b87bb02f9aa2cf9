"""``python -m overbound`` runs the command line."""

from overbound.cli import main

main()
