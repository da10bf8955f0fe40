"""What accuracy costs in time, for light: plantgen's render of a scene scored against a
converged path-traced reference, Blender's Cycles on the CPU rendering plantgen's own glTF
export of the same scene, with NVIDIA's FLIP (``flip-evaluator``, LDR, the mean).

For each scene: plantgen frames it once (``--camera-out``, ``--background none`` for its
coverage mask); ``plantgen export --relief`` writes it with the relief in the vertices, at
the finest subdivision under a triangle budget (the reference must carry the geometry the
image it judges shows, and the ground's mottle and fade); Blender renders that file from
the same camera, sun and sky (:mod:`plantgen.benchmarks.cycles_reference`: the ground
Lambertian, the leaves translucent as plantgen's default leaves are), in linear light,
which :func:`display_image` tones with plantgen's default display curve: the reference at ``--reference-samples``,
a ladder of ``--samples`` (another seed) and a transparent coverage mask. plantgen renders
each ``--variants`` entry (``plantgen render`` options: ``default`` for none), timed as the
median of warm frames. Each image is scored against the reference; the ladder's scores
give how many samples, and how many seconds, Cycles needs to match each.

Cycles' images are cached outside the repository (``--cache``, default
``~/.cache/plantgen/looks``), keyed by a hash of the glb, the job and the Blender script:
a re-run renders only what changed. Run::

    python -m plantgen.benchmarks.looks --out gallery/bench/llvmpipe \\
        --variants "default;--effects shadows;--effects relief,shadows"

It writes ``looks.md`` (the table), ``looks.json`` (every number) and ``looks.png`` (per
scene: each variant beside the reference); ``--name`` sets the files' name.
``--reference-ground none`` exports a single plant without its ground disc (the baseline's
scene, for variants with ``--ground none``); ``--reference-tone variant`` judges each variant
by the reference toned with its own display curve (``--no-tone``: clipped, c^(1/2.2)) instead
of plantgen's default one. It needs Blender (``blender`` on the PATH, or ``--blender``) and
the ``bench`` extra (flip-evaluator).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import math
import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import PlantgenError, missing_extra
from ..geometry.stage import MODEL_LIGHT
from ..gl.material_uniforms import AMBIENT_COLOR, LIGHT_COLOR, SKY
from ..gl.supersample import srgb_encode, tone_curve
from ..settings import EffectSettings, LookSettings
from .arguments import image_size, report
from .side_by_side import labelled_panels

__all__ = ["SCENES", "BLENDER_SCRIPT", "flip_error", "coverage_overlap", "cycles_job", "still", "render_cycles",
           "display_image",
           "samples_to_match", "main"]

#: The scenes of issue 43: four grammars, the well, and a cut of the forest (shipped here).
SCENES = ("saguaro", "broadleaf", "pine", "coconut", "well", "forest_cut")
#: The Blender-side script (run by Blender's own Python; imports nothing from plantgen).
BLENDER_SCRIPT = Path(__file__).with_name("cycles_reference.py")
FOREST_CUT = Path(__file__).with_name("looks_forest_cut.yaml")
DEFAULT_VARIANTS = "default;--effects shadows;--effects relief,shadows"
DEFAULT_CACHE = Path("~/.cache/plantgen/looks")
#: Triangles a frustum gets at subdivision level 0 (16·4^m at level m).
FRUSTUM_TRIANGLES = 16


def model_input(scene: str) -> str:
    """What ``plantgen render`` and ``export`` take for ``scene``: a shipped name, or the
    forest's cut shipped beside this module."""
    return str(FOREST_CUT) if scene == "forest_cut" else scene


# ----------------------------------------------------------------------------- the metric
def flip_error(reference: np.ndarray, test: np.ndarray, ppd: float | None = None) -> tuple[float, np.ndarray]:
    """Mean FLIP of ``test`` against ``reference`` ((h, w, 3) uint8 sRGB, or float in
    [0, 1]), LDR, and the (h, w) error map. ``ppd``: pixels per degree (FLIP's default 67).
    Without flip-evaluator: a PlantgenError naming the extra."""
    try:
        import flip_evaluator
    except ImportError as exc:
        raise PlantgenError(missing_extra("the looks benchmark (FLIP)", "bench")) from exc
    ref, img = (np.ascontiguousarray(_unit(a)[..., :3], dtype=np.float32) for a in (reference, test))
    if ref.shape != img.shape:
        raise PlantgenError(f"images differ in size: {ref.shape[:2]} and {img.shape[:2]}")
    parameters = {} if ppd is None else {"ppd": float(ppd)}
    error_map, mean, _ = flip_evaluator.evaluate(ref, img, "LDR", inputsRGB=True, applyMagma=False,
                                                 computeMeanError=True, parameters=parameters)
    return float(mean), np.asarray(error_map).reshape(ref.shape[:2])


def _unit(image: np.ndarray) -> np.ndarray:
    image = np.asarray(image)
    return image / 255.0 if image.dtype == np.uint8 else np.clip(image, 0.0, 1.0)


def coverage_overlap(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two (h, w) coverage masks (alpha > half): 1 when the two
    renderers cover the same pixels, lower when the framing or the geometry differs."""
    a, b = np.asarray(a) > 127, np.asarray(b) > 127
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def samples_to_match(ladder: list[dict], target: float, score: str = "flip") -> dict:
    """Where Cycles' ladder (``samples``, ``score``, ``sampling_s``, ``setup_s`` each)
    reaches the score ``target``: samples and sampling seconds interpolated in log(samples)
    between the two rungs it falls between; ``bound`` '<' below the first rung, '>' past
    the last."""
    rungs = sorted(ladder, key=lambda r: r["samples"])
    if not rungs:
        return {"samples": None, "sampling_s": None, "setup_s": None, "bound": ""}
    setup = float(np.median([r["setup_s"] for r in rungs]))
    if target >= rungs[0][score]:
        return {"samples": rungs[0]["samples"], "sampling_s": rungs[0]["sampling_s"], "setup_s": setup, "bound": "<"}
    for lo, hi in zip(rungs, rungs[1:], strict=False):
        if hi[score] <= target:
            t = (math.log(lo[score]) - math.log(target)) / max(math.log(lo[score]) - math.log(hi[score]), 1e-12)
            samples, seconds = (_log_between(lo[key], hi[key], t) for key in ("samples", "sampling_s"))
            return {"samples": samples, "sampling_s": seconds, "setup_s": setup, "bound": ""}
    last = rungs[-1]
    return {"samples": last["samples"], "sampling_s": last["sampling_s"], "setup_s": setup, "bound": ">"}


def _log_between(a: float, b: float, t: float) -> float:
    """The point ``t`` of the way from ``a`` to ``b`` on a log scale."""
    return math.exp((1 - t) * math.log(max(a, 1e-3)) + t * math.log(max(b, 1e-3)))


# ----------------------------------------------------------------------------- plantgen's side
@dataclass
class PlantgenRun:
    """One ``plantgen render``: its image, what it printed that the table needs."""

    options: str
    image: Path
    renderer: str = ""
    frusta: int = 0
    frame_ms: float = float("nan")
    shadow_ms: float = 0.0
    flip: float = float("nan")
    flip_model: float = float("nan")
    tone: str = ""                                       # the display curve its reference got
    extra: dict = field(default_factory=dict)            # Cycles matching the FLIP
    extra_model: dict = field(default_factory=dict)      # Cycles matching the FLIP on the model


def plantgen_command(*args: str) -> list[str]:
    """The ``plantgen`` command line run by this interpreter (its package, its env)."""
    return [sys.executable, "-m", "plantgen", *args]


def run_plantgen(args: list[str], what: str, timeout: float = 1800) -> str:
    """Run ``plantgen ARGS``; its stdout. A failure is a PlantgenError of its last line."""
    done = subprocess.run(plantgen_command(*args), capture_output=True, text=True, timeout=timeout)
    if done.returncode != 0:
        tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
        raise PlantgenError(f"plantgen could not {what}: {tail[0]}")
    return done.stdout


def parse_render(text: str, run: PlantgenRun) -> PlantgenRun:
    """Fill ``run`` from ``plantgen render --verbose``'s report: the GL renderer, the frusta, the
    frame's milliseconds (the median with --time-frames) and the shadow map's, drawn once."""
    if m := re.search(r"GL renderer: (.+)", text):
        run.renderer = m.group(1).strip()
    if m := re.search(r"segments: [\d,]+ -> ([\d,]+) frusta", text):
        run.frusta = int(m.group(1).replace(",", ""))
    if m := re.search(r"frame: ([\d.]+) ms", text):
        run.frame_ms = float(m.group(1))
    if m := re.search(r"shadow map: drawn once \(([\d.]+) ms\)", text):
        run.shadow_ms = float(m.group(1))
    return run


def frame_scene(scene: str, work: Path, size) -> tuple[Path, Path, PlantgenRun]:
    """plantgen's camera of ``scene`` at ``size`` (--camera-out) and its coverage mask
    (the default render with --background none): (camera.json, mask.png, the run)."""
    camera, mask = work / "camera.json", work / "mask.png"
    text = run_plantgen(["render", model_input(scene), "-o", str(mask), "--size", f"{size[0]}x{size[1]}",
                         "--background", "none", "--camera-out", str(camera), "--verbose"], f"frame {scene}")
    return camera, mask, parse_render(text, PlantgenRun("mask", mask))


def render_variant(scene: str, options: str, k: int, camera: Path, work: Path, frames: int) -> PlantgenRun:
    """plantgen's image of ``scene`` with render ``options`` ('default': none), from
    ``camera``, timed over ``frames`` warm draws."""
    out = work / f"plantgen_{k}.png"
    extra = [] if options.strip() in ("", "default") else shlex.split(options)
    text = run_plantgen(["render", model_input(scene), "-o", str(out), "--camera", str(camera),
                         "--time-frames", str(frames), "--verbose", *extra], f"render {scene} {options}")
    return parse_render(text, PlantgenRun(options, out))


def export_reference_glb(scene: str, work: Path, frusta: int, max_triangles: int, max_subdiv: int,
                         ground: str = "auto") -> tuple[Path, int]:
    """``scene`` exported with the relief in the vertices at the finest level m (16·4^m
    triangles a frustum) whose triangles stay under ``max_triangles``, and its ground:
    ``ground`` ``auto`` gives a grammar the disc the render draws, ``none`` none (a scene
    writes its own ground either way): (the glb, m)."""
    level = int(math.floor(math.log(max(max_triangles / (FRUSTUM_TRIANGLES * max(frusta, 1)), 1.0), 4)))
    level = max(0, min(max_subdiv, level))
    glb = work / "reference.glb"
    # --ground: a single plant's file carries the ground disc plantgen's render draws under it
    disc = ["--ground"] if ground == "auto" else []
    run_plantgen(["export", model_input(scene), "-o", str(glb), "--relief", "--subdiv", str(level), "--no-sway",
                  *disc], f"export {scene}")
    return glb, level


def glb_document(glb: Path) -> dict:
    """The JSON chunk of a glb file (its first chunk: the length at bytes 12-16, the text
    from byte 20)."""
    data = Path(glb).read_bytes()
    return json.loads(data[20:20 + int.from_bytes(data[12:16], "little")])


def glb_light(glb: Path) -> list[float]:
    """The unit direction towards the sun of a plantgen glb (y up): its
    ``KHR_lights_punctual`` node's, or the model light plantgen gives a grammar (whose file
    has none). The intensity is left out: plantgen's renderer draws every light at 1."""
    document = glb_document(glb)
    for node in document.get("nodes", []):
        if "KHR_lights_punctual" in node.get("extensions", {}):
            x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
            # the light shines along its node's -z: towards it is the rotated +z
            towards = [2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)]
            return towards
    return [float(v) for v in MODEL_LIGHT.towards()]


# ----------------------------------------------------------------------------- Cycles' side
def cycles_job(glb: Path, camera: Path, size, threads: int = 0) -> dict:
    """The job :mod:`~plantgen.benchmarks.cycles_reference` reads, less its ``renders``:
    the file, plantgen's camera, sun (its colour, and the angular diameter of plantgen's
    default sun), ambient and sky, the leaves' transmission where plantgen's default
    leaves are translucent (0 where not), the image's size, and what a coverage mask
    leaves out (``mask_hides``: a single plant's ground disc, which ``plantgen render
    --background none`` does not draw; a scene's ground it does)."""
    view = json.loads(Path(camera).read_text())
    scene = "cameras" in glb_document(glb)
    looks = LookSettings.defaults()
    return {"file": str(glb), "size": [int(size[0]), int(size[1])], "threads": int(threads),
            "mask_hides": [] if scene else ["Ground"], "matte": ["Ground"],
            "camera": {key: view[key] for key in ("eye", "target", "up", "fov_y")},
            "light": {"towards": glb_light(glb), "color": list(LIGHT_COLOR), "angle": float(looks.sun_angle)},
            "leaf_transmission": float(looks.transmission) if looks.translucency else 0.0,
            "ambient": list(AMBIENT_COLOR),
            "sky": {"zenith": list(SKY["sky_zenith"]), "horizon": list(SKY["sky_horizon"]),
                    "ground": list(SKY["ground_tint"])}}


def still(samples: int, seed: int = 0, transparent: bool = False, kind: str = "cycles") -> dict:
    """One render of a job: its samples, seed and film; its name says all three."""
    return {"name": f"{kind}_{samples}spp_seed{seed}{'_alpha' if transparent else ''}", "samples": int(samples),
            "seed": int(seed), "transparent": bool(transparent)}


def job_key(job: dict) -> str:
    """The cache folder of a job: a hash of the glb's bytes, the job (less its paths, its
    threads and its renders, which name their own files) and the Blender script, so a
    changed scene, export, view or script renders anew."""
    digest = hashlib.sha256(Path(job["file"]).read_bytes())
    settings = {k: v for k, v in job.items() if k not in ("file", "threads", "renders")}
    digest.update(json.dumps(settings, sort_keys=True).encode())
    digest.update(BLENDER_SCRIPT.read_bytes())
    return digest.hexdigest()[:20]


def _clock(match) -> float:
    return int(match.group(1)) * 60 + float(match.group(2))


def blender_times(log: str) -> dict[str, dict]:
    """Seconds of each render, by name, from Blender's output: ``import_s`` (the script's
    import and scene build, once for all), ``setup_s`` (the render before its first
    sample: kernels, BVH, images, the ``Sample 0/N`` status line's clock) and
    ``sampling_s`` (the rest of the render)."""
    times = {}
    for part in log.split("CYCLES-START ")[1:]:
        done = re.search(r"^CYCLES (\{.*\})$", part, re.MULTILINE)
        if not done:
            continue
        record = json.loads(done.group(1))
        first = re.search(r"Time:(\d+):(\d+\.\d+) \|[^\n]*\| Sample 0/", part)
        setup = min(_clock(first), record["render_s"]) if first else 0.0
        times[record["name"]] = {"import_s": record["import_s"], "setup_s": setup,
                                 "sampling_s": record["render_s"] - setup}
    return times


def render_cycles(job: dict, stills: list[dict], cache: Path, blender: str, timeout: float = 7200) -> dict[str, dict]:
    """Each of ``stills`` of ``job``, from ``cache`` or rendered by one Blender run (one
    import): {name: {"image": Path, "samples", seconds...}}. Blender's output goes to a log
    beside the images; a failure is a one-line PlantgenError naming it."""
    folder = cache / job_key(job)
    todo = [s for s in stills if not all((folder / f"{s['name']}{ext}").exists() for ext in (".npy", ".json"))]
    if todo:
        folder.mkdir(parents=True, exist_ok=True)
        renders = [{**s, "out": str(folder / s["name"])} for s in todo]
        spec = folder / f"job_{todo[0]['name']}.json"
        spec.write_text(json.dumps({**job, "renders": renders}, indent=1))
        log = folder / f"job_{todo[0]['name']}.log"
        command = [blender, "--background", "--factory-startup", "--python", str(BLENDER_SCRIPT), "--", str(spec)]
        with open(log, "w") as out:
            done = subprocess.run(command, stdout=out, stderr=subprocess.STDOUT, timeout=timeout)
        times = blender_times(log.read_text(errors="replace"))
        for s in todo:
            if s["name"] in times and (folder / f"{s['name']}.npy").exists():
                (folder / f"{s['name']}.json").write_text(json.dumps(times[s["name"]]))
        missing = [s["name"] for s in todo if s["name"] not in times]
        if done.returncode != 0 or missing:
            what = ", ".join(missing) or f"exit status {done.returncode}"
            raise PlantgenError(f"Blender could not render {Path(job['file']).name} ({what}): see {log}")
    for s in stills:                   # the display image, toned as plantgen's default is
        linear = np.load(folder / f"{s['name']}.npy")
        rgb = display_image(linear[..., :3])
        image = np.dstack([rgb, np.rint(255 * np.clip(linear[..., 3], 0, 1))]) if s["transparent"] else rgb
        Image.fromarray(image.astype(np.uint8)).save(folder / f"{s['name']}.png")
    return {s["name"]: {"image": folder / f"{s['name']}.png", "linear": folder / f"{s['name']}.npy",
                        "samples": s["samples"], **json.loads((folder / f"{s['name']}.json").read_text())}
            for s in stills}


def display_image(linear: np.ndarray, looks: LookSettings | None = None) -> np.ndarray:
    """(h, w, 3) uint8: Cycles' linear light as plantgen's renderer writes its own, with
    the display curve of ``looks`` (default: plantgen's default looks): the tone curve
    (``tone_curve`` after ``exposure``), then the sRGB transfer curve, where the tone is
    on; else clipped, then c^(1/2.2)."""
    looks = LookSettings.defaults() if looks is None else looks
    linear = np.asarray(linear, dtype=np.float64)
    if looks.tone:
        shown = srgb_encode(tone_curve(linear, looks.exposure, looks.tone_curve))
    else:
        shown = np.clip(linear, 0.0, 1.0) ** (1 / 2.2)
    return np.rint(255 * np.clip(shown, 0.0, 1.0)).astype(np.uint8)


def variant_looks(options: str) -> LookSettings:
    """The display curve of a render with ``options`` (``plantgen render``'s: ``default``
    for none): the tone curve on unless ``--no-tone`` or an ``--effects`` list without
    ``tone`` turns it off, ``--tone-curve``, ``--exposure``; the rest of the looks the
    defaults'. Other options are left alone."""
    parser = argparse.ArgumentParser(add_help=False, allow_abbrev=False)
    parser.add_argument("--effects")
    parser.add_argument("--tone", dest="tone", action="store_const", const=True, default=None)
    parser.add_argument("--no-tone", dest="tone", action="store_const", const=False)
    parser.add_argument("--tone-curve", default=LookSettings.tone_curve)
    parser.add_argument("--exposure", type=float, default=LookSettings.exposure)
    words = [] if options.strip() in ("", "default") else shlex.split(options)
    known, _ = parser.parse_known_args(words)
    effects = EffectSettings(effects=known.effects, tone=known.tone).resolve()
    return replace(LookSettings.defaults(), tone="tone" in effects, tone_curve=known.tone_curve,
                   exposure=known.exposure)


def find_blender(blender: str | None) -> str:
    """The Blender executable: ``blender`` given, else on the PATH; a PlantgenError without."""
    found = shutil.which(blender or "blender")
    if found is None:
        raise PlantgenError(f"Blender is not installed ({blender or 'blender'} is not on the PATH; "
                            "apt install blender): the looks benchmark needs its Cycles")
    return found


# ----------------------------------------------------------------------------- one scene
#: ``--reference-ground``: the ground plantgen's default render draws, or none under a single plant.
REFERENCE_GROUNDS = ("auto", "none")
#: ``--reference-tone``: the reference toned with plantgen's default display curve for every
#: variant, or with each variant's own.
REFERENCE_TONES = ("default", "variant")


@dataclass
class Settings:
    """The benchmark's knobs, as the command line gives them."""

    size: tuple = (512, 384)
    reference_samples: int = 1024
    samples: tuple = (1, 4, 16, 64, 256)
    variants: tuple = ("default",)
    frames: int = 5
    max_triangles: int = 1_000_000
    max_subdiv: int = 6
    reference_ground: str = "auto"
    reference_tone: str = "default"
    threads: int = 0
    cache: Path = DEFAULT_CACHE
    blender: str = "blender"
    say: object = functools.partial(print, flush=True)


def work_folder(settings: Settings) -> Path:
    """Where plantgen's images, camera and export of each scene go (a folder a scene): by
    image size, and apart for a reference without ground, whose export differs."""
    name = f"{settings.size[0]}x{settings.size[1]}"
    if settings.reference_ground != "auto":
        name += f"_reference-ground-{settings.reference_ground}"
    return settings.cache.expanduser() / "plantgen" / name


def cycles_renders(glb: Path, camera: Path, settings: Settings) -> tuple[dict, dict, list[dict]]:
    """Blender's coverage mask (transparent film, 4 samples), the reference (seed 0) and
    the ladder (seed 1, so no rung is the reference itself), each cached; one Blender run
    makes those missing."""
    job = cycles_job(glb, camera, settings.size, settings.threads)
    mask, reference = still(4, transparent=True, kind="mask"), still(settings.reference_samples, kind="reference")
    ladder = [still(s, seed=1) for s in settings.samples]
    done = render_cycles(job, [mask, reference, *ladder], settings.cache.expanduser(), settings.blender)
    for s in (mask, reference, *ladder):
        r = done[s["name"]]
        settings.say(f"  Cycles {s['name']}: set-up {r['setup_s']:.1f} s, sampling {r['sampling_s']:.1f} s")
    return done[mask["name"]], done[reference["name"]], [done[s["name"]] for s in ladder]


def _rgb(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"))


def _alpha(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGBA"))[..., 3]


def scores(truth: np.ndarray, image: Path | np.ndarray, covered: np.ndarray) -> tuple[float, float]:
    """Mean FLIP of ``image`` (a file or an sRGB array) against ``truth``: over the whole
    image, and over the ``covered`` pixels (either renderer's model: the sky, alike in
    both, left out)."""
    mean, error_map = flip_error(truth, image if isinstance(image, np.ndarray) else _rgb(image))
    return mean, float(error_map[covered].mean()) if covered.any() else mean


def toned_judge(looks: LookSettings, reference: dict, ladder: list[dict], covered: np.ndarray) -> tuple:
    """The reference and the ladder's scores as a render with ``looks`` is judged
    (``--reference-tone variant``): Cycles' linear light toned with that render's display
    curve, each rung scored against the reference toned alike. (truth, ladder)."""
    def toned(still: dict) -> np.ndarray:
        return display_image(np.load(still["linear"])[..., :3], looks)
    truth = toned(reference)
    rungs = []
    for rung in ladder:
        flip, flip_model = scores(truth, toned(rung), covered)
        rungs.append({**rung, "flip": flip, "flip_model": flip_model})
    return truth, rungs


def display_name(looks: LookSettings) -> str:
    """The display curve of ``looks`` in words: the tone curve (and its exposure), or 'clip, 2.2'."""
    if not looks.tone:
        return "clip, 2.2"
    return looks.tone_curve + ("" if looks.exposure == 1 else f" at exposure {looks.exposure:g}")


def measure_scene(scene: str, settings: Settings, work: Path) -> dict:
    """Everything the table says of ``scene``: plantgen's variants (time, FLIP), Cycles'
    ladder (time, FLIP), the samples and seconds Cycles needs to match each variant, the
    coverage masks' overlap, the export's level."""
    work.mkdir(parents=True, exist_ok=True)
    settings.say(f"{scene}: framing, exporting")
    camera, mask, framed = frame_scene(scene, work, settings.size)
    glb, level = export_reference_glb(scene, work, framed.frusta, settings.max_triangles, settings.max_subdiv,
                                      settings.reference_ground)
    cycles_mask, reference, ladder = cycles_renders(glb, camera, settings)
    truth = _rgb(reference["image"])
    ours, theirs = _alpha(mask), _alpha(cycles_mask["image"])
    covered = (ours > 127) | (theirs > 127)
    for rung in ladder:
        rung["flip"], rung["flip_model"] = scores(truth, rung["image"], covered)
    runs, judges = [], {}
    for k, options in enumerate(settings.variants):
        run = render_variant(scene, options, k, camera, work, settings.frames)
        looks = variant_looks(options) if settings.reference_tone == "variant" else LookSettings.defaults()
        run.tone = display_name(looks)
        if run.tone not in judges:
            judges[run.tone] = toned_judge(looks, reference, ladder, covered)
        run_truth, run_ladder = judges[run.tone]
        run.flip, run.flip_model = scores(run_truth, run.image, covered)
        run.extra = samples_to_match(run_ladder, run.flip)
        run.extra_model = samples_to_match(run_ladder, run.flip_model, "flip_model")
        settings.say(f"  plantgen {options}: FLIP {run.flip:.3f} ({run.flip_model:.3f} on the model), "
                     f"frame {run.frame_ms:.1f} ms + shadow map {run.shadow_ms:.1f} ms")
        runs.append(run)
    return {"scene": scene, "renderer": framed.renderer, "frusta": framed.frusta, "subdiv": level,
            "overlap": coverage_overlap(ours, theirs), "covered": float(covered.mean()),
            "reference": reference, "ladder": ladder, "runs": runs}


# ----------------------------------------------------------------------------- the report
def _variant_name(options: str) -> str:
    return "default" if options.strip() in ("", "default") else f"`{options.strip()}`"


def _plantgen_ms(run: PlantgenRun) -> float:
    return run.frame_ms + run.shadow_ms


def _match_cells(run: PlantgenRun, match: dict) -> tuple[str, ...]:
    """The samples and sampling seconds Cycles needs to match ``run`` (``match``: from
    :func:`samples_to_match`), and those seconds over plantgen's warm frame and over the
    frame plus the shadow map."""
    if match.get("samples") is None:
        return "–", "–", "–", "–"
    bound = match["bound"]
    samples = f"{bound}{match['samples']:.0f}" if bound else f"{match['samples']:.1f}"
    ratios = [match["sampling_s"] / max(ms / 1000, 1e-9) for ms in (run.frame_ms, _plantgen_ms(run))]
    return (samples, f"{bound}{match['sampling_s']:.1f}", *(f"{bound}{_ratio(r)}×" for r in ratios))


def _ratio(r: float) -> str:
    return f"{r:.1f}" if r < 10 else f"{r:,.0f}"


def looks_table(results: list[dict], settings: Settings) -> str:
    """The Markdown of the benchmark: the ladder table, the matching table and a legend."""
    w, h = settings.size
    renderers = sorted({r["renderer"] for r in results if r["renderer"]})
    ladder_heads = [f"Cycles {s} spp" for s in settings.samples]
    ground = "" if settings.reference_ground == "auto" else ", without a ground under a single plant"
    lines = [f"Images {w}x{h}; the reference: Cycles (CPU) at {settings.reference_samples} samples of plantgen's "
             f"glTF export with the relief in the vertices{ground}; mean FLIP (LDR), lower is closer. plantgen on "
             f"{', '.join(renderers) or 'an unknown GL renderer'}: the median of {settings.frames} warm frames "
             "plus the shadow map, drawn once." + tone_legend(results, settings), "",
             "| scene | " + " | ".join(_variant_name(v) for v in settings.variants) + " | "
             + " | ".join(ladder_heads) + " | Cycles set-up (s) | masks' overlap | export m |",
             "|---" * (len(settings.variants) + len(ladder_heads) + 4) + "|"]
    for r in results:
        plantgen = [f"{run.flip:.3f} ({run.frame_ms:.0f} + {run.shadow_ms:.0f} ms)" for run in r["runs"]]
        cycles = [f"{rung['flip']:.3f} ({rung['sampling_s']:.1f} s)" for rung in r["ladder"]]
        setup = float(np.median([rung["setup_s"] for rung in r["ladder"]]))
        lines.append(f"| {r['scene']} | " + " | ".join(plantgen + cycles)
                     + f" | {setup:.1f} | {r['overlap']:.3f} | {r['subdiv']} |")
    lines += ["", "What Cycles needs to reach each plantgen image's FLIP: samples and sampling seconds, "
              "interpolated in log samples between the ladder's rungs (< and >: beyond the ladder), and "
              "those seconds over plantgen's. Cycles' set-up comes on top.", "",
              "| scene | plantgen | FLIP | plantgen frame + shadow map (ms) | Cycles spp | Cycles sampling (s) "
              "| Cycles / frame | Cycles / (frame + shadow map) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in results:
        for run in r["runs"]:
            cells = " | ".join(_match_cells(run, run.extra))
            lines.append(f"| {r['scene']} | {_variant_name(run.options)} | {run.flip:.3f} | "
                         f"{run.frame_ms:.0f} + {run.shadow_ms:.0f} | {cells} |")
    return "\n".join(lines + model_table(results, settings)) + "\n"


def tone_legend(results: list[dict], settings: Settings) -> str:
    """How the reference was toned, where each variant got its own display curve
    (``--reference-tone variant``; '' otherwise): each variant's curve, and the ladder's
    columns toned with the default's."""
    if settings.reference_tone != "variant" or not results:
        return ""
    curves = "; ".join(f"{_variant_name(run.options)}: {run.tone}" for run in results[0]["runs"])
    return (" Cycles' linear light is toned for each variant with that variant's own display curve, the "
            f"reference and the ladder it is matched on ({curves}); the ladder's columns are toned with "
            f"plantgen's default curve ({display_name(LookSettings.defaults())}).")


def model_table(results: list[dict], settings: Settings) -> list[str]:
    """The lines of the tables of FLIP over the model's pixels alone (either renderer's
    coverage), where the sky, alike in both, does not dilute the difference, and of what
    Cycles needs to match those."""
    heads = [_variant_name(v) for v in settings.variants] + [f"Cycles {s} spp" for s in settings.samples]
    lines = ["", "The same scores over the pixels either renderer covers (the model and its ground), "
             "leaving out the sky, which the two draw alike:", "",
             "| scene | covered | " + " | ".join(heads) + " |", "|---" * (len(heads) + 2) + "|"]
    for r in results:
        cells = [f"{run.flip_model:.3f}" for run in r["runs"]] + [f"{rung['flip_model']:.3f}" for rung in r["ladder"]]
        lines.append(f"| {r['scene']} | {100 * r['covered']:.0f} % | " + " | ".join(cells) + " |")
    lines += ["", "What Cycles needs to match each plantgen image's FLIP on the model:", "",
              "| scene | plantgen | FLIP on the model | Cycles spp | Cycles sampling (s) "
              "| Cycles / frame | Cycles / (frame + shadow map) |", "|---|---|---|---|---|---|---|"]
    for r in results:
        for run in r["runs"]:
            cells = " | ".join(_match_cells(run, run.extra_model))
            lines.append(f"| {r['scene']} | {_variant_name(run.options)} | {run.flip_model:.3f} | {cells} |")
    return lines


def reference_panels(result: dict, settings: Settings) -> list[tuple[np.ndarray, str]]:
    """Cycles' reference of a scene, labelled: as toned for plantgen's default, or, where
    each variant was judged by its own display curve (``--reference-tone variant``), once
    in each of those curves."""
    label = f"Cycles {settings.reference_samples} spp"
    if settings.reference_tone != "variant":
        return [(_rgb(result["reference"]["image"]), label)]
    linear = np.load(result["reference"]["linear"])[..., :3]
    tones = {run.tone: variant_looks(run.options) for run in result["runs"]}
    return [(display_image(linear, looks), f"{label} ({tone})") for tone, looks in tones.items()]


def looks_picture(results: list[dict], settings: Settings) -> np.ndarray:
    """Per scene a row: each plantgen variant, then Cycles' reference, labelled."""
    rows = []
    for r in results:
        panels = [(_rgb(run.image), f"{r['scene']}: plantgen {run.options} (FLIP {run.flip:.3f})")
                  for run in r["runs"]]
        panels += reference_panels(r, settings)
        rows.append(labelled_panels(panels, settings.size[0]))
    return np.concatenate(rows, axis=0)


def results_json(results: list[dict], settings: Settings) -> str:
    """Every number of the run, for other tools (paths as strings)."""
    def plain(value):
        if isinstance(value, Path):        # the cache under the home folder, as ~
            home = str(Path.home())
            return "~" + str(value)[len(home):] if str(value).startswith(home + os.sep) else str(value)
        if isinstance(value, PlantgenRun):
            return plain(asdict(value))
        if isinstance(value, dict):
            return {k: plain(v) for k, v in value.items()}
        if isinstance(value, (list, tuple)):
            return [plain(v) for v in value]
        return value
    head = {"size": list(settings.size), "reference_samples": settings.reference_samples,
            "samples": list(settings.samples), "variants": list(settings.variants),
            "reference_ground": settings.reference_ground, "reference_tone": settings.reference_tone}
    return json.dumps({"settings": head, "scenes": plain(results)}, indent=1)


def _counts(text: str) -> tuple[int, ...]:
    return tuple(int(x) for x in text.replace(",", " ").split())


def parse_arguments(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description="plantgen's looks against Blender Cycles, scored with FLIP")
    parser.add_argument("--scenes", default=",".join(SCENES), help=f"comma-separated (default {','.join(SCENES)})")
    parser.add_argument("--variants", default=DEFAULT_VARIANTS,
                        help="';'-separated plantgen render options, 'default' for none "
                             f"(default {DEFAULT_VARIANTS!r})")
    parser.add_argument("--size", type=image_size, default=(512, 384), help="WIDTHxHEIGHT (default 512x384)")
    parser.add_argument("--reference-samples", type=int, default=1024, help="Cycles samples of the reference")
    parser.add_argument("--samples", type=_counts, default=(1, 4, 16, 64, 256),
                        help="Cycles' ladder, comma-separated (default 1,4,16,64,256)")
    parser.add_argument("--frames", type=int, default=5, help="plantgen's warm frames timed (the median)")
    parser.add_argument("--max-triangles", type=int, default=1_000_000,
                        help="the reference export's triangle budget (picks its --subdiv)")
    parser.add_argument("--max-subdiv", type=int, default=6, help="the reference export's finest --subdiv")
    parser.add_argument("--reference-ground", choices=REFERENCE_GROUNDS, default="auto",
                        help="the reference's ground: auto, the one plantgen's default render draws (a single "
                             "plant's disc, a scene's own); none, no disc under a single plant (a scene keeps "
                             "its own), to score renders with --ground none (default auto)")
    parser.add_argument("--reference-tone", choices=REFERENCE_TONES, default="default",
                        help="how Cycles' linear light is toned for each variant's score: default, with "
                             "plantgen's default display curve for all; variant, with the variant's own (its "
                             "--no-tone, --tone-curve, --exposure, --effects), the ladder too (default default)")
    parser.add_argument("--threads", type=int, default=0, help="Cycles' threads (0: all)")
    parser.add_argument("--cache", type=Path, default=DEFAULT_CACHE, help=f"Cycles' images (default {DEFAULT_CACHE})")
    parser.add_argument("--blender", default=os.environ.get("BLENDER", "blender"), help="the Blender executable")
    parser.add_argument("--out", type=Path, default=Path("."), help="folder of looks.md, looks.json, looks.png")
    parser.add_argument("--name", default="looks", help="the files' name before .md, .json, .png (default looks)")
    return parser.parse_args(argv)


def main(argv=None) -> int:
    """``python -m plantgen.benchmarks.looks``: the table, the numbers and the picture."""
    args = parse_arguments(argv)
    variants = tuple(v.strip() for v in args.variants.split(";") if v.strip())
    settings = Settings(size=args.size, reference_samples=args.reference_samples, samples=args.samples,
                        variants=variants, frames=args.frames, max_triangles=args.max_triangles,
                        max_subdiv=args.max_subdiv, reference_ground=args.reference_ground,
                        reference_tone=args.reference_tone, threads=args.threads,
                        cache=args.cache, blender=args.blender)
    try:
        settings.blender = find_blender(args.blender)
        flip_error(np.zeros((8, 8, 3), np.uint8), np.zeros((8, 8, 3), np.uint8))
        work = work_folder(settings)
        results = [measure_scene(s.strip(), settings, work / s.strip()) for s in args.scenes.split(",") if s.strip()]
    except (PlantgenError, subprocess.TimeoutExpired, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / f"{args.name}.json").write_text(results_json(results, settings))
    Image.fromarray(looks_picture(results, settings)).save(args.out / f"{args.name}.png")
    return report(looks_table(results, settings), args.out / f"{args.name}.md")


if __name__ == "__main__":
    sys.exit(main())
