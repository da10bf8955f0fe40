"""``--help`` in sections: a command's options grouped under headings (Output, Camera,
Quality, Effects, Limits...) instead of one long list.

click has no grouping of its own. An option made by :func:`plantgen.cli.options.knob_options`
carries the section of the settings it belongs to (:data:`SETTINGS_SECTIONS`); a command
made with ``cls=SectionedCommand`` may name the section of any other parameter
(``sections={"seed": MODEL}``), and lays its options out section by section, in
:data:`ORDER`. An option no one placed goes under "Other options".
"""

from __future__ import annotations

import click

__all__ = ["CAMERA", "EFFECTS", "LIMITS", "MODEL", "ORDER", "OTHER", "OUTPUT", "QUALITY", "SETTINGS_SECTIONS",
           "SectionedCommand", "SectionedOption", "section_of"]

OUTPUT, CAMERA, QUALITY, EFFECTS, MODEL, LIMITS, OTHER = (
    "Output", "Camera", "Quality", "Effects", "Model", "Limits", "Other options")
#: The order of the sections in ``--help``.
ORDER = (OUTPUT, CAMERA, QUALITY, EFFECTS, MODEL, LIMITS, OTHER)

#: The widest option name that keeps its help text on its line (click's default).
COL_MAX = 30

#: The section of each settings class's knobs (a knob of a class not named here: OTHER).
SETTINGS_SECTIONS = {
    "EffectSettings": EFFECTS, "ShadowSettings": EFFECTS, "LookSettings": EFFECTS,
    "RaycastSettings": QUALITY, "DetailSettings": QUALITY, "MeshSettings": QUALITY, "ParallaxSettings": QUALITY,
    "ImageSettings": OUTPUT, "MotionSettings": OUTPUT, "LevelSettings": OUTPUT, "KeyframeSettings": OUTPUT,
    "AssetSettings": OUTPUT,
    "ViewSettings": CAMERA, "Orbit": CAMERA,
}


def section_of(owner: type) -> str:
    """The section of the knobs of the settings class ``owner``."""
    return SETTINGS_SECTIONS.get(owner.__name__, OTHER)


class SectionedOption(click.Option):
    """A click option that knows its ``--help`` section."""

    def __init__(self, *args, section: str | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.section = section


class SectionedCommand(click.Command):
    """A command whose ``--help`` lists its options section by section: a parameter's
    section is ``sections[name]``, else its own (:class:`SectionedOption`), else OTHER."""

    def __init__(self, *args, sections: dict[str, str] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.sections = dict(sections or {})

    def section(self, param: click.Parameter) -> str:
        """The ``--help`` section of ``param``."""
        return self.sections.get(param.name) or getattr(param, "section", None) or OTHER

    def grouped(self, ctx: click.Context) -> dict[str, list[tuple[str, str]]]:
        """{section: help records} in :data:`ORDER` (sections not in it after, as met)."""
        groups: dict[str, list[tuple[str, str]]] = {}
        for param in self.get_params(ctx):
            record = param.get_help_record(ctx) if isinstance(param, click.Option) else None
            if record is not None:
                groups.setdefault(self.section(param), []).append(record)
        known = [name for name in ORDER if name in groups]
        return {name: groups[name] for name in known + [n for n in groups if n not in ORDER]}

    def format_options(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        groups = self.grouped(ctx)
        # one column for the help texts in every section, as click lays out one list
        width = min(max((len(term) for records in groups.values() for term, _ in records), default=0), COL_MAX)
        for name, records in groups.items():
            with formatter.section(name):
                formatter.write_dl([(term.ljust(width), text) for term, text in records], col_max=COL_MAX)
