"""Blender's side of the looks benchmark (:mod:`plantgen.benchmarks.looks`): run by Blender's
own Python, ``blender --background --factory-startup --python cycles_reference.py -- JOB.json``,
it imports a glTF that ``plantgen export`` wrote and renders it with Cycles on the CPU as
plantgen would light it. It imports nothing from plantgen: the job file carries every number.

The job (JSON): ``file`` (the .glb), ``size`` [w, h], ``threads`` (0: all), the
``renders`` to make of it, one import for all (each a ``name``, the ``out`` path without
its suffix, ``samples``, ``seed`` and ``transparent``: film alpha, the coverage mask), the
``camera`` plantgen wrote with ``--camera-out`` (``eye``, ``target``, ``up``, ``fov_y``: y
up), the ``light`` (``towards``: the unit direction to the sun, y up, its ``color`` and
``angle``, the sun's angular diameter in degrees), ``ambient`` (plantgen's ambient
colour), ``sky`` (``zenith``, ``horizon``, ``ground``: plantgen's sky gradient),
``leaf_transmission`` (plantgen's translucent leaves; 0: opaque) and ``matte`` (the
objects whose materials become Lambertian: the ground).

What it sets, and why (the traps of Debian's Blender 3.4 as a reference):

- ``numpy.bool``, which the glTF importer calls and numpy 1.24 removed, is restored first;
- the importer's RAW lighting mode, though the imported lights are removed anyway: the sun
  is rebuilt from the job (a grammar's file has none), of strength π (a Cycles sun of 1
  lights a white diffuse surface to 1/π, plantgen's light of 1 to 1) and plantgen's sun
  angle (0 by default: a hard shadow, as a shadow map gives);
- the leaves (materials named ``... (leaf)``) add a Translucent BSDF of
  ``leaf_transmission`` times their colour, as plantgen's translucent leaves pass the light
  falling on their far side; the ground is Lambertian (a Diffuse BSDF: plantgen's sand
  is nearly so, where the imported Principled BSDF's specular and retro-reflection light
  the far ground up). The ground's
  fade into the sky is in the file (its texture's alpha, ``alphaMode: BLEND``): camera
  rays pass through its rim to the sky;
- the camera is rebuilt from plantgen's (the import ignores the aspect ratio), vertical
  field of view, and the resolution is the job's;
- the world: glTF has no sky. Camera rays see plantgen's gradient; every other ray sees
  plantgen's ambient colour above the horizon and black below, which gives an open surface
  of normal n plantgen's ambient term, ambient · (1 + n_y) / 2;
- linear light out, unclipped: each still is written as a 32-bit EXR and then as a
  (h, w, 4) float32 ``out.npy`` (row 0 at the top), which the benchmark tones with
  plantgen's own display curve (the tone curve and sRGB of plantgen's default render);
  no denoiser, no adaptive sampling, a fixed seed;
- a box pixel filter one pixel wide (Cycles' default is a 1.5-pixel Blackman-Harris,
  which blurs across neighbours): the converged reference is each pixel's own area
  averaged, what plantgen's ``--ssaa N`` converges to.

Before each render it prints ``CYCLES-START name``, after it one line ``CYCLES {json}``
with the seconds of the import and the scene's building (``import_s``, once for all) and
of the render (``render_s``); Blender's own status lines between the two tell the
render's set-up (kernels, BVH, images) from its sampling. Blender is z up: a y-up vector
(x, y, z) is Blender's (x, -z, y).
"""

import json
import math
import sys
import time

import numpy

if not hasattr(numpy, "bool"):      # Debian 12's numpy 1.24 lacks the alias its importer calls
    numpy.bool = numpy.bool_

import bpy  # noqa: E402  (Blender's module: only inside Blender)
from mathutils import Vector  # noqa: E402


def z_up(p):
    """A y-up point or direction as Blender's z-up Vector (the importer's turn)."""
    return Vector((p[0], -p[2], p[1]))


def import_scene(path):
    """Blender emptied, the glTF imported, its cameras and lights removed."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    try:
        bpy.ops.import_scene.gltf(filepath=path, export_import_convert_lighting_mode="RAW")
    except TypeError:                  # an importer without the lighting modes
        bpy.ops.import_scene.gltf(filepath=path)
    for obj in [o for o in bpy.data.objects if o.type in ("CAMERA", "LIGHT")]:
        bpy.data.objects.remove(obj, do_unlink=True)


def add_camera(scene, view):
    """plantgen's camera: eye, target, up (y up) and the vertical field of view."""
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    scene.collection.objects.link(camera)
    eye, target = z_up(view["eye"]), z_up(view["target"])
    camera.location = eye
    camera.rotation_euler = (target - eye).to_track_quat("-Z", "Y").to_euler()
    camera.data.sensor_fit = "VERTICAL"
    camera.data.angle = math.radians(view["fov_y"])
    span = (target - eye).length
    camera.data.clip_start, camera.data.clip_end = span * 1e-3, span * 1e3
    scene.camera = camera


def add_sun(scene, light):
    """A sun shining along -``towards``, strength π, plantgen's light colour and its sun's
    angular diameter (``angle``, degrees; 0: a point, hard shadows)."""
    sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", "SUN"))
    sun.data.energy = math.pi * light.get("intensity", 1.0)
    sun.data.angle = math.radians(float(light.get("angle", 0.0)))
    sun.data.color = light["color"]
    sun.rotation_euler = z_up(light["towards"]).to_track_quat("Z", "Y").to_euler()
    scene.collection.objects.link(sun)


def _math(tree, operation):
    node = tree.nodes.new("ShaderNodeMath")
    node.operation = operation
    return node


def _rgb(tree, color):
    node = tree.nodes.new("ShaderNodeRGB")
    node.outputs[0].default_value = (*color, 1.0)
    return node.outputs[0]


def _mix(tree, fac, a, b):
    node = tree.nodes.new("ShaderNodeMixRGB")
    tree.links.new(fac, node.inputs["Fac"])
    tree.links.new(a, node.inputs[1])
    tree.links.new(b, node.inputs[2])
    return node.outputs[0]


def _power_of(tree, value, sign, exponent):
    """max(sign · value, 0) ** exponent, as math nodes."""
    scaled = _math(tree, "MULTIPLY")
    tree.links.new(value, scaled.inputs[0])
    scaled.inputs[1].default_value = sign
    clamped = _math(tree, "MAXIMUM")
    tree.links.new(scaled.outputs[0], clamped.inputs[0])
    clamped.inputs[1].default_value = 0.0
    power = _math(tree, "POWER")
    tree.links.new(clamped.outputs[0], power.inputs[0])
    power.inputs[1].default_value = exponent
    return power.outputs[0]


def build_world(scene, sky, ambient):
    """Camera rays: plantgen's sky gradient (shaders/shading.glsl's sky_color); other rays:
    the ambient colour above the horizon, black below."""
    world = bpy.data.worlds.new("plantgen sky")
    world.use_nodes = True
    tree = world.node_tree
    up = tree.nodes.new("ShaderNodeSeparateXYZ")
    tree.links.new(tree.nodes.new("ShaderNodeTexCoord").outputs["Generated"], up.inputs[0])
    z = up.outputs["Z"]
    above = _mix(tree, _power_of(tree, z, 1.0, 0.6), _rgb(tree, sky["horizon"]), _rgb(tree, sky["zenith"]))
    seen = _mix(tree, _power_of(tree, z, -1.0, 0.5), above, _rgb(tree, sky["ground"]))
    is_up = _math(tree, "GREATER_THAN")
    tree.links.new(z, is_up.inputs[0])
    is_up.inputs[1].default_value = 0.0
    lighting = _mix(tree, is_up.outputs[0], _rgb(tree, (0.0, 0.0, 0.0)), _rgb(tree, ambient))
    path = tree.nodes.new("ShaderNodeLightPath")
    colour = _mix(tree, path.outputs["Is Camera Ray"], lighting, seen)
    tree.links.new(colour, tree.nodes["Background"].inputs["Color"])
    tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    scene.world = world


def translucent_leaves(transmission):
    """Each leaf material (the export names them ``"<material> (leaf)"`` or ``"(leaf
    card)"``) transmits as plantgen's translucent leaves do: its surface is the imported
    shader plus a Translucent BSDF of ``transmission`` times its base colour (the light
    falling on the far side, diffusely through, tinted by the albedo)."""
    if transmission <= 0.0:
        return
    for material in bpy.data.materials:
        if "(leaf" not in material.name or not material.use_nodes:
            continue
        tree = material.node_tree
        output = next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"), None)
        bsdf = next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
        if output is None or bsdf is None or not output.inputs["Surface"].is_linked:
            continue
        surface = output.inputs["Surface"].links[0].from_socket
        tint = tree.nodes.new("ShaderNodeMixRGB")
        tint.blend_type, tint.inputs["Fac"].default_value = "MULTIPLY", 1.0
        base = bsdf.inputs["Base Color"]
        if base.is_linked:
            tree.links.new(base.links[0].from_socket, tint.inputs[1])
        else:
            tint.inputs[1].default_value = base.default_value
        tint.inputs[2].default_value = (transmission, transmission, transmission, 1.0)
        through = tree.nodes.new("ShaderNodeBsdfTranslucent")
        tree.links.new(tint.outputs[0], through.inputs["Color"])
        both = tree.nodes.new("ShaderNodeAddShader")
        tree.links.new(surface, both.inputs[0])
        tree.links.new(through.outputs[0], both.inputs[1])
        tree.links.new(both.outputs[0], output.inputs["Surface"])


def matte(names):
    """The materials of the objects ``names`` (the ground) made Lambertian, as plantgen
    draws its ground (a specular of 0.02): a Diffuse BSDF of the imported base colour,
    mixed with a Transparent BSDF by its alpha (the fade at the rim). The importer's
    Principled BSDF would add a specular layer that reflects the sky at grazing angles and
    a retro-reflective diffuse, both lighting the far ground up."""
    for obj in bpy.data.objects:
        if obj.type != "MESH" or obj.name.split(".")[0] not in names:
            continue
        for slot in obj.material_slots:
            if slot.material is not None and slot.material.use_nodes:
                lambert(slot.material.node_tree)


def feed(tree, source, target):
    """``target`` takes what feeds ``source``: the link into it, else its value."""
    if source.is_linked:
        tree.links.new(source.links[0].from_socket, target)
    else:
        target.default_value = source.default_value


def lambert(tree):
    """``tree``'s Principled BSDF replaced at its output by Diffuse over Transparent by alpha."""
    output = next((n for n in tree.nodes if n.type == "OUTPUT_MATERIAL"), None)
    bsdf = next((n for n in tree.nodes if n.type == "BSDF_PRINCIPLED"), None)
    if output is None or bsdf is None:
        return
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    feed(tree, bsdf.inputs["Base Color"], diffuse.inputs["Color"])
    mix = tree.nodes.new("ShaderNodeMixShader")
    feed(tree, bsdf.inputs["Alpha"], mix.inputs["Fac"])
    tree.links.new(tree.nodes.new("ShaderNodeBsdfTransparent").outputs[0], mix.inputs[1])
    tree.links.new(diffuse.outputs[0], mix.inputs[2])
    tree.links.new(mix.outputs[0], output.inputs["Surface"])


def set_render(scene, job, still):
    """Cycles on the CPU: the still's samples and seed, no denoiser, no adaptive sampling,
    the Standard view transform, the job's size; a transparent film for a coverage mask."""
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = "CPU"
    cycles.samples = int(still["samples"])
    cycles.seed = int(still.get("seed", 0))
    cycles.use_denoising = False
    cycles.use_adaptive_sampling = False
    cycles.pixel_filter_type, cycles.filter_width = "BOX", 1.0   # a pixel's own area, as plantgen's --ssaa averages
    transparent = bool(still.get("transparent", False))
    scene.render.film_transparent = transparent
    for obj in scene.objects:          # a mask leaves out what plantgen's mask leaves out
        if any(obj.name.split(".")[0] == name for name in job.get("mask_hides", ())):
            obj.hide_render = transparent
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure, scene.view_settings.gamma = 0.0, 1.0
    scene.render.resolution_x, scene.render.resolution_y = job["size"]
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "OPEN_EXR"      # linear light, unclipped
    scene.render.image_settings.color_depth = "32"
    scene.render.image_settings.color_mode = "RGBA"
    threads = int(job.get("threads", 0))
    scene.render.threads_mode = "FIXED" if threads else "AUTO"
    if threads:
        scene.render.threads = threads
    scene.render.filepath = still["out"] + ".exr"


def render_timed():
    """Render and write the still; its seconds (Blender's status lines, which go to stdout,
    tell the set-up from the sampling: the first ``Sample 0/N`` line's clock)."""
    start = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    return time.perf_counter() - start


def save_linear(exr, out):
    """The still's EXR as a (h, w, 4) float32 .npy of linear light, row 0 at the top."""
    image = bpy.data.images.load(exr)
    pixels = numpy.empty(image.size[0] * image.size[1] * 4, dtype=numpy.float32)
    image.pixels.foreach_get(pixels)
    numpy.save(out, pixels.reshape(image.size[1], image.size[0], 4)[::-1])
    bpy.data.images.remove(image)


def main():
    with open(sys.argv[sys.argv.index("--") + 1]) as handle:
        job = json.load(handle)
    start = time.perf_counter()
    import_scene(job["file"])
    scene = bpy.context.scene
    add_camera(scene, job["camera"])
    add_sun(scene, job["light"])
    build_world(scene, job["sky"], job["ambient"])
    matte(job.get("matte", ()))
    translucent_leaves(float(job.get("leaf_transmission", 0.0)))
    imported = time.perf_counter() - start
    for still in job["renders"]:
        set_render(scene, job, still)
        print("CYCLES-START " + still["name"], flush=True)
        seconds = render_timed()
        save_linear(still["out"] + ".exr", still["out"] + ".npy")
        print("CYCLES " + json.dumps({"name": still["name"], "import_s": imported, "render_s": seconds}), flush=True)


if __name__ == "__main__":
    main()
