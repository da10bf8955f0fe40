"""A scanner's beams: the counter-based random numbers (SplitMix64) every scan draws from, the
terrestrial and airborne beam grids (:class:`TerrestrialBeams`, :class:`AirborneBeams`), the
scanner positions and the sub-rays of a diverging beam. The patterns are described in
:mod:`plantgen.geometry.rays.scan`'s docstring ("Beams", "Beam divergence", "Determinism")."""

from __future__ import annotations

import math

import numpy as np

from ...limits import LimitError, Limits, hint
from ...limits import limits as default_limits
from ..vec import cross, unit
from .scan_settings import ScanSettings
from .scan_targets import ScanTarget

#: Vogel's golden angle, between successive sub-rays of a diverging beam.
GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


#: Random streams of the counter-based generator.
_NOISE_A, _NOISE_B, _TURN = 1, 2, 3


# ============================================================================ random numbers
_GAMMA = np.uint64(0x9E3779B97F4A7C15)


def _mix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser of uint64 values (wrapping arithmetic)."""
    with np.errstate(over="ignore"):
        z = x + _GAMMA
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        return z ^ (z >> np.uint64(31))


def _uniform(seed: int, scanner: int, stream: int, ids) -> np.ndarray:
    """(k,) uniform numbers in (0, 1), a function of (seed, scanner, stream, id) alone."""
    key = np.array([int(seed) & (2 ** 64 - 1)], dtype=np.uint64)
    for value in (scanner, stream):
        key = _mix(key ^ np.uint64(int(value) & (2 ** 64 - 1)))
    z = _mix(_mix(np.asarray(ids, dtype=np.int64).astype(np.uint64) ^ key))
    return ((z >> np.uint64(11)).astype(np.float64) + 0.5) * 2.0 ** -53


def normal_noise(seed: int, scanner: int, ids) -> np.ndarray:
    """(k,) standard normal numbers per id (Box-Muller of two streams)."""
    u1, u2 = _uniform(seed, scanner, _NOISE_A, ids), _uniform(seed, scanner, _NOISE_B, ids)
    return np.sqrt(-2.0 * np.log(u1)) * np.cos(2.0 * np.pi * u2)


# ============================================================================ beam grids
def _wrap(angle):
    """Angles brought into [-π, π)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


#: How far past a grid step a box's edge may fall and still take that step's beam (in
#: steps): with the boxes' padding, what keeps rounding from losing a beam.
STEP_SLACK = 1e-9


def _first(x) -> np.ndarray:
    """The first grid index at or after ``x`` (in steps), less :data:`STEP_SLACK`."""
    return np.ceil(np.asarray(x) - STEP_SLACK).astype(np.int64)


def _last(x) -> np.ndarray:
    """The last grid index at or before ``x`` (in steps), plus :data:`STEP_SLACK`."""
    return np.floor(np.asarray(x) + STEP_SLACK).astype(np.int64)


def _xz_corners(lo, hi) -> np.ndarray:
    """(k, 4, 2) the corners of boxes' horizontal (x, z) rectangles."""
    x = np.stack([lo[:, 0], hi[:, 0], hi[:, 0], lo[:, 0]], axis=1)
    z = np.stack([lo[:, 2], lo[:, 2], hi[:, 2], hi[:, 2]], axis=1)
    return np.stack([x, z], axis=-1)


def _trig_of_steps(steps, step: float, start: float | None = None):
    """((cos, sin) of angles, indices of ``steps`` into them): of ``start + steps·step``
    (``steps·step`` without a start), each angle the same float either way: taken once
    for each step of the range a 1-d run of integer ``steps`` spans where that range is
    the shorter, else for every step."""
    steps = np.asarray(steps)
    span = int(steps.max()) - int(steps.min()) + 1 if steps.ndim == 1 and len(steps) else 0
    if np.issubdtype(steps.dtype, np.integer) and 0 < span < len(steps):
        lo = int(steps.min())
        angle, at = np.arange(lo, lo + span, dtype=np.float64) * step, steps - lo
    else:
        angle, at = steps.astype(np.float64) * step, ...
    if start is not None:
        angle = start + angle
    return (np.cos(angle), np.sin(angle)), at


class TerrestrialBeams:
    """The beam grid of a scanner at ``position`` looking at the box (``lo``, ``hi``):
    beam (a, b) at azimuth φ_c + a·Δ and elevation b·Δ (module docstring), a in
    [a0, a0 + na), b in [b0, b0 + nb)."""

    def __init__(self, position, lo, hi, step: float):
        self.origin = np.asarray(position, dtype=np.float64)
        self.step = float(step)
        centre = (np.asarray(lo) + np.asarray(hi)) / 2
        offset = centre - self.origin
        self.phi = math.atan2(offset[2], offset[0]) if (offset[0] or offset[2]) else 0.0
        self.turns = int(math.ceil(2 * math.pi / self.step - 1e-9))
        self.pole = int(math.floor(math.pi / 2 / self.step + 1e-9))
        self.a0, self.a1 = -(self.turns // 2), -(self.turns // 2) + self.turns - 1
        self.b0, self.b1 = -self.pole, self.pole
        self.full_circle = True
        a_lo, a_hi, b_lo, b_hi = self.blocks(np.asarray(lo)[None], np.asarray(hi)[None])
        self.full_circle = bool(a_lo[0] == self.a0 and a_hi[0] == self.a1)
        self.a0, self.a1, self.b0, self.b1 = int(a_lo[0]), int(a_hi[0]), int(b_lo[0]), int(b_hi[0])
        self.na, self.nb = max(self.a1 - self.a0 + 1, 0), max(self.b1 - self.b0 + 1, 0)
        self.pad = 0.0

    @property
    def count(self) -> int:
        return self.na * self.nb

    def _azimuths(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        corners = _xz_corners(lo, hi) - self.origin[[0, 2]]
        inside = (lo[:, 0] <= self.origin[0]) & (self.origin[0] <= hi[:, 0]) \
            & (lo[:, 2] <= self.origin[2]) & (self.origin[2] <= hi[:, 2])
        mid = corners.mean(axis=1)
        centre = np.arctan2(mid[:, 1], mid[:, 0])
        rel = _wrap(np.arctan2(corners[..., 1], corners[..., 0]) - centre[:, None])
        off = _wrap(centre - self.phi)
        a_lo = _first((off + rel.min(axis=1)) / self.step)
        a_hi = _last((off + rel.max(axis=1)) / self.step)
        full = inside | (rel.max(axis=1) - rel.min(axis=1) >= np.pi)
        if self.full_circle:                 # a range across the seam behind the plant: all of it
            full |= (a_lo < self.a0) | (a_hi > self.a1)
        return np.where(full, self.a0, np.maximum(a_lo, self.a0)), np.where(full, self.a1, np.minimum(a_hi, self.a1))

    def _elevations(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        corners = _xz_corners(lo, hi) - self.origin[[0, 2]]
        far = np.sqrt((corners ** 2).sum(axis=-1)).max(axis=1)
        gap = np.maximum(np.maximum(lo[:, [0, 2]] - self.origin[[0, 2]], self.origin[[0, 2]] - hi[:, [0, 2]]), 0.0)
        near = np.hypot(gap[:, 0], gap[:, 1])
        top, bottom = hi[:, 1] - self.origin[1], lo[:, 1] - self.origin[1]
        theta_hi = np.arctan2(top, np.where(top >= 0, near, far))
        theta_lo = np.arctan2(bottom, np.where(bottom <= 0, near, far))
        b_lo = np.maximum(_first(theta_lo / self.step), self.b0)
        return b_lo, np.minimum(_last(theta_hi / self.step), self.b1)

    def blocks(self, lo, hi):
        """Per box (k,): the rectangle [a_lo, a_hi] × [b_lo, b_hi] of beams that can meet it
        (empty where a_lo > a_hi or b_lo > b_hi)."""
        return (*self._azimuths(lo, hi), *self._elevations(lo, hi))

    def rays(self, a, b) -> tuple[np.ndarray, np.ndarray]:
        """Origins (k, 3) and unit directions (k, 3) of beams (a, b). The sines and cosines
        are taken once per azimuth and elevation a run of beams spans (a chunk of a grid's
        beams spans a few rows), each the same number as taken beam by beam."""
        (cos_phi, sin_phi), at_a = _trig_of_steps(a, self.step, self.phi)
        (cos_theta, sin_theta), at_b = _trig_of_steps(b, self.step)
        c = cos_theta[at_b]
        d = np.stack([c * cos_phi[at_a], sin_theta[at_b], c * sin_phi[at_a]], axis=-1)
        return np.broadcast_to(self.origin, d.shape), d


class AirborneBeams:
    """One flight line: pulses at ``origin`` + a·``spacing``·``heading`` (a in [a0, a1]),
    each a fan of beams at b·Δ from the nadir across the track, |b| <= ``fan``."""

    def __init__(self, origin, heading, spacing: float, step: float, fan: int, a0: int, a1: int):
        self.origin = np.asarray(origin, dtype=np.float64)
        self.heading = np.asarray(heading, dtype=np.float64)
        self.across = np.array([-self.heading[2], 0.0, self.heading[0]])
        self.spacing, self.step = float(spacing), float(step)
        self.a0, self.a1, self.b0, self.b1 = int(a0), int(a1), -int(fan), int(fan)
        self.na, self.nb = self.a1 - self.a0 + 1, self.b1 - self.b0 + 1
        self.pad = 0.0

    @property
    def count(self) -> int:
        return self.na * self.nb

    def blocks(self, lo, hi):
        """As :meth:`TerrestrialBeams.blocks`: pulses whose fan plane crosses the box, and
        the across-track angles of the box seen from the pulse's line."""
        corners = _xz_corners(lo, hi) - self.origin[[0, 2]]
        along = corners @ self.heading[[0, 2]]
        across = corners @ self.across[[0, 2]]
        a_lo = np.maximum(_first(along.min(axis=1) / self.spacing), self.a0)
        a_hi = np.minimum(_last(along.max(axis=1) / self.spacing), self.a1)
        w_lo, w_hi = self.origin[1] - hi[:, 1], self.origin[1] - lo[:, 1]        # depth below the line
        u_lo, u_hi = across.min(axis=1), across.max(axis=1)
        angles = np.arctan2(np.stack([u_lo, u_hi, u_lo, u_hi], axis=1), np.stack([w_lo, w_lo, w_hi, w_hi], axis=1))
        b_lo = np.maximum(_first(angles.min(axis=1) / self.step), self.b0)
        b_hi = np.minimum(_last(angles.max(axis=1) / self.step), self.b1)
        inside = (u_lo <= 0) & (u_hi >= 0) & (w_lo <= 0)
        b_lo, b_hi = np.where(inside, self.b0, b_lo), np.where(inside, self.b1, b_hi)
        above = w_hi <= 0
        return a_lo, np.where(above, a_lo - 1, a_hi), b_lo, b_hi

    def rays(self, a, b) -> tuple[np.ndarray, np.ndarray]:
        s = np.asarray(a, dtype=np.float64) * self.spacing
        theta = np.asarray(b, dtype=np.float64) * self.step
        origins = self.origin + s[:, None] * self.heading
        d = np.cos(theta)[:, None] * np.array([0.0, -1.0, 0.0]) + np.sin(theta)[:, None] * self.across
        return origins, d


# ============================================================================ where the scanners are
def _terrestrial_positions(target: ScanTarget, settings: ScanSettings) -> np.ndarray:
    if settings.positions is not None:
        return np.array(settings.positions, dtype=np.float64)
    lo, hi = target.box()
    centre = (lo + hi) / 2
    height = max(float(hi[1] - target.base[1]), 0.0)
    radius = settings.distance
    if radius is None:
        radius = height + 0.5 * float(np.hypot(hi[0] - lo[0], hi[2] - lo[2]))
        radius = radius if radius > 0 else 1.0
    angle = np.radians(settings.azimuth) + 2 * np.pi * np.arange(settings.scanners) / settings.scanners
    y = np.full(settings.scanners, target.base[1] + settings.scanner_height)
    return np.stack([centre[0] + radius * np.cos(angle), y, centre[2] + radius * np.sin(angle)], axis=1)


def _airborne_lines(target: ScanTarget, settings: ScanSettings, limits: Limits | None = None) -> list[AirborneBeams]:
    lo, hi = target.box()
    centre = (lo + hi) / 2
    height = max(float(hi[1] - target.base[1]), 0.0)
    altitude = target.base[1] + (settings.flight_height or (2 * height if height > 0 else 1.0))
    step = math.radians(settings.angular_step)
    fan = int(math.floor(math.radians(settings.scan_angle) / step + 1e-9))
    depth = altitude - lo[1]
    pulse = settings.pulse_spacing or max(depth, 1e-9) * math.tan(step)
    half_swath = max(depth, 0.0) * math.tan(fan * step)
    spacing = settings.line_spacing or (half_swath if fan > 0 else pulse)
    heading = np.array([math.cos(math.radians(settings.azimuth)), 0.0, math.sin(math.radians(settings.azimuth))])
    across = np.array([-heading[2], 0.0, heading[0]])
    corners = _xz_corners(lo[None], hi[None])[0] - centre[[0, 2]]
    along, side = corners @ heading[[0, 2]], corners @ across[[0, 2]]
    # The beams counted in floats before any line is made: a tiny spacing, flight height
    # or pulse spacing (a denormal one too) is refused here, not after the lines fill memory.
    lines_f = (side.max() - side.min() + 2 * half_swath) / spacing + 3
    rays_f = ((along.max() - along.min()) / pulse + 3) * lines_f * (2 * fan + 1) * settings.sub_rays
    limit = (limits or default_limits).max_scan_rays
    if not rays_f <= limit:
        raise LimitError(f"an airborne scan: about {rays_f:.3g} rays ({lines_f:.3g} flight lines), over the "
                         f"limit of {limit:,} ({hint('scan_rays')}; or widen the line or pulse spacing, or "
                         "raise the flight height)")
    a0, a1 = int(math.floor(along.min() / pulse)), int(math.ceil(along.max() / pulse))
    l0 = int(math.floor((side.min() - half_swath) / spacing))
    l1 = int(math.ceil((side.max() + half_swath) / spacing))
    origin = np.array([centre[0], altitude, centre[2]])
    lines = []
    for line in range(l0, l1 + 1):
        beams = AirborneBeams(origin + line * spacing * across, heading, pulse, step, fan, a0, a1)
        beams.line, beams.line_spacing = line, spacing
        lines.append(beams)
    return lines


def scanner_positions(target: ScanTarget, settings: ScanSettings) -> np.ndarray:
    """(s, 3) where the scanners stand (airborne: each flight line's centre point)."""
    if settings.mode == "airborne":
        return np.array([line.origin for line in _airborne_lines(target, settings)]).reshape(-1, 3)
    return _terrestrial_positions(target, settings)


def _reach(origins: np.ndarray, lo, hi) -> float:
    """The farthest distance from any of ``origins`` (k, 3) to the box (lo, hi)."""
    far = np.maximum(np.abs(np.asarray(lo) - origins), np.abs(np.asarray(hi) - origins))
    return float(np.sqrt((far ** 2).sum(axis=1)).max())


def beam_grids(target: ScanTarget, settings: ScanSettings, limits: Limits | None = None) -> list:
    """The beam grid of every scanner (airborne: of every flight line):
    :class:`TerrestrialBeams` or :class:`AirborneBeams`, whose ``rays(a, b)`` gives any
    beam's origin and direction (beam k is (a0 + k // nb, b0 + k % nb)). With a divergence,
    a scanner's ``pad`` widens the box it looks at by the beam's radius at its farthest
    range, so that a beam whose axis misses the plant but a sub-ray hits is fired."""
    lo, hi = target.box()
    half = math.tan(settings.divergence / 2000.0)
    if settings.mode == "airborne":
        return _airborne_lines(target, settings, limits)
    step = math.radians(settings.angular_step)
    grids, fired, positions = [], 0, _terrestrial_positions(target, settings)
    for p in positions:
        pad = _reach(p[None], lo, hi) * half * (1 + 1e-9)
        grid = TerrestrialBeams(p, lo - pad, hi + pad, step)
        grid.pad = pad
        grids.append(grid)
        fired += grid.count * settings.sub_rays      # checked as the grids come: O(1) a scanner
        if limits is not None and fired > limits.max_scan_rays:
            limits.check("scan_rays", fired, f"a scan of {len(positions)} scanners (the first {len(grids)} alone)")
    return grids


# ============================================================================ casting
def diverging_rays(directions: np.ndarray, beam_ids: np.ndarray, seed: int, scanner: int, samples: int,
              half_angle: float) -> np.ndarray:
    """(m·s, 3) the s sub-rays of each beam (m,): a Vogel spiral over the cone of
    ``half_angle``, turned by a random angle per beam; sub-ray j of beam i is row i·s + j."""
    if samples == 1:
        return directions
    e1 = unit(cross(directions, np.where(np.abs(directions[:, 1:2]) < 0.9, [[0.0, 1, 0]], [[1.0, 0, 0]])))
    e2 = cross(directions, e1)
    turn = 2 * np.pi * _uniform(seed, scanner, _TURN, beam_ids)
    j = np.arange(samples)
    radius = np.tan(half_angle * np.sqrt((j + 0.5) / samples))                      # (s,)
    psi = turn[:, None] + GOLDEN_ANGLE * j[None, :]                                  # (m, s)
    off = (np.cos(psi)[..., None] * e1[:, None] + np.sin(psi)[..., None] * e2[:, None]) * radius[None, :, None]
    return unit(directions[:, None, :] + off).reshape(-1, 3)
