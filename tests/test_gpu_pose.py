"""Motion on the GPU: the compute program (plantgen.gl.pose, shaders/pose.glsl) poses and
skins an animation's moving rows into the ray caster's records as the CPU does
(pack_records of SwaySkin.skin of SwaySkin.pose) to float32 rounding; a frame where a joint
may turn sharp is skinned on the CPU (knuckle fans); a still scene builds and dispatches
nothing; the vertex-skinned mesh (GS, GS+R) lies on the posed cones away from joints,
stays closed at them, and draws what the re-tessellated mesh draws.

Tolerances (float32 has a 24-bit significand, so one rounding of x costs up to 2^-24·|x|):

* positions (a record's base, relative to the eye): 2^-21·(|base - eye| + (D + 1)·H), H
  the plant's size (its longest root path), D its depth. The CPU rounds base - eye once
  (2^-24·|base - eye|); the GPU rounds the tree's root start - eye once, then adds D + 1
  plant-sized terms (each addition rounds by at most 2^-24·H) and the root start: eight
  times that budget. Measured on llvmpipe: 3.8e-6 at |base - eye| ~ 35 m (one float32
  unit there, 1.1e-7 of it).
* lengths, radii, plane offsets (formed relative to each row's base from lengths and
  angles): 2^-20·H.
* unit directions (axis, reference direction, plane normals) and u offsets (turns, mod 1):
  2^-17 (7.6e-6, about 64 float32 units of 1): they come out of a few dozen float32
  operations, the sine and cosine of the turn, and products along chains up to nine
  joints long. Measured: 5e-7.
* twist, shell, tag: exact.
* the skinned mesh away from joints: within 2^-20·(|eye| + 8) of its row's posed cone (the
  pose buffer's float32 start, rounded at its distance from the eye, and its turn, good to
  2^-17, times the vertex's offset from its pivot, under a metre here); a joint ring within
  r·|θ|/2 (+1e-5) of both cones, θ the joint's angle.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_effects import SCENE
from test_sway_skin import small_scene

from plantgen.animation import AnimatedScene
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.meshes.skinned_mesh import skin_positions
from plantgen.geometry.rays.camera import Camera
from plantgen.geometry.skeletons.motion import pose, sway_rig
from plantgen.geometry.skeletons.skeleton import Skeleton
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.geometry.stage import Sway
from plantgen.geometry.vec import ancestor_count
from plantgen.gl.pose import PoseStream, tree_groups
from plantgen.gl.raster import RasterRenderer
from plantgen.gl.raycast import Raycaster
from plantgen.gl.records import RECORD_FLOATS, StreamedRows, pack_records
from plantgen.pipeline import grow_file, render_model
from plantgen.settings import RaycastSettings

EYE = np.array([4.0, 17.0, 30.0])        # the dancing cacti's camera


@pytest.fixture(scope="module")
def cacti():
    return AnimatedScene.from_scene(grow_file("dancing_cacti").scene)


def plant_size(plan) -> float:
    """H: the longest root path of the plan's trees (world units)."""
    return float(plan.tree(plan.length).max())


def gpu_records(stream, anim, t, eye):
    """(rows, update, (rows, 24) float64 records) of the frame at ``t`` through ``stream``."""
    rows, buffer, update = anim.upload(stream, t, eye)
    records = np.frombuffer(buffer.read(), np.float32).reshape(-1, RECORD_FLOATS)[:len(rows)]
    return rows, update, records.astype(np.float64)


def assert_records_agree(got, want, size, depth):
    """The GPU's records against the CPU's to the module's tolerances."""
    assert got.shape == want.shape
    reach = np.linalg.norm(want[:, 0:3], axis=1) + (depth + 1) * size
    np.testing.assert_array_less(np.abs(got[:, 0:3] - want[:, 0:3]).max(axis=1), 2.0**-21 * reach)
    for cols in ((3,), (7,), (11,), (15,), (19,)):
        np.testing.assert_allclose(got[:, cols], want[:, cols], rtol=0, atol=2.0**-20 * size, err_msg=str(cols))
    for cols in (slice(4, 7), slice(8, 11), slice(12, 15), slice(16, 19)):
        np.testing.assert_allclose(got[:, cols], want[:, cols], rtol=0, atol=2.0**-17, err_msg=str(cols))
    u = (got[:, 20] - want[:, 20] + 0.5) % 1.0 - 0.5
    np.testing.assert_allclose(u, 0.0, atol=2.0**-17)
    np.testing.assert_array_equal(got[:, 21:], want[:, 21:])


@pytest.mark.parametrize("mode, rows_per_group", [("groups", 1024), ("groups", 200), ("doubling", 300),
                                                  ("walks", 0)])
def test_gpu_records_equal_the_cpu_pose_to_float32_rounding(gl_ctx, cacti, mode, rows_per_group):
    plan = cacti.plan
    stream = PoseStream(gl_ctx, mode, rows_per_group or 1024)
    size, depth = plant_size(plan), int(ancestor_count(plan.parent).max())
    for t in (0.0, 0.37, 2.9, 1e3):
        rows, update, got = gpu_records(stream, cacti, t, EYE)
        assert isinstance(rows, StreamedRows) and update.on_gpu and update.rows_reskinned == plan.n
        assert update.upload_bytes <= 4 * len(stream.gpu(plan).frequencies) + 64 * len(plan.roots)
        assert_records_agree(got, pack_records(plan.skin(plan.pose(t)), EYE), size, depth)
        assert stream.gpu(plan).take_sharp_count() == 0
    assert mode == "walks" or len(stream.gpu(plan).groups) == len(tree_groups(plan, rows_per_group)) > 1
    stream.release()


def hard_plants():
    """small_scene's first plant (zero bends, a 40° bend, a radius step into a cone closing
    to a point at a tip, side branches, one starting at radius 0, a bend at a side
    branch's joint) and a straight chain through a zero-length segment, each swaying."""
    a, _ = small_scene()
    up = np.array([0.0, 1.0, 0.0])
    start = np.array([[3.0, 0, 0], [3.0, 1, 0], [3.0, 1, 0]])
    chain = Skeleton(start, start + [up, 0 * up, up], [0.2, 0.18, 0.18], [0.18, 0.18, 0.1], [-1, 0, 1],
                     [False, True, True], [0, 0, 0], ("bark",))
    skeleton = Skeleton.concatenate([a, chain])
    motions = [Sway(amplitude=35, frequency=0.7, phase=0.4), Sway(amplitude=15, frequency=0.9, phase=1.3)]
    return AnimatedScene(skeleton, np.repeat([0, 1], [len(a), len(chain)]), motions)


def test_hard_cases_sway_on_the_gpu_as_on_the_cpu(gl_ctx):
    """The first plant never comes near a sharp joint; the zero-length segment's planes may
    cross (the cheap exclusion cannot rule it out) where its parent bends, so those phases
    are the CPU's."""
    anim, eye = hard_plants(), np.array([2.0, 1.5, 6.0])
    plan = anim.plan
    cells = plan.sharp_cells()
    assert plan is not None and not cells[0].any() and 0 < cells[1].sum() < cells.shape[1]
    stream = PoseStream(gl_ctx)
    on_gpu = 0
    for t in np.linspace(0.0, 3.0, 13):
        rows, update, got = gpu_records(stream, anim, t, eye)
        assert update.on_gpu != plan.may_be_sharp(t)
        frusta = plan.skin(plan.pose(t))
        if frusta is None:                         # knuckles: the general path's rows
            frusta = skin_skeleton(plan.skeleton(plan.pose(t), anim.skeleton))
        want = pack_records(frusta, eye)
        if update.on_gpu:
            assert_records_agree(got, want, plant_size(plan), 6)
            on_gpu += 1
        else:
            np.testing.assert_array_equal(got, want)
    assert on_gpu >= 3
    stream.release()


def test_hard_cases_stay_closed_while_they_sway(gl_ctx):
    """The GPU's frames draw what the CPU's draw: the same coverage but for a few pixels on
    silhouettes (a hole would show as pixels only the CPU's frame covers, inside both) and
    the same distances where both hit."""
    gpu_anim, cpu_anim = hard_plants(), hard_plants()
    camera = Camera((2.0, 1.5, 6.0), (1.5, 1.0, 0.0), (0.0, 1.0, 0.0), 40.0, 160, 120)
    caster, stream = Raycaster(gl_ctx), PoseStream(gl_ctx)
    for t in (0.2, 1.1, 2.6):
        rows, buffer, _ = gpu_anim.upload(stream, t, camera.eye)
        gpu = caster.render(rows, camera, RaycastSettings(), rows.material_names, record_buffer=buffer)
        frusta = cpu_anim.frusta_at(t)
        cpu = caster.render(frusta, camera, RaycastSettings(), frusta.material_names)
        hit_g, hit_c = np.isfinite(gpu.distance), np.isfinite(cpu.distance)
        assert hit_c.sum() > 1000 and (hit_g != hit_c).sum() <= 4
        both = hit_g & hit_c
        assert np.abs(gpu.distance[both] - cpu.distance[both]).max() < 1e-3
        assert not _holes(hit_g, hit_c).any()
    stream.release()


def _holes(covered, reference):
    """Pixels ``reference`` covers and ``covered`` does not, all 8 neighbours of which
    ``covered`` covers: holes, not silhouettes."""
    padded = np.pad(covered, 1)
    around = np.ones_like(covered)
    h, w = covered.shape
    for dy in (0, 1, 2):
        for dx in (0, 1, 2):
            if (dy, dx) != (1, 1):
                around &= padded[dy:dy + h, dx:dx + w]
    return reference & ~covered & around


def bending_joint():
    """A two-segment chain bent 110° in the plane ⟂ x, swaying about x: its joint angle
    runs over ±20°, so the bend crosses the 120° limit for part of each period."""
    bend = np.radians(110.0)
    start = np.array([[0.0, 0, 0], [0.0, 1, 0]])
    end = start[[1, 1]] + np.array([[0.0, 0, 0], [0.0, np.cos(bend), np.sin(bend)]])
    end[0] = [0.0, 1.0, 0.0]
    skeleton = Skeleton(start, end, [0.1, 0.1], [0.1, 0.1], [-1, 0], [False, True], [0, 0], ("bark",))
    return skeleton, [Sway(amplitude=40.0, frequency=0.5, phase=0.0)]


def test_a_frame_with_a_sharp_joint_is_skinned_on_the_cpu(gl_ctx):
    skeleton, motions = bending_joint()
    anim = AnimatedScene(skeleton, np.zeros(2, int), motions)
    rig = sway_rig(skeleton, np.zeros(2, int), motions)
    plan, stream, eye = anim.plan, PoseStream(gl_ctx), np.array([3.0, 1.0, 4.0])
    kinds = set()
    for t in np.linspace(0.0, 2.0, 41):          # one period
        rows, update, got = gpu_records(stream, anim, t, eye)
        sharp = plan.skin(plan.pose(t)) is None
        assert plan.may_be_sharp(t) or not sharp  # the table never misses a sharp frame
        kinds.add((update.on_gpu, sharp))
        if update.on_gpu:
            assert_records_agree(got, pack_records(plan.skin(plan.pose(t)), eye), plant_size(plan), 1)
            assert stream.gpu(plan).take_sharp_count() == 0
        else:                                     # the CPU's frame, knuckle fans where sharp
            want = skin_skeleton(plan.skeleton(plan.pose(t), skeleton)) if sharp else plan.skin(plan.pose(t))
            np.testing.assert_array_equal(got, pack_records(want, eye))
            if sharp:
                assert len(rows) > 2 and want.report.fan_rows > 0
                general = skin_skeleton(pose(skeleton, rig, t))
                assert len(general) == len(rows) and general.report.sharp_joints == 1
    assert (True, False) in kinds and (False, True) in kinds
    stream.release()


def test_a_still_scene_builds_and_dispatches_nothing(gl_ctx):
    from dataclasses import replace

    scene = grow_file_text(SCENE)
    still = AnimatedScene.from_scene(replace(scene, instances=tuple(replace(i, motion=None) for i in scene.instances)))
    assert still.plan is None and not still.animated
    stream = PoseStream(gl_ctx)
    for t in (0.0, 0.5, 1.0):
        rows, _, update = still.upload(stream, t, EYE)
        assert not update.on_gpu and update.rows_reskinned == 0
    assert stream._gpu is None                    # no rest data, no program, no dispatch
    stream.release()


def grow_file_text(text):
    import tempfile
    from pathlib import Path

    folder = Path(tempfile.mkdtemp())
    (folder / "scene.yaml").write_text(text)
    return grow_file(folder / "scene.yaml").scene


def test_the_pose_buffer_holds_posed_starts_and_turns(gl_ctx, cacti):
    plan, stream = cacti.plan, PoseStream(gl_ctx)
    for t in (0.0, 1.3):
        buffer, update = cacti.pose_segments(stream, t, EYE)
        poses = np.frombuffer(buffer.read(), np.float32).reshape(-1, 8)[:plan.n].astype(np.float64)
        posed = plan.pose(t)
        reach = np.linalg.norm(posed.start.T - EYE, axis=1) + 16 * plant_size(plan)
        np.testing.assert_array_less(np.abs(poses[:, 0:3] + EYE - posed.start.T).max(axis=1), 2.0**-21 * reach)
        x = (plan.omega * t + plan.phase)[plan.tree_of]
        np.testing.assert_allclose(poses[:, 3], np.sin(x) * plan.ca - np.cos(x) * plan.sa, atol=2.0**-17)
        assert update.on_gpu
    stream.release()


# ---------------------------------------------------------------------------- the skinned mesh
def posed_skinned(anim, skinned, stream, t, eye):
    """The skinned mesh's vertices at ``t`` as the vertex shader places them (its numpy
    twin fed with the GPU's pose buffer)."""
    buffer, _ = anim.pose_segments(stream, t, eye)
    poses = np.frombuffer(buffer.read(), np.float32).reshape(-1, 8)[:anim.plan.n].astype(np.float64)
    return skin_positions(skinned, poses[:, 0:3] + eye, poses[:, 3], poses[:, 4:7])


def cone_distance(frusta, rows, points):
    """(k,) distance of ``points`` from the infinite cones of ``rows``."""
    d = points - frusta.base[rows]
    y = np.einsum("ij,ij->i", d, frusta.axis[rows])
    radial = np.linalg.norm(d - y[:, None] * frusta.axis[rows], axis=1)
    return np.abs(radial - (frusta.r1[rows] + frusta.slope[rows] * y)) / np.sqrt(1 + frusta.slope[rows] ** 2)


def test_the_skinned_mesh_lies_on_the_posed_cones_away_from_joints(gl_ctx):
    """Away from joints a vertex is its row's rest vertex moved rigidly: on the posed
    cone (the re-tessellated mesh's vertices lie on it too) to float32 rounding of the
    plant's size; a joint ring between the two cones, within r·|θ|/2 of each."""
    anim, eye = hard_plants(), np.array([2.0, 1.5, 6.0])
    rest, segment = anim.rest_frusta()
    mesh = tessellate(rest, 2, caps=False)
    skinned, stream = anim.skinned(mesh), PoseStream(gl_ctx)
    assert set(np.unique(skinned.pivot)) <= set(np.unique(segment))       # (the zero-length row has no face)
    for t in (0.3, 1.9):
        posed = anim.frusta_at(t)                   # the CPU's rows at t: one per segment here
        row_of = np.full(anim.plan.n, -1)
        row_of[posed.segment] = np.arange(len(posed))
        points = posed_skinned(anim, skinned, stream, t, eye)
        # a side branch's base moves back into its host by a pose-dependent δ and, where
        # its radius would drop below 0 there (one of these starts at radius 0), its cone
        # changes with δ: it is at a joint, so it is left out
        alone = (skinned.pivot >= 0) & ~skinned.shared & ~np.isin(skinned.pivot, anim.plan.side)
        rows = row_of[skinned.pivot[alone]]
        assert cone_distance(posed, rows, points[alone]).max() < 2.0**-20 * (np.abs(eye).max() + 8)
        shared = skinned.shared
        turns = _turns(anim.plan, t)
        theta = np.abs(turns[skinned.pivot[shared]] - turns[skinned.other[shared]])
        r = np.maximum(posed.r1[row_of[skinned.pivot[shared]]], posed.r2[row_of[skinned.other[shared]]])
        for side in (skinned.pivot[shared], skinned.other[shared]):
            gap = cone_distance(posed, row_of[side], points[shared])
            assert np.all(gap <= r * theta / 2 + 1e-5)
    stream.release()


def _turns(plan, t):
    x = (plan.omega * t + plan.phase)[plan.tree_of]
    return np.sin(x) * plan.ca - np.cos(x) * plan.sa


@pytest.mark.parametrize("relief", [False, True])
def test_the_skinned_mesh_stays_watertight_as_it_sways(gl_ctx, cacti, relief):
    import trimesh

    rest, _ = cacti.rest_frusta()
    mesh = tessellate(rest, 0, relief=relief)
    skinned, stream = cacti.skinned(mesh), PoseStream(gl_ctx)
    for t in (0.0, 0.8):
        points = posed_skinned(cacti, skinned, stream, t, EYE)
        posed = trimesh.Trimesh(points, mesh.faces, process=False)
        posed.merge_vertices()
        assert posed.is_watertight and posed.is_winding_consistent
    stream.release()


def test_the_skinned_mesh_draws_what_the_retessellated_one_draws(gl_ctx, cacti):
    """GS of the dancing cacti posed by the vertex shader against the posed frusta
    tessellated anew: the same coverage but for silhouette pixels, no hole where the
    re-tessellated one has none, and the same depth where both hit."""
    camera = Camera(tuple(EYE), (0.0, 1.2, 0.0), (0.0, 1.0, 0.0), 42.0, 200, 150)
    rest, _ = cacti.rest_frusta()
    skinned, stream = cacti.skinned(tessellate(rest, 1, caps="tips")), PoseStream(gl_ctx)
    box = cacti.motion_box()
    skin_r, tess_r = RasterRenderer(gl_ctx), RasterRenderer(gl_ctx)
    for t in (0.4, 1.7):
        poses, _ = cacti.pose_segments(stream, t, camera.eye)
        got = skin_r.render(skinned, rest, camera, poses=poses, bounds=box)
        posed = cacti.frusta_at(t)
        want = tess_r.render(tessellate(posed, 1, caps="tips"), posed, camera)
        hit_g, hit_w = np.isfinite(got.distance), np.isfinite(want.distance)
        assert hit_w.sum() > 2000 and (hit_g != hit_w).mean() < 0.004
        assert not _holes(hit_g, hit_w).any()
        both = hit_g & hit_w
        close = np.abs(got.distance[both] - want.distance[both]) < 0.02
        assert close.mean() > 0.99
    for r in (skin_r, tess_r):
        r.release()
    stream.release()


def test_render_frames_pose_on_the_gpu_unless_asked_not_to(gl_ctx, tmp_path):
    path = tmp_path / "two_posts.yaml"
    path.write_text(SCENE)
    gpu = render_model(path, size=(64, 48), frames=3, fps=10, effects="animation")
    cpu = render_model(path, size=(64, 48), frames=3, fps=10, effects="animation", pose="cpu")
    assert gpu.gpu_frames == 3 and cpu.gpu_frames == 0
    for a, b in zip(gpu.colors, cpu.colors, strict=True):
        assert (np.abs(a.astype(int) - b.astype(int)).max(axis=-1) > 8).mean() < 0.01


def test_the_cli_says_where_the_frames_were_posed(gl_ctx, tmp_path):
    from _cli import run_cli

    path = tmp_path / "two_posts.yaml"
    path.write_text(SCENE)
    for pose_option, said in (("gpu", "on the GPU in 2 of 2 frames"), ("cpu", "on the CPU")):
        code, stdout, stderr = run_cli("render", path, "-o", tmp_path / f"{pose_option}.gif", "--size", "32x24",
                                       "--frames", "2", "--effects", "animation", "--pose", pose_option)
        assert code == 0, stderr
        assert said in stdout


@pytest.mark.parametrize("method", ["RC", "GS"])
def test_the_viewer_poses_a_playing_animation_on_the_gpu(gl_ctx, tmp_path, method):
    from plantgen.settings import RenderSettings
    from plantgen.viewer.session import ViewerSession, ViewOptions

    path = tmp_path / "two_posts.yaml"
    path.write_text(SCENE)
    options = ViewOptions(input=path, settings=RenderSettings.from_options(effects="animation"), size=(80, 60),
                          watch=False, shots=tmp_path, method=method.lower() if method == "RC" else "gs")
    session = ViewerSession(gl_ctx, options, options.prepare(), say=lambda line: None, warn=lambda line: None)
    session.method = method
    session.toggle_play()
    session.tick(0.35)
    assert session.posing_on_gpu()
    playing = session.draw(80, 60)
    assert session.model.anim.updates[-1].on_gpu
    session.toggle_play()                          # paused: the CPU's frame, as render --time draws it
    assert not session.posing_on_gpu()
    paused = session.draw(80, 60)
    hit_p, hit_q = np.isfinite(playing.distance), np.isfinite(paused.distance)
    assert hit_q.sum() > 200 and (hit_p != hit_q).sum() <= 3
    if method == "GS":
        assert "skinned on the GPU" not in session.hud_lines()[0][0]   # paused
    session.release()


def test_leaves_sway_with_a_frame_posed_on_the_gpu(gl_ctx, tmp_path):
    """Leaves are posed on the CPU (the plan's pose, no skin) for a frame the GPU posed:
    the same leaves as after a CPU frame at that time."""
    import shutil

    from test_leaf_sway import SWAYING, TWIG

    shutil.copy(TWIG, tmp_path / TWIG.name)
    (tmp_path / "windy.yaml").write_text(SWAYING)
    scene = grow_file(tmp_path / "windy.yaml").scene
    gpu_anim, cpu_anim = AnimatedScene.from_scene(scene), AnimatedScene.from_scene(scene)
    stream = PoseStream(gl_ctx)
    for t in (0.3, 1.2):
        _, _, update = gpu_anim.upload(stream, t, EYE)
        assert update.on_gpu
        calls = gpu_anim.skin_calls
        leaves = gpu_anim.leaves_at(t)
        assert gpu_anim.skin_calls == calls                # posed, not skinned
        cpu_anim.frusta_at(t)
        want = cpu_anim.leaves_at(t)
        np.testing.assert_allclose(leaves.vertices, want.vertices, rtol=0, atol=1e-12)
        np.testing.assert_allclose(leaves.normal, want.normal, rtol=0, atol=1e-12)
    stream.release()


def test_the_motion_box_holds_every_frame():
    """The box frames posed on the GPU are drawn with (their depth range, light window)
    holds every frame the CPU skins, at times between the box's samples too."""
    from plantgen.geometry.skeletons.frusta import frusta_bounds

    skeleton, motions = bending_joint()
    for anim in (hard_plants(), AnimatedScene(skeleton, np.zeros(2, int), motions)):
        box = anim.motion_box()
        for t in np.linspace(0.0, 3.0, 61):
            frame = frusta_bounds(anim.frusta_at(t))
            assert np.all(frame[0] >= box[0]) and np.all(frame[1] <= box[1]), t
