"""``plantgen render`` (issue 4): files, the camera/depth contract, relief flags, errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from _cli import run_cli
from PIL import Image

from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.skeleton import Skeleton

SIZE = "96x72"


def bent_skeleton() -> Skeleton:
    pts = np.array([[0, 0, 0], [0, 1, 0], [0.3, 1.9, 0], [0.3, 2.7, 0.4]], dtype=float)
    n = len(pts) - 1
    return Skeleton(pts[:-1], pts[1:], np.array([0.25, 0.22, 0.18]), np.array([0.22, 0.18, 0.12]),
                    np.arange(n) - 1, np.arange(n) > 0, np.zeros(n, int), ("bark",))


@pytest.fixture
def skeleton_file(tmp_path):
    path = tmp_path / "bent.npz"
    bent_skeleton().save(path)
    return path


def distance_to_skeleton(points, skel):
    """(k,) distance of each point from the nearest segment's axis, minus its radius there."""
    best = np.full(len(points), np.inf)
    for a, b, ra, rb in zip(skel.start, skel.end, skel.r_start, skel.r_end, strict=True):
        ab = b - a
        s = np.clip((points - a) @ ab / (ab @ ab), 0, 1)
        d = np.linalg.norm(points - (a + s[:, None] * ab), axis=1) - (ra + s * (rb - ra))
        best = np.minimum(best, d)
    return best


def test_render_writes_image_camera_and_depth_that_agree(gl_ctx, skeleton_file, tmp_path):
    out, cam_path, depth_path = tmp_path / "a.png", tmp_path / "cam.json", tmp_path / "d.npy"
    # --ground none: the model's own depth (tests/test_ground.py checks the ground's)
    code, stdout, stderr = run_cli("render", skeleton_file, "-o", out, "--size", SIZE, "--ground", "none",
                                   "--camera-out", cam_path, "--depth-out", depth_path)
    assert code == 0, stderr
    assert "GL renderer: " + gl_ctx.info["GL_RENDERER"] in stdout
    assert "model: 3 branch segments (" in stdout and "frame:" in stdout and " ms" in stdout
    image = Image.open(out)
    assert image.size == (96, 72) and image.mode == "RGB"
    cam = json.loads(cam_path.read_text())
    assert set(cam) == {"eye", "target", "up", "fov_y", "width", "height"}
    assert (cam["width"], cam["height"]) == (96, 72)
    depth = np.load(depth_path)
    assert depth.dtype == np.float32 and depth.shape == (72, 96)
    assert not np.isnan(depth).any()
    hit = np.isfinite(depth)
    assert 0.05 < hit.mean() < 0.9   # auto camera: the model fills much of the frame, not all
    # another program rebuilds the rays from the camera file: the points lie on the skin
    origins, dirs = Camera.load(cam_path).rays()
    points = origins[hit] + dirs[hit] * depth[hit, None]
    off = distance_to_skeleton(points, bent_skeleton())
    # on the skin (caps lie inside the radius; near joints the skin bulges a little past it)
    assert off.max() < 0.02 and off.min() > -0.25 and np.median(np.abs(off)) < 1e-3
    # row 0 of the depth array is the top row of the PNG: bark (red over blue) where it hits
    rgb = np.asarray(image).astype(int)
    bark = rgb[..., 0] > rgb[..., 2]
    assert np.mean(bark == hit) > 0.99 and np.mean(bark == hit[::-1]) < 0.95


def test_camera_file_is_taken_back_and_the_render_repeats(gl_ctx, skeleton_file, tmp_path):
    cam_path = tmp_path / "cam.json"
    assert run_cli("render", skeleton_file, "-o", tmp_path / "a.png", "--size", SIZE,
                   "--camera-out", cam_path, "--depth-out", tmp_path / "a.npy")[0] == 0
    code, _, stderr = run_cli("render", skeleton_file, "-o", tmp_path / "b.png", "--camera", cam_path,
                              "--depth-out", tmp_path / "b.npy")
    assert code == 0, stderr
    assert np.array_equal(np.load(tmp_path / "a.npy"), np.load(tmp_path / "b.npy"))
    assert Image.open(tmp_path / "b.png").size == (96, 72)   # the size comes with the camera


def test_relief_flags_and_scene_effects(gl_ctx, tmp_path):
    scene = tmp_path / "scene.yaml"
    scene.write_text(
        "name: column\neffects: [relief]\ninstances:\n  - skeleton:\n      materials: [stone]\n"
        "      segments:\n        - {start: [0, 0, 0], end: [0, 2, 0], r_start: 0.5, r_end: 0.5}\n")
    depth = {}
    for flag in (None, "--relief", "--no-relief"):
        name = flag or "default"
        args = ["render", scene, "-o", tmp_path / f"{name}.png", "--size", SIZE,
                "--depth-out", tmp_path / f"{name}.npy", "--linear-steps", "16"]
        code, stdout, stderr = run_cli(*args, *([flag] if flag else []))
        assert code == 0, stderr
        assert ("ray cast with relief mapping" in stdout) == (flag != "--no-relief")
        depth[name] = np.load(tmp_path / f"{name}.npy")
    assert np.array_equal(depth["default"], depth["--relief"])   # the scene asked for relief
    assert not np.array_equal(depth["default"], depth["--no-relief"])


@pytest.mark.parametrize("args, message", [
    (["--size", "12by10"], "WIDTHxHEIGHT"),
    (["--size", "0x10"], "WIDTHxHEIGHT"),
    (["--camera", "missing.json"], "no such camera file"),
    (["--linear-steps", "0"], "linear-steps"),
])
def test_bad_options_exit_2_with_one_line(skeleton_file, tmp_path, args, message):
    code, stdout, stderr = run_cli("render", skeleton_file, "-o", tmp_path / "x.png", *args)
    assert code == 2 and message in stderr
    assert not (tmp_path / "x.png").exists()


def test_bad_files_exit_2_and_leave_nothing_half_written(gl_ctx, skeleton_file, tmp_path):
    bad_cam = tmp_path / "bad.json"
    bad_cam.write_text('{"eye": [0, 0, 1]}')
    cases = [
        (["render", tmp_path / "nope.npz", "-o", tmp_path / "x.png"], "nope.npz"),
        (["render", skeleton_file, "-o", tmp_path / "x.bmp"], "must end in .png, .jpg or .webp"),
        (["render", skeleton_file, "-o", tmp_path / "x.jpg", "--background", "none"], "no transparency"),
        (["render", skeleton_file, "-o", tmp_path / "x.png", "--camera", bad_cam], "target"),
        (["render", skeleton_file, "-o", tmp_path / "no_dir" / "x.png", "--size", SIZE], "cannot write"),
        (["render", skeleton_file, "-o", tmp_path / "x.png", "--depth-out", tmp_path / "d.txt"], ".npy"),
    ]
    for args, message in cases:
        code, _, stderr = run_cli(*args)
        assert code == 2, (args, stderr)
        assert message in stderr and len(stderr.strip().splitlines()) == 1, stderr
    leftovers = [p.name for p in tmp_path.rglob("*") if p.name not in {"bent.npz", "bad.json"}]
    assert leftovers == []
