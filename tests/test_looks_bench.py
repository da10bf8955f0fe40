"""The looks benchmark (plantgen.benchmarks.looks): FLIP as it scores, the ladder's
matching, the glb's sun, and Blender's side on a tiny scene where Blender is installed."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from plantgen.benchmarks import looks
from plantgen.errors import PlantgenError
from plantgen.pipeline import grow_file, skin_model


def _picture(seed=0, h=48, w=64):
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    base = np.stack([x / w, y / h, 0.5 + 0.3 * np.sin(x / 5.0)], axis=-1)
    return np.clip(base + 0.02 * rng.standard_normal((h, w, 3)), 0, 1)


def test_flip_is_zero_for_identical_images_and_rises_with_noise():
    pytest.importorskip("flip_evaluator", reason="flip-evaluator (the bench and test extras) is not installed")
    image = _picture()
    same, error_map = looks.flip_error(image, image)
    assert same == pytest.approx(0.0, abs=1e-6) and error_map.shape == image.shape[:2]
    rng = np.random.default_rng(1)
    scores = [looks.flip_error(image, np.clip(image + s * rng.standard_normal(image.shape), 0, 1))[0]
              for s in (0.02, 0.1, 0.3)]
    assert 0 < scores[0] < scores[1] < scores[2] <= 1
    as_bytes = (image * 255).round().astype(np.uint8)
    assert looks.flip_error(as_bytes, as_bytes)[0] == pytest.approx(0.0, abs=1e-6)


def test_without_flip_evaluator_one_line_naming_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "flip_evaluator", None)
    with pytest.raises(PlantgenError, match=r"bench extra"):
        looks.flip_error(_picture(), _picture())


def test_without_blender_the_benchmark_stops_with_one_line(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(looks.shutil, "which", lambda name: None)
    assert looks.main(["--scenes", "saguaro", "--out", str(tmp_path), "--cache", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Blender" in err[0] and not (tmp_path / "looks.md").exists()


def test_samples_to_match_interpolates_in_log_samples_and_says_when_out_of_range():
    ladder = [{"samples": s, "flip": f, "sampling_s": 0.1 * s, "setup_s": 2.0}
              for s, f in ((1, 0.2), (4, 0.1), (16, 0.05))]
    middle = looks.samples_to_match(ladder, 0.1 * 2 ** -0.5)          # halfway in log FLIP between 4 and 16
    assert middle["samples"] == pytest.approx(8.0) and middle["bound"] == "" and middle["setup_s"] == 2.0
    assert looks.samples_to_match(ladder, 0.3)["bound"] == "<"
    assert looks.samples_to_match(ladder, 0.01)["bound"] == ">"


def test_coverage_overlap():
    a = np.zeros((4, 4), np.uint8)
    a[:2] = 255
    b = np.zeros_like(a)
    b[1:3] = 255
    assert looks.coverage_overlap(a, a) == 1.0
    assert looks.coverage_overlap(a, b) == pytest.approx(1 / 3)


def test_blender_timing_lines_split_set_up_from_sampling():
    log = ("Blender 3.4.1\nCYCLES-START a\n"
           "Fra:1 Mem:1M | Time:00:01.50 | Scene, ViewLayer | Updating Scene\n"
           "Fra:1 Mem:1M | Time:00:07.38 | Mem:89M | Scene, ViewLayer | Sample 0/16\n"
           "Fra:1 Mem:1M | Time:00:11.43 | Mem:89M | Scene, ViewLayer | Sample 16/16\n"
           'CYCLES {"name": "a", "import_s": 2.0, "render_s": 11.5}\n'
           "CYCLES-START b\nFra:1 Mem:1M | Time:01:02.00 | Mem:89M | Scene, ViewLayer | Sample 0/4\n"
           'CYCLES {"name": "b", "import_s": 2.0, "render_s": 63.0}\nCYCLES-START c\nError: out of memory\n')
    times = looks.blender_times(log)
    assert set(times) == {"a", "b"}
    assert times["a"]["setup_s"] == pytest.approx(7.38) and times["a"]["sampling_s"] == pytest.approx(11.5 - 7.38)
    assert times["b"]["setup_s"] == pytest.approx(62.0) and times["b"]["import_s"] == 2.0
    assert looks.blender_times("no such line") == {}


def test_the_reference_is_toned_as_plantgens_default_and_carries_its_sun_and_leaves(tmp_path):
    """Cycles' linear light goes through plantgen's display curve (the tone curve, then
    sRGB, as the default render's): below the knee it is sRGB, above it rolls off instead
    of clipping; without the tone, clip then c^(1/2.2). The job passes plantgen's default
    sun angle and leaf transmission, and leaves the ground matte."""
    from plantgen.settings import TONE_KNEE, LookSettings

    linear = np.array([[[0.0, 0.2, 0.5], [TONE_KNEE, 1.0, 1.5]]])
    toned = looks.display_image(linear, LookSettings(tone=True))
    srgb = np.rint(255 * (1.055 * np.array([0.2, 0.5]) ** (1 / 2.4) - 0.055))
    assert toned[0, 0].tolist() == [0, *srgb.astype(int).tolist()]
    assert toned[0, 1, 0] < toned[0, 1, 1] < toned[0, 1, 2] < 255               # rolled off, still rising
    plain = looks.display_image(linear, LookSettings(tone=False))
    assert plain[0, 1].tolist() == [int(np.rint(255 * TONE_KNEE ** (1 / 2.2))), 255, 255]
    assert np.array_equal(looks.display_image(linear), looks.display_image(linear, LookSettings.defaults()))
    camera = tmp_path / "camera.json"
    camera.write_text('{"eye": [0, 1, 5], "target": [0, 1, 0], "up": [0, 1, 0], "fov_y": 40}')
    glb, _ = looks.export_reference_glb("saguaro", tmp_path, 30, 200, 0)
    job = looks.cycles_job(glb, camera, (64, 48))
    defaults = LookSettings.defaults()
    assert job["light"]["angle"] == defaults.sun_angle and job["matte"] == ["Ground"]
    assert job["leaf_transmission"] == (defaults.transmission if defaults.translucency else 0.0)


def test_the_light_of_a_scene_glb_is_its_scenes_and_a_grammar_gets_the_model_light(tmp_path):
    from plantgen.geometry.stage import MODEL_LIGHT

    glb, _ = looks.export_reference_glb("well", tmp_path, 8, 200, 0)
    towards = np.asarray(looks.glb_light(glb))
    expected = np.array([0.5, 1.0, 0.35]) / np.linalg.norm([0.5, 1.0, 0.35])   # well.yaml's light, reversed
    assert towards == pytest.approx(expected, abs=1e-5)
    (tmp_path / "saguaro").mkdir()
    glb, _ = looks.export_reference_glb("saguaro", tmp_path / "saguaro", 30, 200, 0)
    assert looks.glb_light(glb) == pytest.approx(list(MODEL_LIGHT.towards()))


def test_cycles_of_a_tiny_scene_covers_what_plantgen_covers(blender, tmp_path):
    """The saguaro (a grammar: its file has no camera or sun, the job gives them) at 64x48
    and 4 samples: Blender's transparent film covers the pixels plantgen's --background
    none covers, so the two are framed alike."""
    camera, mask, framed = looks.frame_scene("saguaro", tmp_path, (64, 48))
    assert framed.frusta == len(skin_model(grow_file("saguaro"))) and framed.renderer   # its smooth elbows
    glb, level = looks.export_reference_glb("saguaro", tmp_path, framed.frusta, 20_000, 6)
    assert level == 2
    job, mask_still = looks.cycles_job(glb, camera, (64, 48)), looks.still(4, transparent=True, kind="mask")
    colour = looks.still(16)
    done = looks.render_cycles(job, [mask_still, colour], tmp_path / "cache", blender, timeout=600)
    result = done[mask_still["name"]]
    from PIL import Image

    # the colour still: Cycles' linear light toned as plantgen's default, and its ground
    # (right of the plant, clear of its shadow) plantgen's own sand within a few levels
    linear = np.load(done[colour["name"]]["image"].with_suffix(".npy"))
    shown = np.asarray(Image.open(done[colour["name"]]["image"]).convert("RGB"))
    assert linear.shape == (48, 64, 4) and np.array_equal(shown, looks.display_image(linear[..., :3]))
    plantgen = np.asarray(Image.open(looks.render_variant("saguaro", "default", 0, camera, tmp_path, 1).image)
                          .convert("RGB")).astype(float)
    sand = np.s_[29:36, 48:64]
    assert np.abs(shown[sand].astype(float).mean(axis=(0, 1)) - plantgen[sand].mean(axis=(0, 1))).max() < 3.0

    theirs = np.asarray(Image.open(result["image"]).convert("RGBA"))[..., 3]
    ours = np.asarray(Image.open(mask).convert("RGBA"))[..., 3]
    assert theirs.shape == ours.shape == (48, 64)
    assert (ours > 127).mean() > 0.03 and looks.coverage_overlap(ours, theirs) > 0.8
    assert result["sampling_s"] >= 0 and result["setup_s"] >= 0
    again = looks.render_cycles(job, [mask_still], tmp_path / "cache", "/nonexistent/blender")   # cached
    assert again[mask_still["name"]]["image"] == result["image"]


def test_a_failing_blender_is_one_line(tmp_path):
    glb = tmp_path / "x.glb"
    glb.write_bytes(b"not a glb")
    job = {"file": str(glb), "size": [8, 8]}
    with pytest.raises(PlantgenError, match="Blender could not render x.glb"):
        looks.render_cycles(job, [looks.still(1)], tmp_path / "cache", "/bin/false")


def test_the_table_gives_each_variant_and_rung_and_what_cycles_needs(tmp_path):
    ladder = [{"samples": s, "flip": f, "flip_model": 3 * f, "sampling_s": 0.5 * s, "setup_s": 3.0}
              for s, f in ((1, 0.2), (4, 0.1))]
    runs = [looks.PlantgenRun(options, tmp_path / "x.png", frame_ms=10.0, shadow_ms=90.0, flip=flip,
                              flip_model=3 * flip, extra=looks.samples_to_match(ladder, flip),
                              extra_model=looks.samples_to_match(ladder, 3 * flip, "flip_model"))
            for options, flip in (("default", 0.15), ("--effects relief,shadows", 0.05))]
    result = {"scene": "well", "renderer": "llvmpipe (LLVM 15.0.6, 256 bits)", "frusta": 8, "subdiv": 6,
              "overlap": 0.99, "covered": 0.25, "reference": {}, "ladder": ladder, "runs": runs}
    settings = looks.Settings(size=(64, 48), reference_samples=16, samples=(1, 4),
                              variants=("default", "--effects relief,shadows"))
    text = looks.looks_table([result], settings)
    assert "llvmpipe (LLVM 15.0.6, 256 bits)" in text and "16 samples" in text
    assert ("| well | 0.150 (10 + 90 ms) | 0.050 (10 + 90 ms) | 0.200 (0.5 s) | 0.100 (2.0 s) | 3.0 | 0.990 | 6 |"
            in text)
    match = next(line for line in text.splitlines() if line.startswith("| well | default |"))
    # 0.15 lies 0.415 of the way from 0.2 to 0.1 in log FLIP: 4^0.415 = 1.8 samples, 0.9 s, 89x the 10 ms frame
    assert match.endswith("| 1.8 | 0.9 | 89× | 8.9× |")
    assert "| well | `--effects relief,shadows` | 0.050 | 10 + 90 | >4 | >2.0 | >200× | >20× |" in text
    assert "| well | 25 % | 0.450 | 0.150 | 0.600 | 0.300 |" in text          # over the covered pixels
    assert "| well | default | 0.450 | 1.8 | 0.9 | 89× | 8.9× |" in text


def test_a_groundless_reference_has_no_disc_under_a_single_plant_and_a_key_and_folder_of_its_own(tmp_path):
    """--reference-ground none: a single plant's export has no ground disc (the baseline's
    scene, for renders with --ground none); auto (the default) has it. The two files are
    cached apart (the glb is in the key) and exported in folders apart."""
    camera = tmp_path / "camera.json"
    camera.write_text('{"eye": [0, 1, 5], "target": [0, 1, 0], "up": [0, 1, 0], "fov_y": 40}')
    names, keys = {}, {}
    for ground in looks.REFERENCE_GROUNDS:
        (tmp_path / ground).mkdir()
        glb, _ = looks.export_reference_glb("saguaro", tmp_path / ground, 30, 200, 0, ground)
        document = looks.glb_document(glb)
        names[ground] = {item.get("name", "") for part in ("nodes", "meshes") for item in document.get(part, [])}
        keys[ground] = looks.job_key(looks.cycles_job(glb, camera, (64, 48)))
    assert "Ground" in names["auto"] and not any("Ground" in name for name in names["none"])
    assert keys["auto"] != keys["none"]
    args = looks.parse_arguments(["--reference-ground", "none", "--size", "64x48"])
    assert args.reference_ground == "none" and looks.parse_arguments([]).reference_ground == "auto"
    folders = {ground: looks.work_folder(looks.Settings(size=(64, 48), reference_ground=ground, cache=tmp_path))
               for ground in looks.REFERENCE_GROUNDS}
    assert folders["auto"] == tmp_path / "plantgen" / "64x48" and folders["none"] != folders["auto"]
    with pytest.raises(SystemExit):
        looks.parse_arguments(["--reference-ground", "disc"])


def test_a_variant_is_judged_by_the_reference_toned_with_its_own_display_curve(tmp_path):
    """--reference-tone variant: each variant's reference and ladder are Cycles' linear
    light toned with that variant's display curve (--no-tone: clip and 2.2; an --effects
    list without tone: the same; --tone-curve, --exposure), each rung scored anew."""
    from plantgen.settings import LookSettings

    assert looks.variant_looks("default") == looks.variant_looks("--ground none --shadows") == LookSettings.defaults()
    for options in ("--no-tone --no-translucency --ground none --aa none", "--effects shadows"):
        assert not looks.variant_looks(options).tone
    aces = looks.variant_looks("--effects shadows,tone --tone-curve aces --exposure 2")
    assert aces.tone and aces.tone_curve == "aces" and aces.exposure == 2.0
    assert looks.display_name(aces) == "aces at exposure 2" and looks.display_name(LookSettings()) == "clip, 2.2"
    rng = np.random.default_rng(3)
    linear = np.dstack([1.4 * _picture(), np.ones((48, 64))]).astype(np.float32)   # past 1: the curves part
    noisy = np.clip(linear + 0.05 * rng.standard_normal(linear.shape), 0, None).astype(np.float32)
    np.save(tmp_path / "reference.npy", linear)
    np.save(tmp_path / "rung.npy", noisy)
    reference = {"linear": tmp_path / "reference.npy"}
    ladder = [{"samples": 1, "linear": tmp_path / "reference.npy"}, {"samples": 4, "linear": tmp_path / "rung.npy"}]
    covered = np.zeros((48, 64), bool)
    covered[10:30, 20:40] = True
    plain, toned = LookSettings(), LookSettings.defaults()
    truth, rungs = looks.toned_judge(plain, reference, ladder, covered)
    assert np.array_equal(truth, looks.display_image(linear[..., :3], plain))
    assert not np.array_equal(truth, looks.display_image(linear[..., :3], toned))
    assert rungs[0]["flip"] == rungs[0]["flip_model"] == 0.0 and rungs[1]["flip"] > 0.0
    assert "flip" not in ladder[1]                                          # the ladder itself untouched
    _, default_rungs = looks.toned_judge(toned, reference, ladder, covered)
    expected = looks.scores(looks.display_image(linear[..., :3]), looks.display_image(noisy[..., :3]), covered)
    assert (default_rungs[1]["flip"], default_rungs[1]["flip_model"]) == expected != (rungs[1]["flip"],
                                                                                     rungs[1]["flip_model"])
    assert looks.parse_arguments(["--reference-tone", "variant"]).reference_tone == "variant"
    assert looks.parse_arguments([]).reference_tone == "default"


def test_the_table_says_when_the_reference_has_no_ground_and_how_each_variant_was_judged(tmp_path):
    ladder = [{"samples": 1, "flip": 0.2, "flip_model": 0.6, "sampling_s": 0.5, "setup_s": 3.0}]
    runs = [looks.PlantgenRun(options, tmp_path / "x.png", frame_ms=10.0, flip=0.1, flip_model=0.3, tone=tone,
                              extra=looks.samples_to_match(ladder, 0.1),
                              extra_model=looks.samples_to_match(ladder, 0.3, "flip_model"))
            for options, tone in (("--ground none", "filmic"), ("--no-tone --ground none", "clip, 2.2"))]
    result = {"scene": "pine", "renderer": "llvmpipe", "frusta": 8, "subdiv": 1, "overlap": 0.8, "covered": 0.1,
              "reference": {}, "ladder": ladder, "runs": runs}
    variants = tuple(run.options for run in runs)
    plain = looks.looks_table([result], looks.Settings(size=(64, 48), samples=(1,), variants=variants))
    assert "without a ground" not in plain and "own display curve" not in plain
    settings = looks.Settings(size=(64, 48), samples=(1,), variants=variants, reference_ground="none",
                              reference_tone="variant")
    text = looks.looks_table([result], settings)
    assert "relief in the vertices, without a ground under a single plant;" in text
    assert "(`--ground none`: filmic; `--no-tone --ground none`: clip, 2.2)" in text
    assert '"reference_ground": "none"' in looks.results_json([result], settings)


def test_the_picture_shows_the_reference_in_each_display_curve_a_variant_was_judged_by(tmp_path):
    from PIL import Image

    from plantgen.settings import LookSettings

    linear = np.dstack([1.4 * _picture(), np.ones((48, 64))]).astype(np.float32)
    np.save(tmp_path / "reference.npy", linear)
    Image.fromarray(looks.display_image(linear[..., :3])).save(tmp_path / "reference.png")
    runs = [looks.PlantgenRun(options, tmp_path / "x.png", tone=looks.display_name(looks.variant_looks(options)))
            for options in ("--ground none", "--shadows", "--no-tone --ground none")]
    result = {"reference": {"image": tmp_path / "reference.png", "linear": tmp_path / "reference.npy"}, "runs": runs}
    one = looks.reference_panels(result, looks.Settings(reference_samples=16))
    assert [label for _, label in one] == ["Cycles 16 spp"]
    panels = looks.reference_panels(result, looks.Settings(reference_samples=16, reference_tone="variant"))
    assert [label for _, label in panels] == ["Cycles 16 spp (filmic)", "Cycles 16 spp (clip, 2.2)"]
    assert np.array_equal(panels[0][0], one[0][0])
    assert np.array_equal(panels[1][0], looks.display_image(linear[..., :3], LookSettings()))
