"""TEMPORARY: render/raycast.py framing until the geometry branch merges."""
from __future__ import annotations

import numpy as np

from .camera import Camera


def frusta_bounds(frusta) -> np.ndarray:
    """(2, 3) float64 axis-aligned box around every frustum, relief shells included.

    An oblique cutting plane cuts the cone in an ellipse that reaches past the axis end
    point (up to R / cos θ from it, θ the plane's tilt from the axis), so each end
    contributes a ball of that radius around where its plane crosses the axis.
    """
    if len(frusta.base) == 0:
        return np.zeros((2, 3))
    h = frusta.length
    k = (frusta.r2 - frusta.r1) / h
    slope = np.abs(k)
    centres, reach = [], []
    for plane, r_end, y_end in ((frusta.plane_lo, frusta.r1, 0.0), (frusta.plane_hi, frusta.r2, h)):
        normal, offset = plane[:, :3], plane[:, 3]
        cos_t = np.clip(np.einsum("ij,ij->i", normal, frusta.axis), 1e-3, 1.0)
        sin_t = np.sqrt(1.0 - cos_t ** 2)
        y_cross = (offset - np.einsum("ij,ij->i", normal, frusta.base)) / cos_t
        y_cross = np.where(np.isfinite(y_cross), y_cross, y_end)
        radius = np.maximum(frusta.r1 + k * y_cross, 0.0) + frusta.shell
        grow = 1.0 / np.maximum(cos_t - slope * sin_t, 0.05)
        centres.append(frusta.base + frusta.axis * y_cross[:, None])
        reach.append(np.maximum(radius, r_end + frusta.shell) * grow)
    pts = np.concatenate(centres)
    r = np.concatenate(reach)[:, None]
    return np.stack([(pts - r).min(axis=0), (pts + r).max(axis=0)])


def section_points(frusta, samples: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """Points around the two plane sections of every frustum's outer (relief) surface.

    Returns
    -------
    points : (n, 2, samples, 3) float64, world units; [:, 0] on ``plane_lo``, [:, 1] on
        ``plane_hi``. The solid frustum is the convex hull of its two sections.
    slack : (n, 2, samples) float64, how far the true section may bulge past the polygon
        through the samples (its radius times 1/cos(π/samples) - 1), world units
    """
    phi = 2 * np.pi * np.arange(samples) / samples
    side = np.cross(frusta.ref_dir, frusta.axis)
    e = (np.cos(phi)[None, :, None] * frusta.ref_dir[:, None, :]
         + np.sin(phi)[None, :, None] * side[:, None, :])                  # (n, S, 3)
    k = ((frusta.r2 - frusta.r1) / frusta.length)[:, None]
    r_base = (frusta.r1 + frusta.shell)[:, None]
    out, slack = [], []
    for plane, y_end in ((frusta.plane_lo, 0.0), (frusta.plane_hi, frusta.length)):
        normal = plane[:, None, :3]
        gap = (plane[:, 3] - np.einsum("ij,ij->i", plane[:, :3], frusta.base))[:, None]
        n_e = np.sum(normal * e, axis=-1)
        rise = np.einsum("ij,ij->i", plane[:, :3], frusta.axis)[:, None] + k * n_e
        y = np.where(rise > 1e-9, (gap - r_base * n_e) / np.maximum(rise, 1e-9),
                     np.broadcast_to(np.asarray(y_end, dtype=np.float64).reshape(-1, 1), n_e.shape))
        ring = np.maximum(r_base + k * y, 0.0)
        out.append(frusta.base[:, None, :] + y[..., None] * frusta.axis[:, None, :] + ring[..., None] * e)
        slack.append(ring * (1 / np.cos(np.pi / samples) - 1))
    return np.stack(out, axis=1), np.stack(slack, axis=1)


def auto_camera(frusta, width: int = 1024, height: int = 768, *, fov_y: float = 40.0,
                direction=(0.35, 0.25, 1.0), fill: float = 0.9) -> Camera:
    """A camera looking from ``direction`` at the model, as close as it can be while every
    frustum stays inside ``fill`` of the viewport: the model spans most of the viewport
    (as the paper measured). Tighter than a bounding sphere for tall, thin plants.

    Parameters
    ----------
    frusta : Frusta, n rows (world units)
    direction : (3,) from the model towards the eye (not normalised)
    fill : fraction of the half-width and half-height the model may reach
    """
    box = frusta_bounds(frusta)
    if len(frusta.base) == 0:
        return Camera.auto(box, width, height, fov_y=fov_y, direction=direction, fill=fill)
    toward_eye = np.asarray(direction, dtype=np.float64)
    toward_eye /= np.linalg.norm(toward_eye)
    probe = Camera(tuple(toward_eye), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), fov_y, width, height)
    right, up, fwd = probe.basis()
    tan_y = np.tan(np.radians(fov_y) / 2) * fill
    tan_x = tan_y * width / height
    # the solid frustum is the convex hull of its two plane sections: sample them
    centres, radius = section_points(frusta)
    centres = centres.reshape(-1, 3)
    radius = radius.reshape(-1) + 1e-9
    target = 0.5 * (box[0] + box[1])
    for _ in range(2):   # solve the distance, re-centre on the projected extent, solve again
        rel = centres - target
        a, b, z = rel @ right, rel @ up, rel @ fwd
        need = np.maximum((np.abs(a) + radius) / tan_x, (np.abs(b) + radius) / tan_y) - z + radius
        dist = max(float(need.max()), 1e-6)
        depth = dist + z
        x_lo, x_hi = np.min((a - radius) / depth), np.max((a + radius) / depth)
        y_lo, y_hi = np.min((b - radius) / depth), np.max((b + radius) / depth)
        target = target + dist * (0.5 * (x_lo + x_hi) * right + 0.5 * (y_lo + y_hi) * up)
    rel = centres - target
    a, b, z = rel @ right, rel @ up, rel @ fwd
    need = np.maximum((np.abs(a) + radius) / tan_x, (np.abs(b) + radius) / tan_y) - z + radius
    dist = max(float(need.max()), 1e-6)
    eye = target - fwd * dist
    return Camera(tuple(eye.tolist()), tuple(target.tolist()), (0.0, 1.0, 0.0), fov_y, width, height)
