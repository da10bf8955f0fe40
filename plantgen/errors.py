"""The one base class for errors a user can cause (bad files, bad options).

The CLI prints such an error as one line and exits with status 2; anything else is a bug.
"""


class PlantgenError(Exception):
    """Bad input: the message is one line that names the file and, where it can, the place."""


def missing_extra(what: str, extra: str) -> str:
    """The one wording of a missing optional feature: ``what`` needs the ``extra`` extra,
    and the command that installs it (from plantgen's folder, as the README installs it).

    >>> missing_extra("plantgen view", "view")
    "plantgen view needs the view extra: pip install '.[view]' (in plantgen's folder)"
    """
    return f"{what} needs the {extra} extra: pip install '.[{extra}]' (in plantgen's folder)"
