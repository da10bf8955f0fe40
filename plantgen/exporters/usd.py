"""USD (``.usda`` text, ``.usdc`` or ``.usd`` crate) through usd-core (``plantgen[usd]``).

One plant, written in place::

    /<plant>                Xform, the stage's default prim
        Materials/<name>    Material with a UsdPreviewSurface (diffuseColor: the material
                            colour, linear RGB; roughness 0.8; metallic 0)
        Mesh                Mesh: points, triangles, vertex normals, primvars:st, no
                            subdivision; one GeomSubset per material (family materialBind,
                            a partition) bound to its material
        Leaves              Mesh of the grammar's leaf polygons (only when it has some):
                            points, triangles, vertex normals (the polygon's),
                            primvars:st across each leaf, ``doubleSided = true``,
                            primvars:displayColor each leaf's shade (as the renderers
                            draw it); bound to materials ``<name>_leaf`` whose surface
                            reads displayColor (with ``colours`` given: to the plant's
                            materials, as Mesh is)
        Skeleton            BasisCurves, linear, purpose "guide" (drawn on request, not
                            rendered): one curve per branch, widths = diameters (2·radius,
                            as USD defines widths) per point

A plant with levels of detail (:class:`~plantgen.exporters.plants.PlantDetail`):
its prim holds a variantSet ``lod``, variants ``lod0`` (full, selected) to ``lod<N-1>``,
each authoring that level's ``Mesh`` and ``Leaves`` (materials and ``Skeleton`` stay
outside, shared); the screen coverages in its customData ``plantgen:lodScreenCoverage``.
A copy referencing the plant holds the set too, so its selection switches that copy.
A swaying plant's levels are bound to its one ``Joints`` (UsdSkel under the variantSet):
the copy's ``Sway`` drives whichever level is selected.

A scene, ``instancing="nodes"`` (the default): one instanceable Xform per copy with its
transform, referencing its plant under the abstract ``/<scene>/Prototypes`` (every copy a
prim of its own, made by plain composition, which every USD reader performs; a
PointInstancer is a schema a reader must implement, so the default matches glTF's: what
opens everywhere). ``instancing="gpu"``: ``/<scene>/Plants`` is a
``PointInstancer`` whose
prototypes (``Plants/Prototypes/<plant>``, each as above) are the scene's distinct plants,
written once; ``protoIndices``, ``positions``, ``orientations`` (quath, for every reader)
and ``orientationsf`` (quatf, which takes precedence where it is read), ``scales`` place
the copies (compact for thousands of copies, for renderers that instance natively).

A plant that sways (written with an ``animation``, :mod:`~plantgen.exporters.sway`) is
UsdSkel: its prim is a SkelRoot with a Skeleton ``Joints`` (a joint per segment, paths
``s0/s1/...``: :func:`joint_names`; bind transforms at the segments' starts, rest
transforms the translations between them), its Mesh, Leaves and Skeleton curves bound
to it (``primvars:skel:jointIndices`` and ``jointWeights``). It is written once under the
abstract ``/<scene>/Prototypes``, each copy a SkelRoot referencing it (not instanceable:
each has its own animation) with its transform and its SkelAnimation ``Sway`` (rotations
time-sampled at the codes 0 .. keys - 1), the ``skel:animationSource`` of its Joints; a
plant written in place holds its ``Sway`` itself. The stage's start and end time codes
and its time codes (and frames) per second span the keys.

A scene (``extras``, :class:`~plantgen.exporters.plants.SceneExtras`) adds, under the
default prim: ``Ground``, an Xform with its ``Materials`` and a ``Mesh`` (two triangles
facing up, bound to the ground's material); ``Camera``, a perspective ``Camera`` at the
eye looking at the target with the camera's up (``verticalAperture`` 24, as the 35 mm
frame's height, ``horizontalAperture`` that times width over height, ``focalLength``
giving the camera's fov_y, ``clippingRange`` 1/1000 to 1000 times the eye-target
distance); ``Sun``, a ``DistantLight`` shining along the scene light's direction (its -z),
``intensity`` the scene light's (plantgen's units: 1 is the renderer's full light). All
turn with the model (``up``).

Stage metadata: ``upAxis`` (Y, or Z with ``up="z"``: the model is turned, see
:mod:`plantgen.geometry.skeletons.frames`), ``metersPerUnit`` (``unit``: the length of a model unit
in metres, default 1) and ``defaultPrim``. usd-core's compliance checker
(``UsdUtils.ComplianceChecker``, what ``usdchecker`` runs) and its validators pass on
every file (tested).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..files import write_all_atomically
from ..geometry.skeletons.frames import similarity_trs, turn_placements, up_rotation
from ..geometry.skeletons.skeleton import Skeleton
from ..geometry.skeletons.topology import branches
from .formats import ExportError
from .gltf import generator
from .plants import (
    Colours,
    Plant,
    Progress,
    SceneExtras,
    camera_pose,
    ground_colour,
    ground_mesh,
    leaf_parts,
    level_plant,
    light_rotation,
    material_colours,
    turned_mesh,
    unique_name,
)
from .sway import JointRig, Timeline, copy_rotations, joint_rig, level_rig
from .textures import Textures, png_writes, texture_files

__all__ = ["joint_names", "skeleton_curves", "write_usd"]


def skeleton_curves(skeleton: Skeleton) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One polyline per branch: points (p, 3), widths (p,) (diameters), the number of
    points of each curve (b,) and the segment each point lies on (p,) (the point is its
    start or its end). A branch's first point is its first segment's start; a segment
    whose start radius differs from its parent's end radius repeats its start point with
    the new width."""
    topo = branches(skeleton)
    order = np.lexsort((topo.position, topo.branch))
    parent = skeleton.parent[order]
    restart = (topo.position[order] == 0) | (skeleton.r_start[order] != skeleton.r_end[np.maximum(parent, 0)])
    count = 1 + restart.astype(np.int64)
    first = np.cumsum(count) - count
    total = int(count.sum())
    points = np.empty((total, 3))
    widths = np.empty(total)
    points[first + restart], widths[first + restart] = skeleton.end[order], 2 * skeleton.r_end[order]
    starts = first[restart]
    points[starts], widths[starts] = skeleton.start[order][restart], 2 * skeleton.r_start[order][restart]
    per_branch = np.bincount(topo.branch[order], weights=count, minlength=len(topo)).astype(np.int64)
    return points, widths, per_branch, np.repeat(order, count)


def _joined(parts) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(vertices, normals, faces, material per face) of ``parts`` as one mesh."""
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
    return (np.concatenate([p.vertices for p in parts]), np.concatenate([p.normals for p in parts]),
            np.concatenate([p.faces + o for p, o in zip(parts, offsets, strict=False)]),
            np.concatenate([np.full(len(p.faces), p.material) for p in parts]))


#: The vertical aperture of a written camera (tenths of a scene unit, as USD reads it; the
#: 35 mm frame's 24 mm): the focal length follows from the field of view.
CAMERA_APERTURE = 24.0


def _row_major(rotation: np.ndarray, translation=None) -> np.ndarray:
    """(4, 4) transform of ``rotation`` (3, 3, acting on column vectors) and
    ``translation`` in USD's row-vector layout."""
    out = np.eye(4)
    out[:3, :3] = rotation.T
    if translation is not None:
        out[3, :3] = translation
    return out


def _translations(points: np.ndarray) -> np.ndarray:
    """(n, 4, 4) translations by ``points`` (n, 3) in USD's row-vector layout (the
    translation in the last row)."""
    out = np.tile(np.eye(4), (len(points), 1, 1))
    out[:, 3, :3] = points
    return out


def joint_names(parent: np.ndarray) -> list[str]:
    """UsdSkel's joint paths of a forest of joints (``parent`` (j,), parents first): joint
    i is ``s<i>`` under its parent's path (``s0/s1/s5``)."""
    names: list[str] = []
    for joint, up in enumerate(parent.tolist()):
        names.append(f"s{joint}" if up < 0 else f"{names[up]}/s{joint}")
    return names


class _Writer:
    """Builds one stage (usd-core imported lazily: it takes about half a second)."""

    def __init__(self, up: str, unit: float, colours: Colours, textures: Textures | None = None,
                 files: dict | None = None) -> None:
        from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade, UsdSkel, Vt

        self.Gf, self.Sdf, self.Tf, self.Usd, self.UsdGeom, self.UsdShade, self.UsdSkel, self.Vt = (
            Gf, Sdf, Tf, Usd, UsdGeom, UsdShade, UsdSkel, Vt)
        self.UsdLux = UsdLux
        self.up, self.colours = up, colours
        self.textures, self.files = textures, files or {}
        self.stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.z if up == "z" else UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, float(unit))
        self.stage.GetRootLayer().documentation = f"written by {generator()}"

    def name(self, text: str, taken: set) -> str:
        name = unique_name(self.Tf.MakeValidIdentifier(text or "plant"), taken)
        taken.add(name)
        return name

    def root(self, name: str):
        prim = self.UsdGeom.Xform.Define(self.stage, f"/{name}").GetPrim()
        self.stage.SetDefaultPrim(prim)
        return prim.GetPath()

    def plant(self, path, plant: Plant, rig: JointRig | None = None) -> None:
        """The plant's Xform at ``path``: materials, mesh, skeleton curves; with a ``rig``
        a SkelRoot, its joints the UsdSkel Skeleton ``Joints`` and every mesh and curve
        bound to them (see the module docstring)."""
        if rig is None:
            self.UsdGeom.Xform.Define(self.stage, path)
        else:
            self.UsdSkel.Root.Define(self.stage, path)
            self._joints(path.AppendChild("Joints"), rig)
        materials = self._materials(path.AppendChild("Materials"), plant.mesh.material_names)
        leaf_materials = materials
        if plant.has_leaves and self.colours is None:
            leaf_materials = self._leaf_materials(path.AppendChild("Materials"), plant.mesh.material_names,
                                                  set(np.unique(plant.leaves.material).tolist()))
        if plant.detail is None:
            self._surfaces(path, plant, materials, leaf_materials, rig)
        else:
            self._levels(path, plant, materials, leaf_materials, rig)
        if len(plant.skeleton):
            curves, segment = self._curves(path.AppendChild("Skeleton"), plant.skeleton)
            if rig is not None:
                joints = np.zeros((len(segment), 4), np.int64)
                joints[:, 0] = segment
                self._bind(curves, path.AppendChild("Joints"), joints, (np.arange(4) == 0) * np.ones((len(segment), 1)))

    def _surfaces(self, path, plant: Plant, materials, leaf_materials, rig: JointRig | None) -> None:
        """The plant's ``Mesh`` and (where it has leaves) ``Leaves`` under ``path``, bound
        to ``materials`` and ``leaf_materials`` (and with a ``rig`` to its ``Joints``)."""
        vertices, normals = turned_mesh(plant.mesh, self.up)
        mesh = self._mesh(path.AppendChild("Mesh"), (vertices, normals, plant.mesh.faces, plant.mesh.face_material),
                          materials, plant.mesh.uv)
        if rig is not None:
            self._bind(mesh, path.AppendChild("Joints"), rig.vertex_joints, rig.vertex_weights)
        if not plant.has_leaves:
            return
        names = plant.mesh.material_names
        parts = leaf_parts(plant.leaves, self.up, None if rig is None else rig.leaf_joints,
                           names if self.colours is None else None)
        leaves = self._mesh(path.AppendChild("Leaves"), _joined(parts), leaf_materials,
                            np.concatenate([p.uv for p in parts]), double_sided=True)
        if parts[0].colours is not None:
            self.UsdGeom.PrimvarsAPI(leaves).CreatePrimvar(
                "displayColor", self.Sdf.ValueTypeNames.Color3fArray, self.UsdGeom.Tokens.vertex).Set(
                self.Vt.Vec3fArray.FromNumpy(np.concatenate([p.colours for p in parts]).astype(np.float32)))
        if rig is not None:
            self._bind(leaves, path.AppendChild("Joints"), np.concatenate([p.joints for p in parts]),
                       np.concatenate([p.weights for p in parts]))

    def _levels(self, path, plant: Plant, materials, leaf_materials, rig: JointRig | None = None) -> None:
        """The plant's levels of detail: a variantSet ``lod`` on its prim, variant ``lodk``
        holding level k's ``Mesh`` and ``Leaves`` (the materials and the skeleton curves
        outside it, shared; with a ``rig`` every level bound to the one ``Joints``, its
        animation shared too), ``lod0`` (full) selected; the screen coverages in the prim's
        customData ``plantgen:lodScreenCoverage``."""
        prim = self.stage.GetPrimAtPath(path)
        variants = prim.GetVariantSets().AddVariantSet("lod")
        for k in range(len(plant.detail.levels)):
            variants.AddVariant(f"lod{k}")
            variants.SetVariantSelection(f"lod{k}")
            with variants.GetVariantEditContext():
                level = level_plant(plant, k)
                own = None if rig is None else level_rig(rig, level.skeleton, level.mesh, level.sway, level.leaves,
                                                         self.up, plant.name)
                self._surfaces(path, level, materials, leaf_materials, own)
        variants.SetVariantSelection("lod0")
        prim.SetCustomDataByKey("plantgen:lodScreenCoverage",
                                self.Vt.DoubleArray([float(c) for c in plant.detail.coverage]))

    def _joints(self, path, rig: JointRig) -> None:
        """The UsdSkel Skeleton at ``path``: a joint per segment (and the still one), bound
        and at rest where the segments start."""
        skeleton = self.UsdSkel.Skeleton.Define(self.stage, path)
        skeleton.CreateJointsAttr(self.Vt.TokenArray(joint_names(rig.parent)))
        skeleton.CreateBindTransformsAttr(self.Vt.Matrix4dArray.FromNumpy(_translations(rig.bind)))
        skeleton.CreateRestTransformsAttr(self.Vt.Matrix4dArray.FromNumpy(_translations(rig.offset)))

    def _bind(self, prim, skeleton, joints: np.ndarray, weights: np.ndarray) -> None:
        """Bind ``prim`` (a point-based geometry) to the Skeleton at ``skeleton``: each point
        follows ``joints`` (p, 4) with ``weights`` (p, 4), as many of them as any point uses."""
        used = max(1, int((weights > 0).sum(axis=1).max())) if len(weights) else 1
        binding = self.UsdSkel.BindingAPI.Apply(prim.GetPrim())
        binding.CreateSkeletonRel().SetTargets([skeleton])
        binding.CreateJointIndicesPrimvar(False, used).Set(
            self.Vt.IntArray.FromNumpy(np.ascontiguousarray(joints[:, :used], dtype=np.int32).ravel()))
        binding.CreateJointWeightsPrimvar(False, used).Set(
            self.Vt.FloatArray.FromNumpy(np.ascontiguousarray(weights[:, :used], dtype=np.float32).ravel()))
        binding.CreateGeomBindTransformAttr(self.Gf.Matrix4d(1.0))

    def sway(self, path, skeleton, rig: JointRig, rotations: np.ndarray, timeline: Timeline) -> None:
        """A SkelAnimation at ``path`` turning the joints by ``rotations`` (k, j, 4) at the
        time codes 0 .. k - 1 (the timeline's keys), the source of the Skeleton at
        ``skeleton``."""
        Vt = self.Vt
        animation = self.UsdSkel.Animation.Define(self.stage, path)
        animation.CreateJointsAttr(Vt.TokenArray(joint_names(rig.parent)))
        animation.CreateTranslationsAttr(Vt.Vec3fArray.FromNumpy(rig.offset.astype(np.float32)))
        animation.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((rig.joints, 3), np.float16)))
        attribute = animation.CreateRotationsAttr()
        for code, frame in enumerate(rotations.astype(np.float32)):
            attribute.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(frame)), self.Usd.TimeCode(code))
        source = self.UsdSkel.BindingAPI.Apply(self.stage.GetPrimAtPath(skeleton))
        source.CreateAnimationSourceRel().SetTargets([path])
        stage = self.stage
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(timeline.keys - 1)
        stage.SetTimeCodesPerSecond(timeline.rate)
        stage.SetFramesPerSecond(timeline.rate)

    def extras(self, root, extras: SceneExtras, taken: set) -> None:
        """A scene's ground (a Mesh bound to its material), camera (a Camera) and light (a
        DistantLight) under ``root`` (see the module docstring)."""
        Gf = self.Gf
        if extras.ground is not None:
            path = root.AppendChild(self.name("Ground", taken))
            self.UsdGeom.Xform.Define(self.stage, path)
            [material] = self._materials(path.AppendChild("Materials"), [extras.ground.material],
                                         [ground_colour(extras.ground, self.colours)])
            vertices, normals, faces = ground_mesh(extras.ground, self.up)
            self._mesh(path.AppendChild("Mesh"), (vertices, normals.astype(np.float32), faces, np.zeros(2, np.int64)),
                       [material], np.array([[0, 1], [1, 1], [0, 0], [1, 0]]))
        if extras.camera is not None:
            camera = extras.camera
            eye, rotation = camera_pose(camera, self.up)
            prim = self.UsdGeom.Camera.Define(self.stage, root.AppendChild(self.name("Camera", taken)))
            prim.AddTransformOp().Set(Gf.Matrix4d(_row_major(rotation, eye).tolist()))
            vertical = CAMERA_APERTURE
            prim.CreateProjectionAttr(self.UsdGeom.Tokens.perspective)
            prim.CreateVerticalApertureAttr(vertical)
            prim.CreateHorizontalApertureAttr(vertical * camera.width / camera.height)
            prim.CreateFocalLengthAttr(vertical / (2 * np.tan(np.radians(camera.fov_y) / 2)))
            distance = float(np.linalg.norm(np.subtract(camera.target, camera.eye)))
            prim.CreateClippingRangeAttr(Gf.Vec2f(distance / 1000, distance * 1000))
        if extras.light is not None:
            light = self.UsdLux.DistantLight.Define(self.stage, root.AppendChild(self.name("Sun", taken)))
            light.AddTransformOp().Set(Gf.Matrix4d(_row_major(light_rotation(extras.light, self.up)).tolist()))
            light.CreateIntensityAttr(float(extras.light.intensity))

    def _materials(self, scope, names, colours=None) -> list:
        UsdShade, Sdf, Gf = self.UsdShade, self.Sdf, self.Gf
        self.UsdGeom.Scope.Define(self.stage, scope)
        taken: set = set()
        out = []
        colours = material_colours(names, self.colours) if colours is None else colours
        for name, rgb in zip(names, colours, strict=True):
            material = UsdShade.Material.Define(self.stage, scope.AppendChild(self.name(name, taken)))
            if material.GetPath().name != name:
                material.GetPrim().SetDisplayName(name)
            shader = UsdShade.Shader.Define(self.stage, material.GetPath().AppendChild("PreviewSurface"))
            shader.CreateIdAttr("UsdPreviewSurface")
            shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*rgb))
            shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
            shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
            material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
            if name in self.files:
                self._textured(material, shader, name)
            out.append(material)
        return out

    def _leaf_materials(self, scope, names, used) -> list:
        """Materials ``<name>_leaf`` (for the indices ``used`` of ``names``; None at the
        others) whose UsdPreviewSurface takes its diffuseColor from the Leaves' vertex
        primvar ``displayColor`` (each leaf's shade), the material's colour its fallback."""
        UsdShade, Sdf, Gf = self.UsdShade, self.Sdf, self.Gf
        taken = {child.GetName() for child in self.stage.GetPrimAtPath(scope).GetChildren()}
        rgb = material_colours(names)
        out: list = [None] * len(names)
        for index in sorted(used):
            material = UsdShade.Material.Define(self.stage, scope.AppendChild(self.name(f"{names[index]}_leaf", taken)))
            shader = UsdShade.Shader.Define(self.stage, material.GetPath().AppendChild("PreviewSurface"))
            shader.CreateIdAttr("UsdPreviewSurface")
            reader = UsdShade.Shader.Define(self.stage, material.GetPath().AppendChild("LeafColour"))
            reader.CreateIdAttr("UsdPrimvarReader_float3")
            reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("displayColor")
            reader.CreateInput("fallback", Sdf.ValueTypeNames.Float3).Set(Gf.Vec3f(*rgb[index]))
            shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(
                reader.CreateOutput("result", Sdf.ValueTypeNames.Float3))
            shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.8)
            shader.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(0.0)
            material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
            out[index] = material
        return out

    def _textured(self, material, surface, name: str) -> None:
        """Feed ``surface`` (the UsdPreviewSurface of ``material``) the baked maps of ``name``
        through UsdUVTexture readers of its files at ``st``: diffuseColor (sRGB; where no
        colour was given), normal (raw, scale 2 bias -1: tangent space) and displacement
        (raw, the height map times the shell of a segment of the median radius)."""
        UsdShade, Sdf = self.UsdShade, self.Sdf
        files, baked = self.files[name], self.textures.get(name)
        reader = UsdShade.Shader.Define(self.stage, material.GetPath().AppendChild("TexCoord"))
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
        feeds = {"basecolor": ("diffuseColor", Sdf.ValueTypeNames.Color3f, "rgb", "sRGB", None),
                 "normal": ("normal", Sdf.ValueTypeNames.Normal3f, "rgb", "raw", (2.0, -1.0)),
                 "height": ("displacement", Sdf.ValueTypeNames.Float, "r", "raw", (baked.amplitude, 0.0))}
        for kind, (png, _) in files.items():
            target, value_type, channel, space, scale_bias = feeds[kind]
            if kind == "basecolor" and self.colours is not None:
                continue
            texture = UsdShade.Shader.Define(self.stage, material.GetPath().AppendChild(f"{kind.capitalize()}Map"))
            texture.CreateIdAttr("UsdUVTexture")
            texture.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(f"./{png.name}"))
            texture.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
            texture.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(space)
            texture.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set("repeat")
            texture.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set("repeat")
            if scale_bias is not None:
                scale, bias = scale_bias
                texture.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(self.Gf.Vec4f(scale, scale, scale, 1.0))
                texture.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(self.Gf.Vec4f(bias, bias, bias, 0.0))
            output = texture.CreateOutput(channel, Sdf.ValueTypeNames.Float3 if channel == "rgb" else
                                          Sdf.ValueTypeNames.Float)
            surface.CreateInput(target, value_type).ConnectToSource(output)

    def _mesh(self, path, arrays, materials, uv=None, double_sided: bool = False):
        """A Mesh at ``path`` from ``arrays`` = (vertices, unit normals, faces, material per
        face), with ``uv`` as primitive ``st`` where given; the Mesh."""
        UsdGeom, Vt, UsdShade = self.UsdGeom, self.Vt, self.UsdShade
        vertices, normals, faces, face_material = arrays
        points = Vt.Vec3fArray.FromNumpy(vertices.astype(np.float32))
        geom = UsdGeom.Mesh.Define(self.stage, path)
        geom.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        geom.CreatePointsAttr(points)
        geom.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
        geom.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()))
        geom.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(normals))
        geom.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        if uv is not None:
            UsdGeom.PrimvarsAPI(geom).CreatePrimvar("st", self.Sdf.ValueTypeNames.TexCoord2fArray,
                                                    UsdGeom.Tokens.vertex).Set(
                Vt.Vec2fArray.FromNumpy(uv.astype(np.float32)))
        if double_sided:
            geom.CreateDoubleSidedAttr(True)
        geom.CreateExtentAttr(UsdGeom.Mesh.ComputeExtent(points))
        binding = UsdShade.MaterialBindingAPI.Apply(geom.GetPrim())
        used = np.unique(face_material)
        if len(used) == 1:
            binding.Bind(materials[int(used[0])])
            return geom
        for mat in used:
            indices = np.flatnonzero(face_material == mat).astype(np.int32)
            subset = binding.CreateMaterialBindSubset(materials[int(mat)].GetPath().name,
                                                      Vt.IntArray.FromNumpy(indices), UsdGeom.Tokens.face)
            UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(materials[int(mat)])
        binding.SetMaterialBindSubsetsFamilyType(UsdGeom.Tokens.partition)
        return geom

    def _curves(self, path, skeleton: Skeleton):
        """The skeleton's BasisCurves guide at ``path``; (the curves, the segment of each point)."""
        UsdGeom, Vt = self.UsdGeom, self.Vt
        points, widths, counts, segment = skeleton_curves(skeleton)
        points = Vt.Vec3fArray.FromNumpy((points @ up_rotation(self.up).T).astype(np.float32))
        widths = Vt.FloatArray.FromNumpy(widths.astype(np.float32))
        curves = UsdGeom.BasisCurves.Define(self.stage, path)
        curves.CreateTypeAttr(UsdGeom.Tokens.linear)
        curves.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
        curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(counts.astype(np.int32)))
        curves.CreatePointsAttr(points)
        curves.CreateWidthsAttr(widths)
        curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        curves.CreatePurposeAttr(UsdGeom.Tokens.guide)
        curves.CreateExtentAttr(UsdGeom.BasisCurves.ComputeExtent(points, widths))
        return curves, segment

    def instancer(self, path, plants: list[Plant], names: list[str]) -> None:
        UsdGeom, Vt = self.UsdGeom, self.Vt
        instancer = UsdGeom.PointInstancer.Define(self.stage, path)
        protos = path.AppendChild("Prototypes")
        self.UsdGeom.Scope.Define(self.stage, protos)
        targets, index, matrices = [], [], []
        for k, (plant, name) in enumerate(zip(plants, names, strict=True)):
            self.plant(protos.AppendChild(name), plant)
            targets.append(protos.AppendChild(name))
            index += [k] * plant.copies
            matrices.append(turn_placements(plant.matrices, self.up))
        t, q, s = similarity_trs(np.concatenate(matrices))
        instancer.CreatePrototypesRel().SetTargets(targets)
        instancer.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(np.array(index, dtype=np.int32)))
        instancer.CreatePositionsAttr(Vt.Vec3fArray.FromNumpy(t.astype(np.float32)))
        wxyz = np.ascontiguousarray(q[:, [3, 0, 1, 2]])
        instancer.CreateOrientationsAttr(Vt.QuathArray([self.Gf.Quath(*map(float, r)) for r in wxyz]))
        instancer.CreateOrientationsfAttr(Vt.QuatfArray([self.Gf.Quatf(*map(float, r)) for r in wxyz]))
        instancer.CreateScalesAttr(Vt.Vec3fArray.FromNumpy(np.repeat(s[:, None], 3, 1).astype(np.float32)))
        extent = instancer.ComputeExtentAtTime(self.Usd.TimeCode.Default(), self.Usd.TimeCode.Default())
        instancer.CreateExtentAttr(extent)

    def references(self, root, plants: list[Plant], names: list[str], taken: set) -> None:
        """Each copy an instanceable Xform referencing its plant under the abstract
        ``Prototypes``."""
        protos = root.AppendChild("Prototypes")
        self.stage.CreateClassPrim(protos)
        for plant, name in zip(plants, names, strict=True):
            self.plant(protos.AppendChild(name), plant)
            for k, matrix in enumerate(turn_placements(plant.matrices, self.up)):
                copy = self.UsdGeom.Xform.Define(self.stage, root.AppendChild(self.name(f"{name}_{k + 1}", taken)))
                copy.AddTransformOp().Set(self.Gf.Matrix4d(matrix.T.tolist()))
                copy.GetPrim().GetReferences().AddInternalReference(protos.AppendChild(name))
                copy.GetPrim().SetInstanceable(True)

    def swaying(self, root, plant: Plant, name: str, timeline: Timeline, taken: set) -> None:
        """A swaying plant's copies: its SkelRoot once under the abstract ``Prototypes``,
        each copy a SkelRoot referencing it (not instanceable: each holds its own
        animation) with its transform and, where it sways, its SkelAnimation ``Sway``, the
        source of its ``Joints``."""
        rig = joint_rig(plant.skeleton, plant.mesh, plant.sway, plant.leaves, self.up, plant.name)
        protos = root.AppendChild("Prototypes")
        self.stage.CreateClassPrim(protos)
        self.plant(protos.AppendChild(name), plant, rig)
        for k, matrix in enumerate(turn_placements(plant.matrices, self.up)):
            copy = self.UsdSkel.Root.Define(self.stage, root.AppendChild(self.name(f"{name}_{k + 1}", taken)))
            copy.AddTransformOp().Set(self.Gf.Matrix4d(matrix.T.tolist()))
            copy.GetPrim().GetReferences().AddInternalReference(protos.AppendChild(name))
            if plant.sway.copy_moves(k):
                rotations = copy_rotations(plant.skeleton, plant.sway, k, plant.matrices[k], timeline.times,
                                           self.up, rig.joints)
                self.sway(copy.GetPath().AppendChild("Sway"), copy.GetPath().AppendChild("Joints"), rig, rotations,
                          timeline)


def write_usd(plants: list[Plant], path: str | Path, *, up: str = "y", colours: Colours = None,
              instancing: str = "nodes", unit: float = 1.0, name: str | None = None,
              progress: Progress = None, animation: Timeline | None = None,
              extras: SceneExtras | None = None, textures: Textures | None = None) -> list[Path]:
    """Write ``plants`` as a USD stage at ``path`` (see the module docstring); with
    ``animation``, the plants that sway as UsdSkel skeletons with their SkelAnimations;
    with ``extras``, the scene's ground, camera and light; with ``textures``, the relief's
    maps as PNG files beside it (``<stem>_<material>_<kind>.png``) that each material's
    UsdPreviewSurface reads through UsdUVTexture."""
    path = Path(path)
    if not unit > 0:
        raise ExportError(f"{path}: the unit must be a positive number of metres, got {unit!r}")
    files = {} if textures is None else texture_files(path, textures, [n for p in plants for n in
                                                                        p.mesh.material_names], v_up=True)
    writer = _Writer(up, unit, colours, textures, files)
    taken: set = set()
    stem = name or path.name.split(".")[0]
    swaying = [animation is not None and p.sway is not None and p.sway.moves for p in plants]
    if len(plants) == 1 and plants[0].matrices is None:
        root = writer.root(writer.name(plants[0].name or stem, taken))
        _write_in_place(writer, root, plants[0], animation if swaying[0] else None)
        taken = {"Materials", "Mesh", "Leaves", "Skeleton", "Joints", "Sway"}
    else:
        root = writer.root(writer.name(stem, taken))
        reserved = {"Plants", "Prototypes"}
        names = [writer.name(p.name, reserved) for p in plants]
        taken = set(names) | reserved
        still = [k for k, moves in enumerate(swaying) if not moves]
        if still and instancing == "gpu":
            writer.instancer(root.AppendChild("Plants"), [plants[k] for k in still], [names[k] for k in still])
        elif still:
            writer.references(root, [plants[k] for k in still], [names[k] for k in still], taken)
        for k in np.flatnonzero(swaying):
            writer.swaying(root, plants[k], names[k], animation, taken)
    if extras is not None:
        writer.extras(root, extras, taken)
    if progress is not None:
        progress("write", 1, 1)

    def export(tmp):
        if not writer.stage.GetRootLayer().Export(str(tmp)):
            raise OSError(f"usd-core could not write {tmp.name}")
    pngs = png_writes(files)
    return write_all_atomically([*pngs, (path, export)], ExportError)


def _write_in_place(writer: _Writer, path, plant: Plant, animation: Timeline | None) -> None:
    """One plant where it stands (a grammar, a skeleton, a scene written in place): an
    Xform, or with ``animation`` a SkelRoot with its SkelAnimation ``Sway``."""
    if animation is None:
        writer.plant(path, plant)
        return
    rig = joint_rig(plant.skeleton, plant.mesh, plant.sway, plant.leaves, writer.up, plant.name)
    writer.plant(path, plant, rig)
    writer.sway(path.AppendChild("Sway"), path.AppendChild("Joints"), rig,
                copy_rotations(plant.skeleton, plant.sway, 0, None, animation.times, writer.up, rig.joints), animation)
