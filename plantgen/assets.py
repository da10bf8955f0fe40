"""Assets that engines take as they are (``plantgen export --asset game``): levels of detail
(swaying where the model sways, every level on one skeleton), leaf cards, an octahedral
impostor baked by the ray caster as the last level, textures, each level within a stated
triangle budget.

:class:`AssetSettings` holds the knobs; :func:`finished_plants` turns the tessellated
plants into what is written (the impostor baked from the polygon leaves before they
become cards); :func:`budget_warnings` says where a level is over its budget.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from .exporters import ExportError
from .exporters.cards import LEAF_MODES, card_plant
from .exporters.plants import Plant
from .knobs import check_knobs, knob
from .limits import GAME_LEVEL_TRIANGLES
from .settings import LevelSettings

__all__ = ["ASSET_PRESETS", "GAME_LEVELS", "AssetSettings", "asset_lines", "budget_warnings", "finished_plants"]

#: What ``--asset`` takes.
ASSET_PRESETS = ("game",)
#: Levels of detail a game asset gets unless ``--lod-levels`` says otherwise.
GAME_LEVELS = 4


@dataclass(frozen=True)
class AssetSettings:
    """How the plants are written for an engine (glTF).

    asset : None, or ``"game"``: levels of detail (:data:`GAME_LEVELS` unless asked),
        leaf cards, an impostor, textures, and the triangle budgets checked
    leaves : ``"polygons"``, or ``"cards"`` (:mod:`plantgen.geometry.meshes.leaf_cards`); None:
        cards for a game asset, else polygons
    impostor : bake an octahedral impostor as the last level (None: for a game asset)
    impostor_frames, impostor_size : its N×N views and its atlas's side in texels
    """

    asset: str | None = knob(None, "--asset", "glTF: game writes what an engine takes: 4 levels of detail (swaying "
                             "where the model sways), leaf cards, an octahedral impostor baked by the ray caster as "
                             "the last level, and textures, at m = 0 unless --subdiv is given, each level "
                             "checked against its triangle budget.",
                             kind="choice", choices=ASSET_PRESETS)
    leaves: str | None = knob(None, "--leaves", "glTF: a grammar's leaves as their polygons, or as cards: one "
                              "alpha-cut quad per leaf polygon over an atlas of the distinct leaf shapes (alphaMode "
                              "MASK, each leaf's shade kept). Default: cards with --asset game, else polygons.",
                              kind="choice", choices=LEAF_MODES)
    impostor: bool | None = knob(None, "--impostor", "glTF: bake a (hemi-)octahedral impostor by RC+R "
                                 "as the last level of detail (base colour, normal, depth). Default: with --asset "
                                 "game.", kind="bool", flag="--impostor/--no-impostor")
    impostor_frames: int = knob(8, "--impostor-frames", "Impostor: N×N views.", kind="int", lo=2, hi=32, metavar="N")
    impostor_size: int = knob(1024, "--impostor-size", "Impostor: the atlas's side in texels (a multiple of N).",
                              kind="int", lo=64, hi=4096, metavar="TEXELS")

    def __post_init__(self):
        check_knobs(self)
        if self.impostor_size % self.impostor_frames:
            raise ExportError(f"--impostor-size {self.impostor_size} must be a multiple of --impostor-frames "
                              f"{self.impostor_frames}")

    @property
    def game(self) -> bool:
        return self.asset == "game"

    @property
    def leaf_mode(self) -> str:
        return self.leaves or ("cards" if self.game else "polygons")

    @property
    def baked(self) -> bool:
        return self.impostor if self.impostor is not None else self.game

    def levels(self, levels: LevelSettings | None) -> LevelSettings | None:
        """``levels``, or :data:`GAME_LEVELS` for a game asset where none were asked."""
        if self.game and (levels is None or levels.levels is None):
            return LevelSettings(levels=GAME_LEVELS)
        return levels

    def check(self, fmt, path) -> None:
        """One line where the format cannot hold what is asked (cards, impostor: glTF)."""
        if (self.leaf_mode == "cards" or self.baked or self.game) and fmt.name not in ("glb", "gltf"):
            raise ExportError(f"{path}: leaf cards, impostors and --asset game are written by glTF (.glb, .gltf) "
                              "only")


def finished_plants(plants: list[Plant], settings: AssetSettings, skin, relief: bool, progress=None) -> list[Plant]:
    """The plants as written: with an impostor baked from the plant's frusta (``skin`` of
    its skeleton, as tessellated) and polygon leaves (``relief``: RC+R) where asked, then
    their leaves as cards where asked."""
    if settings.baked:
        from .gl.impostor import bake_impostor

        out = []
        for plant in plants:
            frusta = skin(plant.skeleton)
            impostor = bake_impostor(frusta, plant.mesh.material_names, plant.leaves if plant.has_leaves else None,
                                     frames=settings.impostor_frames, size=settings.impostor_size, relief=relief,
                                     progress=progress)
            out.append(replace(plant, impostor=impostor))
        plants = out
    if settings.leaf_mode == "cards":
        plants = [card_plant(p) for p in plants]
    return plants


def budget_warnings(levels: list[tuple[int, int]], settings: AssetSettings, copies: int = 1) -> list[str]:
    """Lines for the levels ([(rows, triangles)], summed over the distinct plants) over a
    game asset's budgets (:data:`~plantgen.limits.GAME_LEVEL_TRIANGLES`, per distinct plant,
    the impostor's two triangles apart); empty when none is or the asset is not a game's."""
    if not settings.game:
        return []
    out = []
    for k, (_, triangles) in enumerate(levels):
        budget = GAME_LEVEL_TRIANGLES[min(k, len(GAME_LEVEL_TRIANGLES) - 1)] * copies
        if triangles > budget:
            out.append(f"--asset game: level {k} has {triangles:,} triangles, over its budget of {budget:,} "
                       "(lower --subdiv, or fewer segments)")
    return out


def asset_lines(plants: list[Plant]) -> list[str]:
    """What the command says of the cards and impostors written (empty: none)."""
    out = []
    cards = [p.cards for p in plants if p.cards is not None]
    if cards:
        shapes = sum(c.atlas.shapes for c in cards)
        size = cards[0].atlas.image.shape
        out.append(f"leaf cards: {sum(len(c.polygons) for c in cards):,} cards (2 triangles each) over {shapes:,} "
                   f"leaf {'shape' if shapes == 1 else 'shapes'} ({size[1]}x{size[0]} atlas, alpha cut at 0.5)")
    impostors = [p.impostor for p in plants if p.impostor is not None]
    if impostors:
        i = impostors[0]
        out.append(f"impostor: {i.frames}x{i.frames} views, {i.size}x{i.size} atlas ({i.tile} texels a view; "
                   f"colour, normal, depth; {'hemi-octahedral' if i.hemi else 'octahedral'}) as the last level, "
                   f"baked on {i.renderer}")
    return out
