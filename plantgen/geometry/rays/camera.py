"""Pinhole camera: the view contract shared by every renderer, the reference and tests,
and framing: :func:`auto_camera` (a camera that fits frusta into the viewport),
:func:`box_corners` and :func:`depth_range` (near and far distances around points).

Camera JSON holds ``eye``, ``target``, ``up``, ``fov_y`` (vertical, degrees), ``width``
and ``height``. Rays go through pixel centres; pixel row 0 is the top row of the image.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ... import fields
from ...errors import PlantgenError
from ...files import read_input
from ...knobs import knob
from ...limits import MAX_IMAGE_SIDE, Limits
from ...limits import limits as default_limits
from ...tolerances import tol
from ..skeletons.frusta import ROW_FIELDS, Frusta, end_balls, frusta_bounds, section_points
from ..vec import by_rows

__all__ = ["Camera", "CameraError", "Orbit", "auto_camera", "frame_copies", "box_corners", "depth_range",
           "orbit_angles", "orbit_direction", "orbit_view", "AUTO_DIRECTION"]

#: The direction :func:`auto_camera` looks from (from the model towards the eye, not unit).
AUTO_DIRECTION = (0.35, 0.25, 1.0)

#: Elevations are kept this far from the poles (degrees), where the view's up (+y) would be
#: parallel to the view direction.
MAX_ELEVATION = 89.0


class CameraError(PlantgenError, ValueError):
    """A camera file or value that breaks the contract."""


@dataclass(frozen=True)
class Camera:
    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    fov_y: float = 40.0
    width: int = 1024
    height: int = 768

    # ------------------------------------------------------------------ frame
    def basis(self) -> np.ndarray:
        """(3, 3) float64 rows: right, true up, forward (unit vectors, right-handed view)."""
        eye, target, up = (np.asarray(a, dtype=np.float64) for a in (self.eye, self.target, self.up))
        fwd = target - eye
        nf = np.linalg.norm(fwd)
        if nf == 0:
            raise CameraError("camera eye and target coincide")
        fwd /= nf
        right = np.cross(fwd, up)
        nr = np.linalg.norm(right)
        if nr < tol.parallel:
            raise CameraError("camera up is parallel to the view direction")
        right /= nr
        true_up = np.cross(right, fwd)
        return np.stack([right, true_up, fwd])

    @property
    def aspect(self) -> float:
        return self.width / self.height

    def rays(self, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
        """Rays through pixel centres.

        Returns
        -------
        origins : (height, width, 3) array, all equal to ``eye``
        directions : (height, width, 3) array, unit length; row 0 is the top row
        """
        right, up, fwd = self.basis()
        tan_y = np.tan(np.radians(self.fov_y) / 2)
        tan_x = tan_y * self.aspect
        xs = ((np.arange(self.width) + 0.5) / self.width * 2 - 1) * tan_x
        ys = (1 - (np.arange(self.height) + 0.5) / self.height * 2) * tan_y
        d = fwd + xs[None, :, None] * right + ys[:, None, None] * up
        d /= np.linalg.norm(d, axis=-1, keepdims=True)
        o = np.broadcast_to(np.asarray(self.eye, dtype=np.float64), d.shape)
        return o.astype(dtype), d.astype(dtype)

    def view_matrix(self) -> np.ndarray:
        """(4, 4) float64 world-to-view matrix (OpenGL convention: looking down -z)."""
        right, up, fwd = self.basis()
        eye = np.asarray(self.eye, dtype=np.float64)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = right, up, -fwd
        m[:3, 3] = -m[:3, :3] @ eye
        return m

    def projection_matrix(self, near: float, far: float) -> np.ndarray:
        """(4, 4) float64 OpenGL perspective matrix for this camera's fov and aspect."""
        f = 1.0 / np.tan(np.radians(self.fov_y) / 2)
        m = np.zeros((4, 4))
        m[0, 0] = f / self.aspect
        m[1, 1] = f
        m[2, 2] = (far + near) / (near - far)
        m[2, 3] = 2 * far * near / (near - far)
        m[3, 2] = -1.0
        return m

    # ------------------------------------------------------------------ framing
    @classmethod
    def auto(cls, bounds: np.ndarray, width: int = 1024, height: int = 768, fov_y: float = 40.0,
             direction=(0.35, 0.25, 1.0), fill: float = 0.9) -> Camera:
        """Frame an axis-aligned box so that it spans most of the viewport.

        The eye looks at the box centre from ``direction`` (not normalised) at the distance
        where the box's bounding sphere fills ``fill`` of the tighter field of view.
        """
        b = np.asarray(bounds, dtype=np.float64)
        centre = b.mean(axis=0)
        radius = max(float(np.linalg.norm(b[1] - b[0])) / 2, tol.frame_extent)
        half_y = np.radians(fov_y) / 2
        half_x = np.arctan(np.tan(half_y) * width / height)
        half = min(half_x, half_y) * fill
        dist = radius / np.sin(half)
        d = np.asarray(direction, dtype=np.float64)
        d /= np.linalg.norm(d)
        eye = centre + d * dist
        return cls(tuple(eye.tolist()), tuple(centre.tolist()), (0.0, 1.0, 0.0), fov_y, width, height)

    # ------------------------------------------------------------------ files
    def to_dict(self) -> dict:
        return {"eye": list(self.eye), "target": list(self.target), "up": list(self.up),
                "fov_y": self.fov_y, "width": self.width, "height": self.height}

    def scaled(self, factor: int) -> Camera:
        """The same view at ``factor`` times the pixels per side: each pixel's
        ``factor`` x ``factor`` sub-pixel centres are the rays of the larger image (the
        samples of supersampling)."""
        return Camera(self.eye, self.target, self.up, self.fov_y, self.width * int(factor),
                      self.height * int(factor))

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def from_dict(cls, d: dict, source: str = "camera") -> Camera:
        """A camera from a mapping (a camera JSON, a scene's ``camera``): every value typed
        and ranged (points finite and within ``tol.max_coordinate``, ``fov_y`` in (0, 180),
        sides 1..MAX_IMAGE_SIDE pixels), one line naming ``source`` otherwise."""
        fields.keys(d, {"eye", "target", "up", "fov_y", "width", "height"}, source, CameraError)
        missing = {"eye", "target"} - set(d)
        if missing:
            raise CameraError(f"{source}: camera needs {sorted(missing)}")
        vec = lambda key, v: tuple(fields.vector(v, key, source, CameraError,  # noqa: E731
                                                 max_abs=tol.max_coordinate).tolist())
        side = lambda key, v: fields.integer(v, f"camera {key}", source, CameraError,  # noqa: E731
                                             lo=1, hi=MAX_IMAGE_SIDE)
        cam = cls(vec("eye", d["eye"]), vec("target", d["target"]), vec("up", d.get("up", [0, 1, 0])),
                  fields.number(d.get("fov_y", 40.0), "fov_y", source, CameraError),
                  side("width", d.get("width", 1024)), side("height", d.get("height", 768)))
        if not 0 < cam.fov_y < 180:
            raise CameraError(f"{source}: fov_y must lie in (0, 180), got {cam.fov_y:g}")
        try:
            cam.basis()
        except CameraError as exc:
            raise CameraError(f"{source}: {exc}") from None
        return cam

    @classmethod
    def load(cls, path: str | Path, limits: Limits | None = None) -> Camera:
        """A camera JSON file (a regular file within ``limits.max_input_bytes``), checked by
        :meth:`from_dict`."""
        limits = limits or default_limits
        data = read_input(path, CameraError, max_bytes=limits.max_input_bytes, limit="input_bytes",
                          what="camera JSON")
        try:
            d = json.loads(data.decode("utf-8"))
        except (ValueError, RecursionError) as exc:   # JSONDecodeError, UnicodeDecodeError, a deep nest
            raise CameraError(f"{path}: cannot read camera JSON ({str(exc).splitlines()[0][:100]})") from None
        if not isinstance(d, dict):
            raise CameraError(f"{path}: camera JSON must be an object")
        return cls.from_dict(d, str(path))


# ---------------------------------------------------------------------- framing
#: Frustum rows :func:`auto_camera` samples at a time (bounds its memory, not its result).
FRAME_CHUNK = 1 << 15
#: Rows a framing pass samples first, those whose bounds reach farthest (1: the farthest
#: alone): their exact extreme is the bar every other row's bound must reach for it to be
#: sampled at all.
FRAME_PROBE = 1
#: How far past its end ball (:func:`~plantgen.geometry.skeletons.frusta.row_end_balls`) a
#: section's sample balls may reach, relative to the ball's radius: the slack is at most 1/cos(π/24) - 1 < 0.0087.
FRAME_BALL_GROW = 1.01


def auto_camera(frusta: Frusta, width: int = 1024, height: int = 768, *, fov_y: float = 40.0,
                direction=AUTO_DIRECTION, fill: float = 0.9, points=None, stats: dict | None = None) -> Camera:
    """A camera looking from ``direction`` at the model, as close as it can be while every
    frustum stays inside ``fill`` of the viewport: the model spans most of the viewport
    (as the paper measured). Tighter than a bounding sphere for tall, thin plants.

    Each pass samples the sections (:func:`section_points`) of the rows whose bounding
    balls may reach the pass's extreme only (:class:`FrameRows`): the same camera as
    sampling every row, in time about linear in the rows.

    Parameters
    ----------
    frusta : Frusta, n rows (world units)
    width, height : viewport in pixels
    fov_y : vertical field of view, degrees
    direction : (3,) from the model towards the eye (not normalised)
    fill : fraction of the half-width and half-height the model may reach
    points : (k, 3) further points the view must hold (a model's leaf vertices), or None
    stats : a dict that gets ``rows`` (n), ``sampled`` (rows whose sections were sampled,
        over every pass) and ``passes``, or None
    """
    points = np.zeros((0, 3)) if points is None else np.asarray(points, np.float64).reshape(-1, 3)
    rows = FrameRows(frusta, points)
    box = rows.box
    if len(points):
        box = np.stack([np.minimum(box[0], points.min(axis=0)), np.maximum(box[1], points.max(axis=0))])
    if len(frusta.base) == 0:
        return Camera.auto(box, width, height, fov_y=fov_y, direction=direction, fill=fill)
    camera = _frame(rows, box, width, height, fov_y, direction, fill)
    if stats is not None:
        stats.update(rows=len(frusta.base), sampled=rows.sampled, passes=rows.passes)
    return camera


def frame_copies(plants, width: int = 1024, height: int = 768, *, fov_y: float = 40.0,
                 direction=AUTO_DIRECTION, fill: float = 0.9) -> Camera:
    """A camera framing copies of plants as :func:`auto_camera` frames one model, at the
    cost of one plant's bound times its copies: ``plants`` is [(frusta, matrices (k, 4, 4)
    of its copies, its leaf vertices (m, 3) or None)], each copy framed as the eight
    corners of its plant's box (:func:`frusta_bounds`, leaves included) moved by its
    matrix: never cutting a copy off, a little wider than framing every placed row."""
    corners = []
    for frusta, matrices, leaves in plants:
        box = frusta_bounds(frusta)
        if leaves is not None and len(leaves):
            box = np.stack([np.minimum(box[0], leaves.min(axis=0)), np.maximum(box[1], leaves.max(axis=0))])
        m = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
        corners.append((np.einsum("kij,pj->kpi", m[:, :3, :3], box_corners(box)) + m[:, None, :3, 3]).reshape(-1, 3))
    points = np.concatenate(corners) if corners else np.zeros((0, 3))
    if not len(points):
        return Camera.auto(np.zeros((2, 3)), width, height, fov_y=fov_y, direction=direction, fill=fill)
    box = np.stack([points.min(axis=0), points.max(axis=0)])
    return _frame(FrameRows(None, points), box, width, height, fov_y, direction, fill)


def _frame(rows: FrameRows, box, width: int, height: int, fov_y: float, direction, fill: float) -> Camera:
    """:func:`auto_camera`'s solve over ``rows``: the distance from ``direction`` at which
    everything fits, re-centred on its projected extent, twice, then the distance again."""
    toward_eye = np.asarray(direction, dtype=np.float64)
    toward_eye /= np.linalg.norm(toward_eye)
    probe = Camera(tuple(toward_eye), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y, width, height)
    right, up, fwd = probe.basis()
    tan_y = np.tan(np.radians(fov_y) / 2) * fill
    tan_x = tan_y * width / height
    view = (right, up, fwd)
    target = 0.5 * (box[0] + box[1])
    for _ in range(2):   # solve the distance, re-centre on the projected extent, solve again
        dist = rows.distance(target, view, tan_x, tan_y)
        x_lo, x_hi, y_lo, y_hi = rows.extent(target, dist, view)
        target = target + dist * (0.5 * (x_lo + x_hi) * right + 0.5 * (y_lo + y_hi) * up)
    dist = rows.distance(target, view, tan_x, tan_y)
    eye = target - fwd * dist
    return Camera(tuple(eye.tolist()), tuple(target.tolist()), (0.0, 1.0, 0.0), fov_y, width, height)


class FrameRows:
    """The rows :func:`auto_camera` frames, their sections sampled only where they may
    matter.

    A row's two end balls (:func:`~plantgen.geometry.skeletons.frusta.row_end_balls`, grown by
    :data:`FRAME_BALL_GROW` to hold its section samples' balls) bound every quantity a pass takes the extreme of. A pass
    samples the :data:`FRAME_PROBE` rows whose bounds reach farthest, then the rows whose
    bounds reach that exact extreme (or are not finite): no other row's samples can reach
    it, so the result is the exact extreme over every row's samples. ``sampled`` counts
    the rows sampled over the passes, ``passes`` the passes (work counters)."""

    def __init__(self, frusta: Frusta | None, points: np.ndarray):
        self.frusta, self.points, self.sampled, self.passes = frusta, points, 0, 0
        self.n = 0 if frusta is None else len(frusta.base)
        n = self.n
        # the balls a block of rows at a time, into the (2n,) arrays, and the rows' box from them
        self.centres, radii = end_balls(frusta) if n else (np.empty((0, 3)), np.empty(0))
        #: (2, 3) the box around the rows (:func:`frusta_bounds`: the box of the same balls)
        self.box = frusta_bounds(frusta) if n else np.zeros((2, 3))
        self.radii = radii * FRAME_BALL_GROW + (2 * tol.frame_extent + 1e-9 * float(np.abs(self.box).max()))
        self._view, self._projected = None, None

    def bounds(self, view, target, bound) -> tuple[np.ndarray, ...]:
        """``bound(a, b, z, radius)``, elementwise, over the balls: (a, b, z) their centres
        less ``target`` along the ``view``'s right, up and forward axes (the centres
        projected once a view), evaluated a block of balls at a time (:func:`by_rows`)."""
        if self._view is not view:
            self._view, self._projected = view, tuple(self.centres @ axis for axis in view)
        shift = [float(np.dot(target, axis)) for axis in view]
        return by_rows(lambda a, b, z, r: bound(a - shift[0], b - shift[1], z - shift[2], r),
                       *self._projected, self.radii)

    def balls(self, rows: np.ndarray):
        """(centres (m, 3), radii (m,)) of the section samples of ``rows`` (row indices),
        a chunk at a time, then those of the extra points."""
        self.sampled += len(rows)
        f = self.frusta
        for start in range(0, len(rows), FRAME_CHUNK):
            take = rows[start:start + FRAME_CHUNK]
            part = Frusta(**{k: getattr(f, k)[take] for k in ROW_FIELDS}, material_names=f.material_names,
                          parent_row=np.full(len(take), -1, np.int64), report=None)
            centres, radius = section_points(part)
            yield centres.reshape(-1, 3), radius.reshape(-1) + tol.frame_extent
        if len(self.points):
            yield self.points, np.zeros(len(self.points)) + tol.frame_extent

    def select(self, bounds: list[np.ndarray], exact) -> list[float]:
        """The exact maxima ``exact(rows)`` over every row, ``bounds`` one (2n,) upper
        bound an objective (a ball each); ``exact(rows)`` gives each objective's maximum
        over the samples of ``rows`` and the points."""
        self.passes += 1
        n = self.n
        if n == 0:
            return exact(np.zeros(0, np.int64))
        top = min(FRAME_PROBE, 2 * n)
        probe = np.unique(np.concatenate([[np.argmax(u) % n] if top == 1 else np.argpartition(-u, top - 1)[:top] % n
                                          for u in bounds]))
        bars = exact(probe)
        keep = np.zeros(2 * n, bool)
        for u, bar in zip(bounds, bars, strict=True):
            keep |= ~(u < bar)
        rest = np.setdiff1d(np.flatnonzero(keep[:n] | keep[n:]), probe)
        if not len(rest):
            return bars
        return [max(a, b) for a, b in zip(bars, exact(rest), strict=True)]

    def distance(self, target, view, tan_x, tan_y) -> float:
        """:func:`_framing_distance` over every row's samples and the points."""
        right, up, fwd = view
        bound = self.bounds(view, target, lambda a, b, z, r: _framing_need(a, b, z, r, tan_x, tan_y))

        def exact(rows):
            return [max(_framing_distance(rel @ right, rel @ up, rel @ fwd, r, tan_x, tan_y)
                        for rel, r in ((c - target, r) for c, r in self.balls(rows)))]
        return self.select([bound], exact)[0]

    def extent(self, target, dist, view) -> tuple[float, float, float, float]:
        """(x_lo, x_hi, y_lo, y_hi): the tangents of the samples' and points' extent in the
        view from ``dist`` before ``target``."""
        right, up, fwd = view

        def reaches(a, b, z, r):
            near, far = dist + z - r, dist + z + r
            with np.errstate(divide="ignore", invalid="ignore"):
                def reach(num):   # an upper bound of num'/depth for any num' <= num, depth in [near, far]
                    return np.where(near > 0, np.where(num > 0, num / near, num / far), np.inf)
                return reach(r - a), reach(a + r), reach(r - b), reach(b + r)
        bounds = list(self.bounds(view, target, reaches))

        def exact(rows):
            x_lo = y_lo = np.inf
            x_hi = y_hi = -np.inf
            for centres, radius in self.balls(rows):
                rel = centres - target
                a, b, z = rel @ right, rel @ up, rel @ fwd
                depth = dist + z
                x_lo, x_hi = min(x_lo, np.min((a - radius) / depth)), max(x_hi, np.max((a + radius) / depth))
                y_lo, y_hi = min(y_lo, np.min((b - radius) / depth)), max(y_hi, np.max((b + radius) / depth))
            return [-x_lo, x_hi, -y_lo, y_hi]
        x_lo, x_hi, y_lo, y_hi = self.select(bounds, exact)
        return -x_lo, x_hi, -y_lo, y_hi


# ---------------------------------------------------------------------- orbits
@dataclass(frozen=True)
class Orbit:
    """A view given as angles around a target, as the command line and the viewer give it.

    azimuth : degrees about +y; 0 looks from +z towards -z, 90 from +x (None: keep)
    elevation : degrees above the horizontal, within +-89 (None: keep)
    distance : eye-target distance in world units (None: keep, or frame the model anew)
    zoom : divides the distance (2: twice as close; None: 1)
    fov_y : vertical field of view in degrees (None: keep)
    """

    azimuth: float | None = knob(None, "--azimuth", "Camera: degrees around the vertical axis (0 looks from +z, 90 "
                                 "from +x; default: the automatic camera's, about 19).", metavar="DEG")
    elevation: float | None = knob(None, "--elevation", "Camera: degrees above the horizontal (default: about 13).",
                                   lo=-MAX_ELEVATION, hi=MAX_ELEVATION, metavar="DEG")
    distance: float | None = knob(None, "--distance", "Camera: distance from the target in world units (default: "
                                  "framed so the model fills the view).", lo=0, lo_open=True, metavar="D")
    zoom: float | None = knob(None, "--zoom", "Camera: divide the distance by F (2: twice as close).", lo=0,
                              lo_open=True, metavar="F")
    fov_y: float | None = knob(None, "--fov", "Camera: vertical field of view in degrees (default: 40).", lo=0, hi=180,
                               lo_open=True, hi_open=True, metavar="DEG")

    def __post_init__(self):
        for name in ("azimuth", "elevation", "distance", "zoom", "fov_y"):
            value = getattr(self, name)
            if value is not None and not np.isfinite(value):
                raise CameraError(f"camera {name} must be a finite number, got {value!r}")
        if self.elevation is not None and abs(self.elevation) > MAX_ELEVATION:
            raise CameraError(f"camera elevation must lie within +-{MAX_ELEVATION:g} degrees, got {self.elevation:g}")
        if self.distance is not None and not 0 < self.distance <= tol.max_coordinate:
            raise CameraError(f"camera distance must lie in (0, {tol.max_coordinate:g}], got {self.distance:g}")
        if self.zoom is not None and not 0 < self.zoom <= 1e6:
            raise CameraError(f"camera zoom must lie in (0, 1e6], got {self.zoom:g}")
        if self.fov_y is not None and not 0 < self.fov_y < 180:
            raise CameraError(f"camera fov must lie in (0, 180) degrees, got {self.fov_y:g}")

    @property
    def empty(self) -> bool:
        """True when no value is given (the view stays as it is)."""
        return all(getattr(self, n) is None for n in ("azimuth", "elevation", "distance", "zoom", "fov_y"))

    @property
    def turns(self) -> bool:
        """True when the direction or the field of view changes (a framed view is framed anew)."""
        return any(getattr(self, n) is not None for n in ("azimuth", "elevation", "fov_y"))


def orbit_direction(azimuth: float, elevation: float) -> np.ndarray:
    """(3,) unit vector from the target towards the eye at ``azimuth``, ``elevation`` (degrees)."""
    az, el = np.radians(azimuth), np.radians(elevation)
    return np.array([np.sin(az) * np.cos(el), np.sin(el), np.cos(az) * np.cos(el)])


def orbit_angles(camera: Camera) -> tuple[float, float, float]:
    """(azimuth, elevation, distance) of ``camera``'s eye around its target (degrees, world
    units): the inverse of :func:`orbit_direction` times the distance."""
    d = np.asarray(camera.eye, dtype=np.float64) - np.asarray(camera.target, dtype=np.float64)
    dist = float(np.linalg.norm(d))
    if dist == 0:
        raise CameraError("camera eye and target coincide")
    azimuth = float(np.degrees(np.arctan2(d[0], d[2])))
    elevation = float(np.degrees(np.arcsin(np.clip(d[1] / dist, -1.0, 1.0))))
    return azimuth, elevation, dist


def orbit_view(base: Camera, orbit: Orbit, frame=None) -> Camera:
    """``base`` turned, moved and zoomed as ``orbit`` says, around ``base``'s target.

    Values ``orbit`` leaves out keep ``base``'s. ``frame`` (optional) is a callable
    ``frame(direction, fov_y) -> Camera`` that frames the model from a new direction (the
    auto camera): when ``orbit`` turns the view and gives no distance, the view is framed
    anew, so the model still fills it. The up vector is +y; the elevation is kept within
    +-89 degrees.
    """
    if orbit.empty:
        return base
    az0, el0, dist = orbit_angles(base)
    azimuth = az0 if orbit.azimuth is None else orbit.azimuth
    elevation = float(np.clip(el0 if orbit.elevation is None else orbit.elevation, -MAX_ELEVATION, MAX_ELEVATION))
    fov_y = base.fov_y if orbit.fov_y is None else orbit.fov_y
    direction = orbit_direction(azimuth, elevation)
    target = np.asarray(base.target, dtype=np.float64)
    if frame is not None and orbit.turns and orbit.distance is None:
        framed = frame(direction, fov_y)
        target = np.asarray(framed.target, dtype=np.float64)
        dist = float(np.linalg.norm(np.asarray(framed.eye) - target))
    if orbit.distance is not None:
        dist = float(orbit.distance)
    dist /= orbit.zoom or 1.0
    eye = target + direction * dist
    return Camera(tuple(eye.tolist()), tuple(target.tolist()), (0.0, 1.0, 0.0), fov_y, base.width, base.height)


def _framing_need(a, b, z, radius, tan_x, tan_y) -> np.ndarray:
    """(m,) the eye distance from the target at which each ball (centre (a, b, z) in the
    view frame, radius) lies inside the half-angles with tangents tan_x, tan_y; a ball
    inside another needs no more than it."""
    return np.maximum((np.abs(a) + radius) / tan_x, (np.abs(b) + radius) / tan_y) - z + radius


def _framing_distance(a, b, z, radius, tan_x, tan_y) -> float:
    """The eye distance from the target at which every ball (centres at (a, b, z) (m,) in
    the view frame, radii (m,)) lies inside the half-angles with tangents tan_x, tan_y."""
    return max(float(_framing_need(a, b, z, radius, tan_x, tan_y).max()), tol.frame_distance)


def box_corners(box) -> np.ndarray:
    """(8, 3) float64 corners of the axis-aligned (2, 3) box ``[lo, hi]``."""
    box = np.asarray(box, dtype=np.float64)
    return np.stack(np.meshgrid(*box.T, indexing="ij"), axis=-1).reshape(-1, 3)


def depth_range(point_sets, eye: np.ndarray, fwd: np.ndarray) -> tuple[float, float]:
    """Near and far distances along the unit view direction ``fwd`` (3,) from ``eye`` (3,)
    enclosing every (k, 3) array of ``point_sets`` with a 5 % margin of their extent;
    (0.1, 10) for none. near stays above far·``tol.near_far_ratio``, so the depth buffer
    keeps its precision."""
    pts = [np.asarray(p, dtype=np.float64) for p in point_sets if len(p)]
    if not pts:
        return 0.1, 10.0
    corners = np.concatenate(pts)
    box = np.stack([corners.min(axis=0), corners.max(axis=0)])
    depths = (corners - eye) @ fwd
    size = float(np.linalg.norm(box[1] - box[0]))
    far = max(float(depths.max()), 0.0) + 0.05 * size + tol.depth_far_pad
    near = max(float(depths.min()) - 0.05 * size, far * tol.near_far_ratio)
    return near, far
