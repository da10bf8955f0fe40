"""The RC+R | Blender image of one model: plantgen's ray-cast render beside Blender's render
(Cycles, on the CPU) of the glTF that ``plantgen export`` writes of it, seen by the same
camera and lit by the same sun. It shows what the exported file carries into another tool:
the baked base-colour and normal maps on the mesh, the scene's ground, camera and light.

Run as ``python -m plantgen.benchmarks.in_blender MODEL OUT.png [--size W H] [--samples N]
[--level M]``; it needs Blender (``blender`` on the PATH, run as ``blender --background``).

The camera and the sun are plantgen's (the scene's, or the automatic framing and the
model light of a grammar), set in Blender by the script below rather than taken from the
file: glTF's directional light carries lux, which Blender's importer turns into
W/m² (1 lux is 1/683 W/m²), so the sun is given a strength of 3 W/m² and the world a flat
sky colour for the ambient light, and Blender's "Standard" view transform writes sRGB as
plantgen does. Blender's y is glTF's -z and its z glTF's y (its importer's axis change).
Debian 12's Blender 3.4 importer calls ``numpy.bool``, which Debian's numpy 1.24 lacks: the
script restores the alias before importing.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from PIL import Image

from ..errors import PlantgenError
from ..gl.raycast import Raycaster
from ..pipeline import export_model, frame_arguments, prepare_model, stage_model
from ..settings import RaycastSettings, ShadowSettings
from .side_by_side import labelled_panels

__all__ = ["BLENDER_SCRIPT", "NUMPY_BOOL", "blender_view", "main"]

#: The first lines of a script for Debian 12's Blender 3.4: its glTF importer calls
#: ``numpy.bool``, which Debian's numpy 1.24 lacks (numpy 2 has it again); restored here,
#: so that the importer runs whichever numpy Blender's Python finds.
NUMPY_BOOL = """import numpy
if not hasattr(numpy, "bool"):
    numpy.bool = numpy.bool_
"""

#: Run by ``blender --background --python``: import the glTF, set the camera and the sun,
#: render with Cycles. Its arguments after ``--``: the JSON of :func:`_view_json`.
BLENDER_SCRIPT = NUMPY_BOOL + r"""
import json, math, sys, time
import bpy
from mathutils import Vector

job = json.loads(sys.argv[sys.argv.index("--") + 1])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=job["file"])
for obj in [o for o in bpy.data.objects if o.type in ("CAMERA", "LIGHT")]:
    bpy.data.objects.remove(obj, do_unlink=True)

def z_up(p):                            # glTF (y up) -> Blender (z up), as the importer turns it
    return Vector((p[0], -p[2], p[1]))

scene = bpy.context.scene
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
eye, target = z_up(job["eye"]), z_up(job["target"])
camera.location = eye
camera.rotation_euler = (target - eye).to_track_quat("-Z", "Y").to_euler()
camera.data.sensor_fit = "VERTICAL"
camera.data.angle = math.radians(job["fov_y"])
camera.data.clip_start, camera.data.clip_end = job["near"], job["far"]
scene.camera = camera
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
sun.data.energy = 3.0
sun.data.angle = 0.0
sun.rotation_euler = z_up(job["light_dir"]).to_track_quat("Z", "Y").to_euler()
scene.collection.objects.link(sun)
world = bpy.data.worlds.new("sky")
world.use_nodes = True
background = world.node_tree.nodes["Background"]
background.inputs[0].default_value = (0.55, 0.7, 0.9, 1.0)
background.inputs[1].default_value = 0.6
scene.world = world
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = job["samples"]
scene.cycles.use_denoising = False
scene.view_settings.view_transform = "Standard"
scene.render.resolution_x, scene.render.resolution_y = job["size"]
scene.render.resolution_percentage = 100
scene.render.filepath = job["out"]
t0 = time.perf_counter()
bpy.ops.render.render(write_still=True)
print("RENDERED %.1f" % (time.perf_counter() - t0))
"""


def _view_json(staging, glb: Path, out: Path, samples: int) -> str:
    cam = staging.camera
    span = float(np.linalg.norm(np.subtract(cam.eye, cam.target)))
    return json.dumps({"file": str(glb), "out": str(out), "samples": int(samples), "size": [cam.width, cam.height],
                       "eye": list(map(float, cam.eye)), "target": list(map(float, cam.target)),
                       "fov_y": float(cam.fov_y), "near": span * 1e-3, "far": span * 1e3,
                       "light_dir": list(map(float, staging.light_dir))})


def blender_view(model: str, size=(512, 384), samples: int = 32, level: int = 2, blender: str | None = None,
                 say=print) -> np.ndarray:
    """RC+R | Blender of ``model`` (a grammar, scene or skeleton), labelled, (h, 2w, 3) uint8."""
    blender = blender or shutil.which("blender")
    if blender is None:
        raise PlantgenError("Blender is not installed (apt install blender): its render cannot be made here")
    prepared = prepare_model(model)
    frusta = prepared.frusta_at(0.0)
    staging = stage_model(prepared.grown, frusta, *size)
    shadows = ShadowSettings() if "shadows" in prepared.effects else None
    rc = Raycaster().render(frusta, settings=RaycastSettings(relief=True),
                            **frame_arguments(frusta, staging, shadows))
    with tempfile.TemporaryDirectory() as tmp:
        glb, out, script = Path(tmp) / "model.glb", Path(tmp) / "blender.png", Path(tmp) / "render.py"
        summary = export_model(model, glb, level=level)
        script.write_text(BLENDER_SCRIPT)
        t0 = time.perf_counter()
        done = subprocess.run([blender, "--background", "--factory-startup", "--python", str(script), "--",
                               _view_json(staging, glb, out, samples)], capture_output=True, text=True, timeout=3600)
        if done.returncode != 0 or not out.exists():
            tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            raise PlantgenError(f"Blender could not render {model}: {tail[0]}")
        seconds = time.perf_counter() - t0
        picture = np.asarray(Image.open(out).convert("RGB"))
    say(f"{model}: RC+R {rc.frame_ms:.1f} ms; Blender Cycles {samples} samples {seconds:.1f} s")
    triangles = summary.get("triangles", 0)
    panels = [(rc.color, f"plantgen RC+R: {len(frusta):,} frusta"),
              (picture, f"Blender 3.4 Cycles: the exported glb, m={level}, {triangles:,} triangles")]
    return labelled_panels(panels, size[0])


def main(argv=None) -> int:
    """``python -m plantgen.benchmarks.in_blender MODEL OUT.png``: the RC+R | Blender image."""
    parser = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    parser.add_argument("model", help="grammar, scene or skeleton .npz")
    parser.add_argument("output")
    parser.add_argument("--size", type=int, nargs=2, default=(512, 384))
    parser.add_argument("--samples", type=int, default=32, help="Cycles samples per pixel (default 32)")
    parser.add_argument("--level", type=int, default=2, help="the exported mesh's subdivision level (default 2)")
    args = parser.parse_args(argv)
    try:
        image = blender_view(args.model, tuple(args.size), args.samples, args.level)
    except PlantgenError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    Image.fromarray(image).save(args.output)
    print(f"wrote {args.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
