"""The one base class for errors a user can cause (bad files, bad options).

The CLI prints such an error as one line and exits with status 2; anything else is a bug.
"""


class PlantgenError(Exception):
    """Bad input: the message is one line that names the file and, where it can, the place."""
