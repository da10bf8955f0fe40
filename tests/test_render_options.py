"""``plantgen render`` as users expect it (issue 13): a camera from angles, supersampling,
a background colour or transparency, one draw for a still, and the Python API."""

from __future__ import annotations

import importlib
import io
import json

import numpy as np
import pytest
import trimesh
from _cli import run_cli
from PIL import Image

import plantgen
from plantgen.geometry.rays.camera import Camera, auto_camera, orbit_angles, orbit_direction
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.pipeline import grow_file, skin_model

SIZE = "96x72"


def camera_of(tmp_path, *args) -> Camera:
    cam = tmp_path / "cam.json"
    code, _, err = run_cli("render", "saguaro", "-o", tmp_path / "x.png", "--size", SIZE, "--camera-out", cam, *args)
    assert code == 0, err
    return Camera.load(cam)


def test_angles_frame_the_model_anew_from_that_direction(gl_ctx, tmp_path):
    frusta = skin_model(grow_file("saguaro"))         # as render skins it (its elbows smoothed)
    cam = camera_of(tmp_path, "--azimuth", "90", "--elevation", "30", "--fov", "25")
    direction = orbit_direction(90, 30)
    assert np.allclose(np.subtract(cam.eye, cam.target) / np.linalg.norm(np.subtract(cam.eye, cam.target)),
                       direction)
    framed = auto_camera(frusta, 96, 72, fov_y=25, direction=direction)
    assert np.allclose(cam.eye, framed.eye) and np.allclose(cam.target, framed.target) and cam.fov_y == 25


def test_distance_and_zoom_move_the_eye_along_the_view(gl_ctx, tmp_path):
    auto = camera_of(tmp_path)
    az, el, dist = orbit_angles(auto)
    assert orbit_angles(camera_of(tmp_path, "--distance", "7"))[2] == pytest.approx(7.0)
    zoomed = camera_of(tmp_path, "--zoom", "2")
    assert orbit_angles(zoomed) == (pytest.approx(az), pytest.approx(el), pytest.approx(dist / 2))
    assert zoomed.target == auto.target


@pytest.mark.parametrize("args, message", [
    (["--elevation", "95"], "elevation"),
    (["--zoom", "0"], "zoom"),
    (["--fov", "180"], "fov"),
    (["--ssaa", "9"], "ssaa"),
    (["--background", "blurple"], "not a colour"),
    (["--azimuth", "10", "--camera", "CAM"], "--camera"),
    (["--ssaa", "8", "--size", "3000x2000"], "largest side"),
])
def test_bad_camera_and_image_options_are_one_line(gl_ctx, tmp_path, args, message):
    cam = tmp_path / "cam.json"
    Camera((0.0, 1.0, 5.0), (0.0, 1.0, 0.0)).save(cam)
    args = [str(cam) if a == "CAM" else a for a in args]
    code, _, err = run_cli("render", "saguaro", "-o", tmp_path / "x.png", *args)
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "x.png").exists()


def twig_file(tmp_path, radius: float, rise: float):
    """One straight twig across the view, rising ``rise`` over its length of 12, and a
    camera looking at it along -z."""
    skel = Skeleton(np.array([[-6.0, -rise / 2, 0.0]]), np.array([[6.0, rise / 2, 0.0]]), np.array([radius]),
                    np.array([radius]), np.array([-1]), np.array([False]), np.array([0]), ("bark",))
    path = tmp_path / "twig.npz"
    skel.save(path)
    cam = tmp_path / "twig_cam.json"
    Camera((0.0, 0.0, 4.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 40.0, 120, 40).save(cam)
    return path, cam


def test_supersampling_covers_a_thin_twig_in_proportion_to_its_width(gl_ctx, tmp_path):
    """A slanting twig 0.3 pixel wide: one ray a pixel hits it in some columns and misses it
    in others (dots); N x N rays a pixel give every column a coverage that sums to the
    twig's height in that column within one sample spacing (1/N pixel)."""
    world_per_pixel = 2 * 4.0 * np.tan(np.radians(20.0)) / 40
    radius, rise = 0.15 * world_per_pixel, 2.0
    path, cam = twig_file(tmp_path, radius, rise)
    height = 2 * radius / world_per_pixel * np.hypot(12.0, rise) / 12.0   # pixels of twig in a column
    inner = slice(20, 100)                               # away from the image's sides
    for n in (1, 4, 5):
        out = tmp_path / f"twig{n}.png"
        code, stdout, err = run_cli("render", path, "-o", out, "--camera", cam, "--background", "none",
                                    "--ssaa", str(n))
        assert code == 0, err
        image = np.asarray(Image.open(out))
        assert image.shape == (40, 120, 4)
        coverage = (image[..., 3].astype(float) / 255)[:, inner].sum(axis=0)
        if n == 1:
            assert (coverage == 0).mean() > 0.3 and (coverage >= 1).mean() > 0.1    # broken into dots
        else:
            assert np.all(np.abs(coverage - height) <= 1.0 / n + 0.01), (n, coverage.min(), coverage.max())
            assert f"{n}x{n} supersampling" in stdout


def test_a_background_colour_stays_exact_and_none_is_transparent(gl_ctx, tmp_path):
    for n in (1, 3):
        out, depth = tmp_path / f"b{n}.png", tmp_path / f"b{n}.npy"
        code, _, err = run_cli("render", "saguaro", "-o", out, "--size", SIZE, "--background", "#204060",
                               "--ssaa", str(n), "--depth-out", depth, "--ground", "none")
        assert code == 0, err
        rgb = np.asarray(Image.open(out))
        miss = ~np.isfinite(np.load(depth))
        assert rgb.shape == (72, 96, 3) and (rgb[miss] == (32, 64, 96)).all(axis=-1).mean() > 0.97
    # the depth of a supersampled render is the plain one's (rays through pixel centres)
    assert np.array_equal(np.load(tmp_path / "b1.npy"), np.load(tmp_path / "b3.npy"))
    out, depth = tmp_path / "t.png", tmp_path / "t.npy"
    assert run_cli("render", "saguaro", "-o", out, "--size", SIZE, "--background", "none", "--depth-out", depth)[0] == 0
    image = Image.open(out)
    assert image.mode == "RGBA"
    alpha = np.asarray(image)[..., 3]
    assert np.array_equal(alpha == 255, np.isfinite(np.load(depth))) and set(np.unique(alpha)) == {0, 255}


def test_a_still_draws_once_unless_frames_are_timed(gl_ctx, tmp_path):
    code, out, _ = run_cli("render", "saguaro", "-o", tmp_path / "a.png", "--size", SIZE)
    assert code == 0 and "one draw" in out
    code, out, _ = run_cli("render", "saguaro", "-o", tmp_path / "b.png", "--size", SIZE, "--time-frames", "4")
    assert code == 0 and "median of 4 frames after a warm-up" in out
    assert np.array_equal(np.asarray(Image.open(tmp_path / "a.png")), np.asarray(Image.open(tmp_path / "b.png")))


def test_the_python_api_renders_an_image_that_shows_itself(gl_ctx, tmp_path):
    image = plantgen.render("saguaro", size=(96, 72), azimuth=40, ssaa=2)
    assert isinstance(image, plantgen.RenderedImage) and image.size == (96, 72)
    shown = np.asarray(Image.open(io.BytesIO(image._repr_png_())))     # what Jupyter displays
    assert np.array_equal(shown, image.array)
    code, _, err = run_cli("render", "saguaro", "-o", tmp_path / "cli.png", "--size", SIZE, "--azimuth", "40",
                           "--ssaa", "2")
    assert code == 0, err
    assert np.array_equal(np.asarray(Image.open(tmp_path / "cli.png")), image.array)
    # the GL package (plantgen.gl) is imported by now; plantgen.render is still the function
    assert importlib.import_module("plantgen.gl.raycast").Raycaster
    assert callable(plantgen.render) and plantgen.render("cactus", size=(32, 24)).size == (32, 24)
    written = plantgen.render("cactus", tmp_path / "c.png", size=(32, 24), background="none")
    assert Image.open(tmp_path / "c.png").mode == "RGBA" and written.report.written == [tmp_path / "c.png"]


def test_the_python_api_exports_a_mesh_that_trimesh_reads(tmp_path):
    summary = plantgen.export("cactus", tmp_path / "c.glb", subdiv=1)
    assert callable(plantgen.export)
    mesh = trimesh.load(tmp_path / "c.glb", force="mesh")
    assert len(mesh.faces) == summary["triangles"] > 0
    info = json.loads(json.dumps({k: str(v) for k, v in summary.items()}))
    assert info["level"] == "1"
