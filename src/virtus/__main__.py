"""``python -m virtus`` runs the command line."""

from virtus.cli import main

main()
