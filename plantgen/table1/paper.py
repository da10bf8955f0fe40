"""What Bhagvat et al. 2009 measured: Table 1 (NVidia 8800 GTX, 1024x768) and the memory
claim of §4. Printed beside our numbers, never used as ours."""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["PaperLevel", "PaperRow", "PAPER_TABLE1", "TABLE1_MODELS", "PAPER_MEMORY_RATIO"]


class PaperLevel(NamedTuple):
    """A polygonal method's column of Table 1: its fps and the subdivision level it used."""

    fps: int
    sub: int


class PaperRow(NamedTuple):
    """One model of Table 1 (indexable as the plain tuple it replaces)."""

    segments: int
    rc_fps: int
    rcr_fps: int
    gs: PaperLevel
    gsr: PaperLevel

    @property
    def rcr_over_gsr(self) -> float:
        """RC+R fps over GS+R fps, the ratio the paper's numbers imply."""
        return self.rcr_fps / self.gsr.fps


#: Table 1 of the paper, in its order, keyed by the shipped grammar/scene names.
PAPER_TABLE1 = {
    "coconut": PaperRow(3713, 83, 71, PaperLevel(240, 1), PaperLevel(63, 2)),
    "pine": PaperRow(16997, 34, 16, PaperLevel(55, 1), PaperLevel(15, 2)),
    "elm": PaperRow(1833, 193, 20, PaperLevel(375, 1), PaperLevel(102, 2)),
    "aloe": PaperRow(229, 171, 20, PaperLevel(820, 2), PaperLevel(53, 4)),
    "saguaro": PaperRow(30, 305, 105, PaperLevel(830, 2), PaperLevel(54, 4)),
    "well": PaperRow(8, 303, 105, PaperLevel(296, 2), PaperLevel(21, 4)),
    "desert": PaperRow(799, 421, 151, PaperLevel(1100, 0), PaperLevel(79, 2)),
    "oasis": PaperRow(18557, 46, 31, PaperLevel(174, 0), PaperLevel(13, 2)),
    "dancing_cacti": PaperRow(2158, 35, 33, PaperLevel(170, 0), PaperLevel(12, 2)),
}
#: The nine models of Table 1, in the paper's order.
TABLE1_MODELS = tuple(PAPER_TABLE1)
#: §4: "the vertices for polygons at the same sampling density will take twelve times as
#: much space" as the 8-bit relief map.
PAPER_MEMORY_RATIO = 12.0
