"""Leaves written as cards (``plantgen export --leaves cards``): each plant's leaf polygons
replaced by their cards (:mod:`plantgen.geometry.meshes.leaf_cards`), which glTF writes as
alpha-cut quads over one atlas of the leaf shapes."""

from __future__ import annotations

from dataclasses import replace

from ..geometry.meshes.leaf_cards import leaf_cards
from .formats import ExportError
from .plants import Plant

__all__ = ["LEAF_MODES", "card_plant"]

#: How ``--leaves`` writes a grammar's leaves: their polygons, or cards.
LEAF_MODES = ("polygons", "cards")


def card_plant(plant: Plant, tile: int = 64) -> Plant:
    """``plant`` with its leaves as cards (their quads in ``leaves``, the atlas in
    ``cards``; ``tile`` texels a shape); a plant without leaves as it is. One line when
    the leaves have too many distinct shapes for an atlas."""
    if not plant.has_leaves:
        return plant
    try:
        cards = leaf_cards(plant.leaves, tile=tile)
    except ValueError as err:
        raise ExportError(f"{plant.name}: {err}") from None
    return replace(plant, leaves=cards.polygons, cards=cards)
