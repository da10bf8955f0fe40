"""A scan's settings and its result: :class:`ScanSettings` (every option of ``plantgen scan``,
checked), the point labels (:data:`LABELS`, :data:`PART_NAMES`) and :class:`PointCloud`.
The scan itself: :mod:`plantgen.geometry.rays.scan`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...errors import PlantgenError
from ...knobs import check_knobs, knob

#: The parts a point may belong to, by the ``part`` label's value.
PART_NAMES = ("stem", "branch", "leaf")


STEM, BRANCH, LEAF = 0, 1, 2


#: How a scan is made.
SCAN_MODES = ("terrestrial", "airborne")


class ScanError(PlantgenError, ValueError):
    """Scan settings or a scan that plantgen cannot make."""


def _positions(value) -> tuple | None:
    """Scanner positions as a tuple of (x, y, z) float triples, from 'x,y,z;x,y,z' or a
    sequence of triples; None stays None."""
    if value is None:
        return None
    given = value
    if isinstance(value, str):
        items = [p for p in value.replace(" ", "").split(";") if p]
        value = [p.split(",") for p in items]
    try:
        out = tuple(tuple(float(c) for c in p) for p in value)
    except (TypeError, ValueError):
        raise ScanError(f"--scanner-positions must be 'x,y,z;x,y,z...' (numbers), got {given!r}") from None
    if not out or any(len(p) != 3 or not all(math.isfinite(c) for c in p) for p in out):
        raise ScanError(f"--scanner-positions must be finite x,y,z triples separated by ';', got {given!r}")
    return out


@dataclass(frozen=True)
class ScanSettings:
    """A laser scan's knobs (see the module docstring). Lengths are model units (metres
    for the shipped grammars), angles degrees, the divergence milliradians."""

    mode: str = knob("terrestrial", "--scan-mode", "Terrestrial scanners around the plant, or airborne flight "
                     "lines over it.", kind="choice", choices=SCAN_MODES)
    angular_step: float = knob(0.05, "--angular-step", "Degrees between neighbouring beams (azimuth and elevation; "
                               "airborne: across the track).", lo=0.001, hi=10.0, metavar="DEG")
    range_noise: float = knob(0.0, "--range-noise", "Gaussian sigma of each range, model units (0: exact).",
                              lo=0.0, hi=1e6, metavar="SIGMA")
    divergence: float = knob(0.0, "--divergence", "Beam divergence, full angle in milliradians (0: ideal rays; "
                             "terrestrial scanners have about 0.3).", lo=0.0, hi=100.0, metavar="MRAD")
    beam_samples: int = knob(8, "--beam-samples", "Sub-rays sampled across a diverging beam.", kind="int", lo=1,
                             hi=256, metavar="N")
    beam_return: str = knob("first", "--beam-return", "A diverging beam's range: its sub-rays' nearest hit (first) "
                            "or their mean (mixed pixels at edges).", kind="choice", choices=("first", "mean"))
    scanners: int = knob(4, "--scanners", "Terrestrial scanners evenly on a circle around the plant.", kind="int",
                         lo=1, hi=360, metavar="N")
    distance: float | None = knob(None, "--scan-distance", "Radius of the scanners' circle around the plant's centre "
                                  "(model units; default: the plant's height plus half its width).", lo=1e-6,
                                  hi=1e9, metavar="D")
    scanner_height: float = knob(1.5, "--scanner-height", "Terrestrial scanners' height above the plant's base "
                                 "(model units).", lo=-1e9, hi=1e9, metavar="H")
    azimuth: float = knob(0.0, "--scan-azimuth", "Degrees: the first scanner's direction from the plant (0: +x, "
                          "90: +z); airborne: the flight lines' heading.", metavar="DEG")
    positions: tuple | None = knob(None, "--scanner-positions", "Terrestrial scanners at these points instead of "
                                   "the circle: 'x,y,z;x,y,z' (model units, the plant's frame).", kind="str",
                                   metavar="X,Y,Z;...")
    flight_height: float | None = knob(None, "--flight-height", "Airborne: the lines' height above the plant's base "
                                       "(default: twice the plant's height).", lo=1e-6, hi=1e9, metavar="H")
    line_spacing: float | None = knob(None, "--line-spacing", "Airborne: distance between flight lines (default: "
                                      "half the swath, or the pulse spacing for nadir lines).", lo=1e-9, hi=1e9,
                                      metavar="D")
    pulse_spacing: float | None = knob(None, "--pulse-spacing", "Airborne: distance between scan lines along the "
                                       "track (default: the beams' spacing at the nadir, on the ground).", lo=1e-9,
                                       hi=1e9, metavar="D")
    scan_angle: float = knob(30.0, "--scan-angle", "Airborne: the mirror's sweep, degrees either side of the nadir "
                             "(0: nadir beams only).", lo=0.0, hi=75.0, metavar="DEG")
    precision: str = knob("float64", "--scan-precision", "float64: the exact reference on the CPU; float32: each "
                          "beam's primitive found on the GPU in float32, its range then solved in float64 (the "
                          "reference's ranges; without GL the frusta tested in float32 on the CPU). plantgen scan "
                          "without it: float32 where a GL context exists, else float64.",
                          kind="choice", choices=("float64", "float32"))

    def __post_init__(self):
        check_knobs(self, ScanError)
        object.__setattr__(self, "positions", _positions(self.positions))
        if not math.isfinite(self.scanner_height) or not math.isfinite(self.azimuth):
            raise ScanError("--scanner-height and --scan-azimuth must be finite numbers")

    @property
    def sub_rays(self) -> int:
        """Rays cast per beam: ``beam_samples`` with a divergence, else 1."""
        return self.beam_samples if self.divergence > 0 else 1

    def describe(self) -> str:
        """One line: what the scan is."""
        beam = (f"divergence {self.divergence:g} mrad ({self.sub_rays} sub-rays, {self.beam_return} return)"
                if self.divergence > 0 else "ideal rays")
        return (f"{self.mode}, step {self.angular_step:g}°, range noise {self.range_noise:g}, {beam}, "
                f"{self.precision}")


# ============================================================================ the point cloud
#: Per-point label arrays of a :class:`PointCloud` and their dtypes.
LABELS = {"plant": np.int32, "part": np.uint8, "order": np.int16, "segment": np.int32, "leaf": np.int32,
          "scanner": np.uint16}


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points of a scan, in scan order (scanner by scanner, beam by beam), model units, y up.

    ======================  ==========  ========================================================
    ``xyz``                 (m, 3) f8   the points
    ``plant``               (m,) i4     the plant (the ``plant`` given to :func:`scan_plant`)
    ``part``                (m,) u1     index into :data:`PART_NAMES`: stem, branch, leaf
    ``order``               (m,) i2     branch order (a leaf: its segment's; -1: none)
    ``segment``             (m,) i4     skeleton segment (a leaf: the one it hangs from; -1)
    ``leaf``                (m,) i4     leaf polygon, -1 for wood
    ``scanner``             (m,) u2     the scanner (airborne: the flight line)
    ``scanners``            (s, 3) f8   each scanner's position (airborne: its line's centre)
    ``metadata``            dict        the settings and seed that made it (JSON values)
    ======================  ==========  ========================================================
    """

    xyz: np.ndarray
    plant: np.ndarray
    part: np.ndarray
    order: np.ndarray
    segment: np.ndarray
    leaf: np.ndarray
    scanner: np.ndarray
    scanners: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    metadata: dict = field(default_factory=dict)

    def __post_init__(self):
        xyz = np.ascontiguousarray(self.xyz, dtype=np.float64).reshape(-1, 3)
        object.__setattr__(self, "xyz", xyz)
        for name, dtype in LABELS.items():
            arr = np.ascontiguousarray(getattr(self, name), dtype=dtype).reshape(-1)
            if arr.shape != (len(xyz),):
                raise ValueError(f"PointCloud.{name} has {arr.shape[0]} values for {len(xyz)} points")
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "scanners", np.asarray(self.scanners, dtype=np.float64).reshape(-1, 3))

    def __len__(self) -> int:
        return len(self.xyz)

    @classmethod
    def empty(cls, scanners=None, metadata=None) -> PointCloud:
        return cls(np.zeros((0, 3)), *(np.zeros(0, dtype) for dtype in LABELS.values()),
                   scanners=np.zeros((0, 3)) if scanners is None else scanners, metadata=dict(metadata or {}))

    def labels(self) -> dict[str, np.ndarray]:
        """The label arrays by name (:data:`LABELS` order)."""
        return {name: getattr(self, name) for name in LABELS}

    def bounds(self) -> np.ndarray:
        """(2, 3) the points' box (zeros for none)."""
        if not len(self):
            return np.zeros((2, 3))
        return np.stack([self.xyz.min(axis=0), self.xyz.max(axis=0)])

    def subset(self, keep) -> PointCloud:
        """The points ``keep`` selects ((m,) bool or indices), same scanners and metadata."""
        return PointCloud(self.xyz[keep], *(a[keep] for a in self.labels().values()), scanners=self.scanners,
                          metadata=self.metadata)
