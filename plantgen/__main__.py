"""``python -m plantgen``: the same command line as the ``plantgen`` script."""

from .cli import main

main()
