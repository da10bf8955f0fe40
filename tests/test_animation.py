"""Animation (issue 6): only moving instances are re-skinned and uploaded, a frame at t
is deterministic, consecutive frames move smoothly with joints that stay shut, and the
CLI writes GIF/WebP animations and stills at --time."""

from __future__ import annotations

import numpy as np
import pytest
from _cli import run_cli, run_cli_on_terminal
from PIL import Image
from test_effects import SCENE

from plantgen.animation import AnimatedScene
from plantgen.geometry.rays.camera import Camera
from plantgen.gl.raycast import Raycaster
from plantgen.gl.records import RECORD_BYTES, RecordStream
from plantgen.pipeline import grow_file
from plantgen.settings import RaycastSettings


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("anim") / "two_posts.yaml"
    path.write_text(SCENE)
    return path


@pytest.fixture(scope="module")
def scene(scene_file):
    return grow_file(scene_file).scene


CAMERA = Camera((4.0, 3.0, 5.0), (0.0, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0, 64, 48)


def test_only_moving_instances_are_reskinned_and_uploaded(gl_ctx, scene):
    anim = AnimatedScene.from_scene(scene)
    assert anim.animated and len(anim.moving_segments) == 2 and len(anim.static_segments) == 1
    assert anim.skin_calls == 1                       # the static post, once
    stream = RecordStream(gl_ctx)
    updates = [anim.upload(stream, t, CAMERA.eye)[2] for t in (0.0, 0.1, 0.2, 0.3)]
    assert anim.skin_calls == 1 + 4                   # the moving chain, once per frame
    moving_rows = updates[-1].rows_reskinned
    assert moving_rows >= 2
    # the first frame uploads every record; later ones only the moving rows' records
    assert updates[0].upload_bytes == (1 + moving_rows) * RECORD_BYTES
    assert all(u.upload_bytes == moving_rows * RECORD_BYTES for u in updates[1:])
    stream.release()


def test_static_scene_is_skinned_once(gl_ctx, scene):
    from dataclasses import replace

    still = replace(scene, instances=tuple(replace(i, motion=None) for i in scene.instances))
    anim = AnimatedScene.from_scene(still)
    assert not anim.animated
    stream = RecordStream(gl_ctx)
    updates = [anim.upload(stream, t, CAMERA.eye)[2] for t in np.linspace(0, 1, 5)]
    assert anim.skin_calls == 1
    assert [u.rows_reskinned for u in updates] == [0] * 5
    assert [u.upload_bytes for u in updates][1:] == [0] * 4
    stream.release()


def test_frame_at_t_is_deterministic(gl_ctx, scene):
    a, b = AnimatedScene.from_scene(scene), AnimatedScene.from_scene(scene)
    fa, fb = a.frusta_at(0.37), b.frusta_at(0.37)
    assert np.array_equal(fa.base, fb.base) and np.array_equal(fa.plane_hi, fb.plane_hi)
    caster = Raycaster(gl_ctx)
    images = []
    streams = {id(a): RecordStream(gl_ctx), id(b): RecordStream(gl_ctx)}
    for anim in (a, b, a):
        frusta, buf, _ = anim.upload(streams[id(anim)], 0.37, CAMERA.eye)
        images.append(caster.render(frusta, CAMERA, RaycastSettings(), ("bark",),
                                    record_buffer=buf).color)
    assert np.array_equal(images[0], images[1]) and np.array_equal(images[0], images[2])
    assert not np.array_equal(a.frusta_at(0.0).base, fa.base)      # it does move
    for stream in streams.values():
        stream.release()


def test_consecutive_frames_move_smoothly_and_joints_stay_shut(scene):
    anim = AnimatedScene.from_scene(scene)
    dt = 1 / 100
    times = np.arange(0, 1.0, dt)
    frames = [anim.frusta_at(t) for t in times]
    tops = np.stack([f.top for f in frames])                     # (T, rows, 3)
    steps = np.linalg.norm(np.diff(tops, axis=0), axis=-1).max(axis=1)
    # sway of 20° at 1 Hz on a 2 m chain: the tip moves at most ~ 2π·f·A·L per second
    bound = 2 * np.pi * 1.0 * np.radians(20) * 2.0 * dt * 1.5
    assert steps.max() <= bound and steps.max() > 0.1 * bound
    # velocity changes smoothly: no frame jumps more than twice its neighbours' average
    assert np.all(steps[1:-1] <= 2 * 0.5 * (steps[:-2] + steps[2:]) + 1e-9)
    for f in frames:   # joints shut in every pose: a continuing row shares its parent's plane
        child = np.flatnonzero(f.parent_row >= 0)
        assert np.array_equal(f.plane_lo[child], f.plane_hi[f.parent_row[child]])
        assert np.isfinite(f.plane_lo).all() and np.isfinite(f.plane_hi).all()


def test_cli_writes_an_animation_with_progress(gl_ctx, scene_file, tmp_path):
    out = tmp_path / "dance.gif"
    code, stdout, stderr = run_cli_on_terminal("render", scene_file, "-o", out, "--size", "48x36",
                                               "--frames", "4", "--fps", "8", "--shadow-res", "64",
                                               "--effects", "animation,shadows")
    assert code == 0, stderr
    assert "rendering frames" in stderr      # on a terminal only
    assert "frames: 4" in stdout and "update" in stdout
    with Image.open(out) as gif:
        assert gif.n_frames == 4 and gif.size == (48, 36)
        gif.seek(0)
        first = np.asarray(gif.convert("RGB"))
        gif.seek(2)
        third = np.asarray(gif.convert("RGB"))
    assert not np.array_equal(first, third)   # the post sways
    webp = tmp_path / "dance.webp"
    code, _, stderr = run_cli("render", scene_file, "-o", webp, "--size", "48x36", "--frames", "2",
                             "--effects", "animation")
    assert code == 0, stderr
    with Image.open(webp) as im:
        assert im.n_frames == 2
    assert not list(tmp_path.glob(".*part*"))    # temporary names renamed away


def test_cli_still_at_time(gl_ctx, scene_file, tmp_path):
    shots = {}
    for name, t in (("a", "0.25"), ("b", "0.25"), ("c", "0.75")):
        out = tmp_path / f"{name}.png"
        code, _, stderr = run_cli("render", scene_file, "-o", out, "--size", "48x36",
                                  "--effects", "animation", "--time", t)
        assert code == 0, stderr
        shots[name] = np.asarray(Image.open(out))
    assert np.array_equal(shots["a"], shots["b"]) and not np.array_equal(shots["a"], shots["c"])


def test_animation_output_must_be_gif_or_webp(scene_file, tmp_path):
    code, _, stderr = run_cli("render", scene_file, "-o", tmp_path / "x.png", "--frames", "3")
    assert code == 2 and "must end in .gif or .webp" in stderr


def test_shadowed_frames_change_only_where_the_moving_plant_or_its_shadow_is(gl_ctx, scene):
    """No flicker: between consecutive frames (one light window for the clip), pixels
    change only on the moving plant and in its shadow, in either frame; the static post,
    its shadow and the open ground stay identical."""
    from plantgen.geometry.rays.reference import intersect_frusta
    from plantgen.gl.passes import ShadowSettings

    anim = AnimatedScene.from_scene(scene)
    times = (0.30, 0.32)
    box = anim.bounds(np.linspace(0, 1, 5))
    caster = Raycaster(gl_ctx)
    to_light = -np.asarray(scene.light.travel, dtype=np.float64)
    camera = Camera((4.0, 3.0, 5.0), (0.5, 0.8, 0.0), (0.0, 1.0, 0.0), 40.0, 96, 72)
    frames, movers = [], []
    stream = RecordStream(gl_ctx)
    for t in times:
        frusta, buf, update = anim.upload(stream, t, camera.eye)
        n_static = len(frusta) - update.rows_reskinned
        frames.append(caster.render(frusta, camera, RaycastSettings(), ("bark",), to_light, scene.ground,
                                    shadows=ShadowSettings(resolution=256), shadow_box=box,
                                    record_buffer=buf))
        movers.append(frusta.subset(np.arange(n_static, len(frusta))))
    changed = np.any(frames[0].color != frames[1].color, axis=-1)
    assert changed.any()
    eye, dirs = camera.rays()
    region = np.zeros(changed.shape, dtype=bool)
    for mover in movers:
        region |= intersect_frusta(mover, eye, dirs).hit             # the plant itself
        for frame in frames:                                          # and its shadow
            seen = np.isfinite(frame.distance)
            points = eye[seen] + frame.distance[seen, None].astype(np.float64) * dirs[seen]
            blocked = intersect_frusta(mover, points + 1e-4 * to_light,
                                       np.broadcast_to(to_light, points.shape)).hit
            shadowed = np.zeros(seen.sum(), dtype=bool)
            shadowed[blocked] = True
            region[seen] |= shadowed
    grown = region.copy()   # soft shadow edges and silhouettes: two pixels of slack
    for _ in range(2):
        grown[1:] |= grown[:-1].copy()
        grown[:-1] |= grown[1:].copy()
        grown[:, 1:] |= grown[:, :-1].copy()
        grown[:, :-1] |= grown[:, 1:].copy()
    assert not (changed & ~grown).any(), int((changed & ~grown).sum())
    stream.release()
