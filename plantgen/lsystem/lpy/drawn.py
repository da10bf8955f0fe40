"""The drawn-as table: how L-Py's predefined modules map onto plantgen's.

The turtle modules plantgen draws (:data:`TURTLE`), those it needs no drawing for
(:data:`SILENT`), the tropism modules, those it cannot draw (:data:`UNDRAWN`, dropped with a
warning), those it draws through an interpretation rule of its own (:data:`DRAWN_AS`:
``nF``, ``Frame``, ``@O``/``Sphere``) and those refused (:data:`REFUSED_MODULES`); and
:class:`DrawnAs`, the reader's part that writes modules back as plantgen text, each L-Py
module under its plantgen symbol."""

from __future__ import annotations

import numpy as np

from ..symbols import ARITY, SYMBOLS
from .common import Mod

# ------------------------------------------------------------------ L-Py's predefined modules
#: L-Py's turtle modules that plantgen draws, by L-Py name: the plantgen symbol. L-Py names
#: ``/`` roll left and ``\\`` roll right (ABOP the other way round), so they swap here.
TURTLE: dict[str, str] = {
    "F": "F", "f": "f", "+": "+", "Left": "+", "-": "-", "Right": "-", "&": "&", "Down": "&",
    "^": "^", "Up": "^", "/": "\\", "RollL": "\\", "iRollL": "\\", "\\": "/", "RollR": "/", "iRollR": "/",
    "|": "|", "TurnAround": "|", "[": "[", "SB": "[", "]": "]", "EB": "]", "{": "{", "BP": "{",
    "}": "}", "EP": "}", ".": ".", "PP": ".", "%": "%", "Cut": "%", "$": "$", "@v": "$", "RollToVert": "$",
    "!": "!", "DecWidth": "!", "_": "!", "IncWidth": "!", "SetWidth": "!", ";": ";", "IncColor": ";",
    "SetColor": ";", "~l": "~",
    "?P": "?P", "GetPos": "?P", "?H": "?H", "GetHead": "?H", "?U": "?U", "GetUp": "?U", "?L": "?L",
    "GetLeft": "?L", "?E": "?E",
}
#: Modules that need no drawing in plantgen: generalised cylinders (plantgen skins every
#: axis as one), ``None``.
SILENT = {"@Gc", "StartGC", "@Ge", "EndGC", "None"}
#: Tropism modules: the grammar's one tropism (constant arguments only).
TROPISM = {"@Ts": "strength", "Elasticity": "strength", "@Tp": "direction", "Tropism": "direction"}
#: L-Py drawing modules plantgen cannot draw: dropped with one warning each.
UNDRAWN = {
    "@O": "sphere", "Sphere": "sphere", "@o": "circle", "Circle": "circle", "@M": "move to", "MoveTo": "move to",
    "MoveRel": "relative move", "@R": "set heading", "SetHead": "set heading", "Pinpoint": "pinpoint",
    "PinpointRel": "pinpoint", "EulerAngles": "Euler angles", "LeftReflection": "reflection",
    "UpReflection": "reflection", "HeadingReflection": "reflection", "@2D": "screen projection",
    "@3D": "screen projection", "StartScreenProjection": "screen projection",
    "EndScreenProjection": "screen projection", "@Dd": "scale", "DivScale": "scale", "@Di": "scale",
    "MultScale": "scale", "@D": "scale", "SetScale": "scale", "nF": "n-step path", "@B": "box", "Box": "box",
    "@b": "quad", "Quad": "quad", "@L": "label", "Label": "label", "Frame": "frame", "SetContour": "contour",
    "SectionResolution": "section resolution", "SetGuide": "guide", "EndGuide": "guide", "Sweep": "sweep",
    "PositionOnGuide": "guide", "LineTo": "line to", "OLineTo": "line to", "LineRel": "relative line",
    "OLineRel": "relative line", "InterpolateColors": "colour interpolation", ",": "previous colour",
    "DecColor": "previous colour", "?R": "right-vector query", "GetRight": "right-vector query",
    "?F": "frame query", "GetFrame": "frame query", "MouseIns": "mouse insertion",
    "TextureScale": "texture", "TextureUScale": "texture", "TextureVScale": "texture", "TextureVCoeff": "texture",
    "TextureTranslation": "texture", "TextureRotation": "texture", "TextureTransformation": "texture",
    "surface": "named surface",
}
#: L-Py's arguments for a drawing module written without any.
DEFAULT_ARGS = {"Frame": ["1"]}
#: Frusta approximating one sphere ``@O(r)``.
SPHERE_SEGMENTS = 6


def _frame(size: str) -> str:
    axis = f"!(({size}) / 20) F({size})"
    return f"[{axis}][+(90) {axis}][^(90) {axis}]"


def _sphere(r: str) -> str:
    k = SPHERE_SEGMENTS
    steps = " ".join(f"F(2 * ({r}) / {k}, ({r}) * {float(np.sqrt(max(0.0, 1 - (-1 + 2 * (i + 1) / k) ** 2)))!r})"
                     for i in range(k))
    return f"[f(-({r})) !(0) {steps}]"


#: L-Py drawing modules plantgen draws through an interpretation rule of its own: per
#: module, its least parameters and the plantgen string its parameters p0, p1, ... give.
#: ``nF(length, dx)``: a path of ``length`` in steps of ``dx``, drawn as one segment of the
#: whole length (the steps differ from it only under a guide, which plantgen does not draw).
#: ``Frame(size)`` (L-Py's default size 1): three axes of length ``size`` and radius
#: ``size/20`` along H, L and U, each in a branch. ``@O(r)`` (``Sphere``): a chain of
#: :data:`SPHERE_SEGMENTS` frusta along H from ``-r`` to ``r`` about the turtle, their end
#: radii ``sqrt(r² - z²)`` (on the sphere, 0 at both poles), in a branch.
DRAWN_AS = {"nF": (2, "F(p0)"), "Frame": (1, _frame("p0")), "@O": (1, _sphere("p0")),
            "Sphere": (1, _sphere("p0"))}
#: L-Py constructs refused wherever they appear, with why.
REFUSED_MODULES = {
    "@g": "PlantGL shapes (@g) are not supported", "PglShape": "PlantGL shapes (PglShape) are not supported",
    "*": "the any-module pattern '*' is not supported", "=]": "the '=]' pattern is not supported",
    "?I": "lstring iterators (?I) are not supported", "GetIterator": "lstring iterators are not supported",
    "GetModule": "module requests are not supported", "new": "modules created by name (new) are not supported",
    "newmodule": "modules created by name are not supported", "or": "'or' patterns are not supported",
    "repexp": "repetition patterns are not supported", "all": "repetition patterns are not supported",
    "any": "the any-module pattern is not supported",
}
NAMED = set(TURTLE) | SILENT | set(TROPISM) | set(UNDRAWN) | set(REFUSED_MODULES)
SPECIAL = sorted((n for n in NAMED if not n[0].isalpha() and n[0] != "_" and len(n) > 1), key=len, reverse=True)
PLANTGEN_CHARS = {s.char for s in SYMBOLS} | set("(),:<>") | {"#"}
CANDIDATES = ("ABCDEHIJKMNOPQRSTVWXYZabcdeghijklmnopqrstuvwxyz"
               + "".join(chr(c) for c in range(0x391, 0x3AA) if chr(c).isalpha())
               + "".join(chr(c) for c in range(0x3B1, 0x3CA))
               + "".join(chr(c) for c in range(0x410, 0x450)))


def turtle_params(sym: str) -> int:
    """How many parameters plantgen's turtle symbol ``sym`` takes at most (``~``: after
    the surface's name)."""
    arity = ARITY.get(sym)
    return (max(arity) - (sym == "~")) if arity else 0


class DrawnAs:
    """The reader's part that writes modules as plantgen text: each L-Py module's plantgen
    symbol, the ``ignore`` list, a rule's text."""

    def _ignore(self) -> str:
        syms = []
        for kind, text, line in self.decls:
            mods = self._lstring(text, line, {}, pattern=True)
            mods = [m for m in mods if m.name in self.names or m.name in TURTLE]    # unused names match nothing
            if kind == "ignore":
                syms += [self._symbol(m.name) for m in mods]
            else:
                keep = {self._symbol(m.name) for m in mods}
                used = {self._symbol(m.name) for m in self.axiom}
                for sec in self.rules.values():
                    for r in sec:
                        used |= {self._symbol(m.name) for m in (*r[0][0], *r[0][1], *r[1], *r[2], *r[4])}
                syms += sorted(s for s in used if s not in keep and s not in "[]%" and len(s) == 1)
        return "".join(dict.fromkeys(s for s in syms if len(s) == 1 and s not in "[]"))

    def _symbol(self, name: str, nargs: int = 0) -> str:
        """The plantgen symbol of an L-Py module written with ``nargs`` parameters."""
        if name in self.carried and nargs > turtle_params(TURTLE[name]):
            return self.names[name]
        return TURTLE.get(name) or self.names[name]

    def _text(self, mods: list[Mod], pattern: bool = False) -> str:
        out = []
        for m in mods:
            sym = self._symbol(m.name, len(m.args))
            args = [a if isinstance(a, str) else a.text for a in m.args]
            if m.name in ("_", "IncWidth") and not args:
                self.dropped[m.name] = self.dropped.get(m.name, 0) + 1
                continue
            if sym == ";":
                self.used_colour = True
                if len(args) > 1:
                    self.dropped["SetColor"] = self.dropped.get("SetColor", 0) + 1
                    continue
            if m.name == "~l" and sym == "~":
                args = ["leaf", *args[:1]]
            if sym in ("?P", "?H", "?U", "?L") and len(args) == 3:
                args = [args[1], args[2], args[0]]          # L-Py's (x, y, z) with z up: plantgen's (y, z, x)
            if sym in ("{", "}", "F", "f", "+", "-", "&", "^", "\\", "/", "!") and len(args) > {
                    "{": 0, "}": 0, "F": 2}.get(sym, 1):
                args = args[:{"{": 0, "}": 0, "F": 2}.get(sym, 1)]
            out.append(sym + (f"({', '.join(args)})" if args else ""))
        return " ".join(out)

    def _rule_text(self, rule) -> object:
        (left, new_left), pred, right, cond, succ, line, p, effects = rule
        lhs = self._text(pred, True)
        if new_left:
            lhs = f"{self._text(new_left, True)} << {lhs}"
        if left:
            lhs = f"{self._text(left, True)} < {lhs}"
        if right:
            lhs = f"{lhs} > {self._text(right, True)}"
        if cond:
            lhs = f"{lhs} : {cond[0]}"
        text = f"{lhs} -> {self._text(succ)}".rstrip()
        if len(text) > 100_000:
            raise self.refuse(line, "a rule over 100,000 characters once translated")
        live = {k: v.text for k, v in effects if k in self.globals}
        if not live:
            return text if p is None else {"rule": text, "p": p}
        return {"rule": text, **({} if p is None else {"p": p}), "set": live}
