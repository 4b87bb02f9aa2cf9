"""``python -m overbound`` runs the command line."""

from overbound.cli import main

if __name__ == "__main__":
    main()
