"""The viewer's state and frames without a window (EGL): every control changes what it
says, each frame equals ``plantgen render`` of the same state, and the file watcher and
the reload thread behave (issue 13)."""

from __future__ import annotations

import os
import shlex
import time

import numpy as np
import pytest
from _cli import run_cli
from PIL import Image

from plantgen.geometry.meshes.mesh import triangle_count
from plantgen.geometry.rays.camera import auto_camera, orbit_angles
from plantgen.pipeline import prepare_model, render_model
from plantgen.settings import MAX_SUBDIV
from plantgen.viewer.handlers import ACTIONS
from plantgen.viewer.keys import BINDINGS, GROW_STEP_S, binding_for, help_lines
from plantgen.viewer.session import VIEW_MAX_TRIANGLES, ViewerSession, ViewOptions
from plantgen.viewer.watch import BackgroundJob, FileWatcher

SIZE = (96, 72)


@pytest.fixture
def session(gl_ctx, tmp_path):
    options = ViewOptions(input="saguaro", size=SIZE, watch=False, shots=tmp_path)
    s = ViewerSession(gl_ctx, options, prepare_model("saguaro"), say=lambda line: None, warn=lambda line: None)
    yield s
    s.release()


def test_every_binding_names_a_control_of_the_session():
    for b in BINDINGS:
        assert callable(getattr(ViewerSession, b.action)), b
        assert ACTIONS[b.action] is getattr(ViewerSession, b.action), b     # the session's method is the handler
    assert binding_for("P", False).action == "screenshot" and binding_for("P", True).action == "window_shot"
    assert {k for k, _ in help_lines()} >= {"P", "C", "H", "1 2 3 4 5 6", "Space"}


def test_the_first_frame_is_plantgen_renders(session):
    frame = session.draw(*SIZE)
    assert np.array_equal(frame.color, render_model("saguaro", size=SIZE).result.color)


def test_keys_change_method_knobs_and_frame_as_render_does(session, tmp_path):
    session.key("_2")
    session.key("S")
    session.key("L", shift=True)        # linear steps 32 -> 16
    session.key("B")                    # binary steps 12 -> 13
    session.key("M")                    # fixed march
    session.key("A")                    # 2 x 2 supersampling
    march = session.march
    assert (session.method, session.shadows, march.linear_steps, march.binary_steps, march.march,
            session.ssaa) == ("RC+R", True, 16, 13, "fixed", 2)
    frame = session.draw(*SIZE)
    expected = render_model("saguaro", size=SIZE, relief=True, shadows=True, linear_steps=16, binary_steps=13,
                            march="fixed", ssaa=2)
    assert np.array_equal(frame.color, expected.result.color)
    # the printed command draws the same frame
    camera = session.save_camera()
    args = shlex.split(session.render_command(camera))
    assert run_cli(*args[1:])[0] == 0
    assert np.array_equal(np.asarray(Image.open(args[args.index("-o") + 1])), frame.color)


def test_orbit_pan_zoom_and_reset_move_the_camera_as_their_keys_say(session):
    a0, e0, d0 = orbit_angles(session.camera)
    session.key("LEFT")
    session.key("UP")
    a1, e1, d1 = orbit_angles(session.camera)
    assert (a1 - a0, e1 - e0, d1) == (pytest.approx(-5.0), pytest.approx(5.0), pytest.approx(d0))
    session.key("EQUAL")
    assert orbit_angles(session.camera)[2] == pytest.approx(d0 / 1.1)
    right = session.camera.basis()[0]
    target = np.asarray(session.camera.target)
    dist = orbit_angles(session.camera)[2]
    session.key("RIGHT", shift=True)                  # pan 5 % of the view's height to the right
    moved = np.asarray(session.camera.target) - target
    view_height = 2 * dist * np.tan(np.radians(session.camera.fov_y) / 2)
    assert np.allclose(moved, 0.05 * view_height * right)
    session.drag(10, 0)                               # a drag to the right turns the other way
    assert orbit_angles(session.camera)[0] == pytest.approx(a1 - 4.0)
    session.key("R")
    assert session.camera == auto_camera(session.frusta(), *SIZE)


def test_gs_levels_stay_within_the_triangle_budget(session):
    session.key("_3")
    session.key("BRACKETRIGHT")
    assert (session.method, session.level) == ("GS", 2)
    frame = session.draw(*SIZE)
    rows = len(session.frusta())        # the saguaro's 30 segments, its elbows smoothed into arcs
    assert len(session.mesh(session.frusta()).faces) == rows * 16 * 4 ** 2 + session.mesh(session.frusta()).n_caps * 32
    assert frame.stats.triangles == len(session.mesh(session.frusta()).faces)
    for _ in range(10):
        session.key("BRACKETRIGHT")
    # the keys climb to the finest level the viewer's triangle budget allows (30 segments
    # were m = 7, 7.9 M triangles; m = 8 would be 31 M), never past the settings' finest level
    frusta = session.frusta()
    caps = int(frusta.open_lo.sum() + frusta.open_hi.sum())
    assert session.level <= MAX_SUBDIV
    assert triangle_count(len(frusta), session.level, caps) <= VIEW_MAX_TRIANGLES
    assert triangle_count(len(frusta), session.level + 1, caps) > VIEW_MAX_TRIANGLES
    session.key("_4")
    assert session.method == "GS+R"


def test_keys_5_and_6_ray_trace_as_render_method_rt(session):
    session.key("_6")
    assert session.method == "RT+R" and session.request().march.method == "rt"
    frame = session.draw(*SIZE)
    rendered = render_model("saguaro", size=SIZE, method="rt", relief=True).result
    assert frame.stats.program[0] == "rt.glsl"
    assert np.array_equal(frame.color, rendered.color)
    assert any(text.startswith("RT+R") or "RT+R" in text for text, _ in session.hud_lines())


def test_a_still_model_does_not_play(session):
    session.key("SPACE")
    session.key("PERIOD")
    assert (session.playing, session.t) == (False, 0.0) and "nothing moves" in session.status


def test_screenshots_and_cameras_get_fresh_names(session, tmp_path):
    paths = [session.screenshot(), session.save_camera(), session.screenshot()]
    assert [p.name for p in paths] == ["saguaro-001.png", "saguaro-002.json", "saguaro-003.png"]
    assert np.array_equal(np.asarray(Image.open(paths[0])), session.last.color)


# ---------------------------------------------------------------------- watching files
def test_a_change_is_reported_once_it_has_settled(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("a")
    watcher = FileWatcher([f], settle_s=0.05)
    assert watcher.poll(0.0) is None
    os.utime(f, ns=(time.time_ns(), time.time_ns() + 10**9))
    assert watcher.poll(1.0) is None                  # seen moving
    change = watcher.poll(1.06)
    assert change is not None and change.paths == (f.resolve(),)
    assert change.saved_ns == os.stat(f).st_mtime_ns
    assert watcher.poll(2.0) is None                  # reported once


def test_a_file_replaced_by_rename_is_seen_and_a_missing_one_waited_for(tmp_path):
    f = tmp_path / "g.yaml"
    f.write_text("one")
    watcher = FileWatcher([f], settle_s=0.0)
    tmp = tmp_path / "g.yaml.new"
    tmp.write_text("two")
    os.replace(tmp, f)                                # editors that write a new file and rename it
    assert watcher.poll(0.0) is not None or watcher.poll(0.01) is not None
    f.unlink()
    assert watcher.poll(1.0) is None and watcher.poll(2.0) is None
    f.write_text("three")
    assert watcher.poll(3.0) is not None or watcher.poll(3.01) is not None


def finished(job, seconds: float = 5.0):
    """The job's result once it has one (polling, at most ``seconds``), else None."""
    deadline = time.monotonic() + seconds
    done = job.result()
    while done is None and time.monotonic() < deadline:
        time.sleep(0.01)
        done = job.result()
    return done


def test_the_background_job_runs_the_newest_queued_arguments():
    import threading

    gate = threading.Event()
    calls = []

    def work(x):
        gate.wait(5)
        calls.append(x)
        return x * 2

    job = BackgroundJob(work)
    job.start(1)
    job.start(2)
    job.start(3)                                       # supersedes 2
    gate.set()
    done = finished(job)
    assert done == ((3,), 6, None) and calls == [1, 3] and not job.busy


def test_a_failing_reload_hands_back_its_error():
    job = BackgroundJob(lambda: 1 / 0)
    job.start()
    done = finished(job)
    assert isinstance(done[2], ZeroDivisionError)


def test_the_viewer_guide_lists_the_keys_the_viewer_binds():
    from _docs import page

    rows = [line for line in page("how-to/view.md").splitlines() if line.startswith("| ")]
    for keys, text in help_lines():
        assert f"| {keys} | {text} |" in rows, (keys, text)


def test_smooth_bends_reach_the_viewer_and_its_render_command(gl_ctx, tmp_path):
    # --smooth-bends 10 turns the saguaro's bent joints into arcs; the frame the viewer
    # draws is the one its printed command renders
    options = ViewOptions(input="saguaro", size=SIZE, watch=False, shots=tmp_path, smooth_bends=10.0)
    model = options.prepare()
    # (its grammar smooths bends past 20°; 179° leaves the polyline)
    assert len(model.frusta_at(0.0)) > len(prepare_model("saguaro", smooth_bends=179.0).frusta_at(0.0))
    s = ViewerSession(gl_ctx, options, model, say=lambda line: None, warn=lambda line: None)
    try:
        frame = s.draw(*SIZE)
        args = shlex.split(s.render_command(s.save_camera()))
        assert args[args.index("--smooth-bends") + 1] == "10.0"
        assert run_cli(*args[1:])[0] == 0
        assert np.array_equal(np.asarray(Image.open(args[args.index("-o") + 1])), frame.color)
    finally:
        s.release()


@pytest.mark.parametrize("method", ["RC", "GS"])
def test_the_viewer_draws_a_grammars_leaves(gl_ctx, tmp_path, method):
    leafy = tmp_path / "leafy.yaml"
    leafy.write_text('name: leafy\naxiom: "F[+(40)F{.+(30)G.-(30)G.-(30)G.}]F"\nmaterials: [bark, leaf]\n'
                     'turtle: {angle: 30, step: 1.0}\nrules: []\n')
    bare = tmp_path / "bare.yaml"
    bare.write_text(leafy.read_text().replace("{.+(30)G.-(30)G.-(30)G.}", "").replace("leafy", "bare"))
    frames = {}
    for path in (leafy, bare):
        options = ViewOptions(input=path, size=SIZE, watch=False, shots=tmp_path, method=method)
        s = ViewerSession(gl_ctx, options, options.prepare(), say=lambda line: None, warn=lambda line: None)
        try:
            if path is bare:
                s.camera = frames[leafy][1]       # the leafy plant's framing for both
            frames[path] = (s.draw(*SIZE), s.camera, s.hud_lines()[0][0])
        finally:
            s.release()
    with_leaf, without = frames[leafy][0], frames[bare][0]
    # same camera: the leaf covers pixels where the bare plant shows the sky
    gained = np.isfinite(with_leaf.distance) & ~np.isfinite(without.distance)
    assert gained.sum() > 20
    assert "leaves" in with_leaf.stats.passes and "leaves" not in without.stats.passes
    assert "1 leaf |" in frames[leafy][2] and "leaf" not in frames[bare][2]      # the heads-up line


def test_a_placed_forest_opens_in_every_method(gl_ctx, tmp_path):
    """A scene with the lod effect is drawn instanced in the viewer, RC to GS+R."""
    scene = tmp_path / "grove.yaml"
    scene.write_text("effects: [shadows, lod]\nground: {size: 40}\ncamera: {eye: [0, 2, 30], target: [0, 3, 0]}\n"
                     "instances:\n  - {grammar: abop_monopodial, grid: {count: [3, 3], spacing: [8, 8], jitter: 0.3,"
                     " seeds: 1}}\n")
    options = ViewOptions(input=str(scene), size=SIZE, watch=False, shots=tmp_path)
    s = ViewerSession(gl_ctx, options, prepare_model(scene), say=lambda line: None, warn=lambda line: None)
    try:
        for key in ("_1", "_2", "_3", "_4"):
            s.key(key)
            frame = s.draw(*SIZE)
            assert np.isfinite(frame.distance).mean() > 0.05, key
    finally:
        s.release()


def test_the_mesh_caster_casts_still_frames_and_playing_ones_fall_back_to_the_march_said_once(gl_ctx, tmp_path):
    """``--shadow-caster mesh`` in the viewer: the paused frame's map is the mesh's; frames
    posed on the GPU, which it cannot cast, are cast by the relief march, and the viewer
    says so once instead of failing."""
    from dataclasses import replace

    from plantgen.settings import RenderSettings, ShadowSettings

    settings = replace(RenderSettings(), shadows=ShadowSettings(caster="mesh", mesh_level=1))
    lines = []
    options = ViewOptions(input="dancing_cacti", size=SIZE, watch=False, shots=tmp_path, settings=settings)
    s = ViewerSession(gl_ctx, options, prepare_model("dancing_cacti"), say=lambda line: None, warn=lines.append)
    try:
        s.draw(*SIZE)
        assert ("raster.glsl", ("SHADOW_PASS",)) in s.raycaster.programs_used and not lines
        s.toggle_play()
        assert s.posing_on_gpu()
        for _ in range(2):
            s.t += 0.1
            assert s.draw(*SIZE).color.shape == (SIZE[1], SIZE[0], 3)
        assert len(lines) == 1 and "relief march" in lines[0]
    finally:
        s.release()


# ---------------------------------------------------------------------- growth step by step
SPROUT = """name: sprout
seed: 1
iterations: 4
defines: {a: 25}
axiom: "!(0.12) F(1) A"
rules:
  - "A -> F(0.5) [+(a) ! F(0.6) A] [-(a) ! F(0.6) A] /(90) A"
"""


def _sprout_session(gl_ctx, tmp_path, text=SPROUT, **options):
    path = tmp_path / "sprout.yaml"
    path.write_text(text)
    opts = ViewOptions(input=path, size=SIZE, watch=False, shots=tmp_path, **options)
    said = []
    s = ViewerSession(gl_ctx, opts, opts.prepare(), say=said.append, warn=said.append)
    return s, path, said


def _until_grown(s, seconds: float = 20.0, dt: float = 0.01) -> None:
    """Tick the session until its reload thread is idle and its result taken in."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        s.tick(dt)
        if not s.reloader.busy:
            s.tick(dt)            # a result handed back after the last look
            return
        time.sleep(0.01)
    raise AssertionError("the growth step did not finish")


def test_growth_steps_back_and_forward_as_iterations_grow_it(gl_ctx, tmp_path):
    s, path, said = _sprout_session(gl_ctx, tmp_path)
    try:
        assert (s.step, s.steps_end, s.step_target) == (4, 4, None)
        assert not any(text.startswith("growth:") for text, _ in s.hud_lines())
        segments = {k: prepare_model(path, iterations=k).grown.segments for k in range(5)}
        assert all(segments[k] < segments[k + 1] for k in range(4))      # it grows every step
        said.clear()
        for k in (3, 2, 1, 0):
            s.key("N", shift=True)
            _until_grown(s)
            assert (s.step, s.model.grown.segments) == (k, segments[k])
            assert said[-1] == f"sprout: step {k} of 4: {segments[k]:,} segments"
        s.key("N", shift=True)                          # below the axiom: nothing to grow
        assert (s.step, s.step_target, s.reloader.busy) == (0, 0, False) and "axiom" in s.status
        s.key("N")
        s.key("N")                                      # asked before the first is in: the newest wins
        _until_grown(s)
        assert (s.step, s.model.grown.segments) == (2, segments[2])
        assert any(text == "growth: step 2 of 4, paused (N, Shift+N, G)" for text, _ in s.hud_lines())
        # the frame is plantgen render's at --iterations 2, and C's command says so
        frame = s.draw(*SIZE)
        args = shlex.split(s.render_command(s.save_camera()))
        assert args[args.index("--iterations") + 1] == "2"
        assert run_cli(*args[1:])[0] == 0
        assert np.array_equal(np.asarray(Image.open(args[args.index("-o") + 1])), frame.color)
        for _ in range(3):
            s.key("N")
            _until_grown(s)
        assert s.step == 4 and "last" in s.status         # stops at the grammar's iterations
    finally:
        s.release()


def test_growth_plays_from_the_axiom_to_the_grammars_iterations_and_stops(gl_ctx, tmp_path):
    s, _, _ = _sprout_session(gl_ctx, tmp_path, iterations=3)     # --iterations sets the last step
    try:
        assert s.steps_end == 3
        s.key("G")
        assert s.growing and s.step_target == 0
        seen = [s.step]
        deadline = time.monotonic() + 60
        while s.growing and time.monotonic() < deadline:
            s.tick(GROW_STEP_S / 2)     # the clock of the window's loop, two ticks a step
            if s.step != seen[-1]:
                seen.append(s.step)
            time.sleep(0.01)
        assert seen == [3, 0, 1, 2, 3] and not s.growing and s.status == "grown: step 3 of 3"
        s.key("N", shift=True)
        s.key("G")                      # from the step shown, not the axiom; G again stops
        assert s.growing and s.step_target == 2
        s.key("G")
        assert not s.growing and "stopped" in s.status
        _until_grown(s)
        assert s.step == 2
    finally:
        s.release()


def test_a_step_that_draws_nothing_keeps_the_last_plant_with_one_line(gl_ctx, tmp_path):
    s, _, said = _sprout_session(gl_ctx, tmp_path, SPROUT.replace('"!(0.12) F(1) A"', "A"), iterations=1)
    try:
        s.key("N", shift=True)          # the axiom "A" draws no segment
        _until_grown(s)
        assert s.step == 1 and s.step_target == 1
        assert s.error.startswith("step 0: ") and "nothing to render" in s.error
        assert sum("nothing to render" in line for line in said) == 1
    finally:
        s.release()


def test_a_scene_or_a_skeleton_says_once_that_steps_need_a_grammar(gl_ctx, tmp_path):
    (tmp_path / "sprout.yaml").write_text(SPROUT)
    scene = tmp_path / "garden.yaml"
    scene.write_text("name: garden\ninstances:\n  - grammar: sprout.yaml\n    position: [0, 0, 0]\n")
    skeleton = tmp_path / "sprout.npz"
    prepare_model(tmp_path / "sprout.yaml").grown.skeleton.save(skeleton)
    for path, kind in ((scene, "scene"), (skeleton, "skeleton")):
        options = ViewOptions(input=path, size=SIZE, watch=False, shots=tmp_path)
        said = []
        s = ViewerSession(gl_ctx, options, options.prepare(), say=said.append, warn=said.append)
        try:
            model = s.model
            for key, shift in (("N", False), ("N", True), ("G", False), ("N", False)):
                s.key(key, shift)
            assert s.model is model and s.step is None and not s.growing and not s.reloader.busy
            assert said == [f"growth steps need a grammar (this is a {kind})"] and s.status == said[0]
        finally:
            s.release()
