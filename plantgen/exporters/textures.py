"""The relief's textures in the files: which maps a model's materials get, their PNG bytes,
and the companion files' names (:func:`bake_textures`, :func:`texture_files`).

:func:`bake_textures` bakes, for each material name with relief that the plants' meshes
use, the maps of :mod:`plantgen.geometry.meshes.textures` (base colour, tangent-space normal,
height), the normal map at the material's median aspect over every plant's faces. A mesh
whose vertices already carry the relief (GS+R, ``displaced``) gets the base colour only:
a normal map on top of its tilted normals would count the relief twice, and a height map
would displace it twice.

PNG bytes come from :func:`plantgen.images.png_bytes` (Pillow, as every image plantgen
writes). Orientation: glTF's texture coordinates
have v = 0 at the image's top row, as plantgen's maps lay out v (row 0 at v = 0), so glTF
takes the maps as they are; OBJ and USD put v = 0 at the bottom row, so their images are
flipped upside down, and the normal map's green channel (its "up in the image") negated.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry.meshes.textures import MaterialTextures, bake_material, mesh_aspects, weighted_median
from ..images import png_bytes

__all__ = ["KINDS", "Textures", "bake_textures", "bucket_name", "png_writes", "split_by_aspect",
           "texture_files", "texture_image"]

#: The maps, in the order files list them: base colour (sRGB), normal (linear), height (linear).
KINDS = ("basecolor", "normal", "height")


@dataclass(frozen=True, eq=False)
class Textures:
    """The baked maps of a model by material name (:class:`~plantgen.geometry.meshes.textures.
    MaterialTextures`), and which kinds (:data:`KINDS`) the files carry: all three, or the
    base colour only for a displaced (GS+R) mesh."""

    materials: dict
    kinds: tuple[str, ...] = KINDS

    def get(self, name: str) -> MaterialTextures | None:
        return self.materials.get(name)

    def __len__(self) -> int:
        return len(self.materials)


def bake_textures(meshes, *, displaced: bool = False, bases: dict | None = None) -> Textures:
    """The textures of every relief material the tessellated ``meshes`` (an iterable of
    :class:`~plantgen.geometry.meshes.mesh.TessellatedMesh`, None skipped) use, keyed by material
    name; each normal map at the area-weighted median aspect of that material's faces over
    all the meshes. ``displaced``: the meshes carry their relief (GS+R): base colour only.
    ``bases``: {name: material} for names that stand for another material's relief (the
    aspect buckets of :func:`split_by_aspect`)."""
    faces: dict[str, list] = {}
    for mesh in meshes:
        if mesh is None:
            continue
        for index, (aspect, area, radius) in mesh_aspects(mesh).items():
            faces.setdefault(mesh.material_names[index], []).append((aspect, area, radius))
    out = {}
    for name, chunks in faces.items():
        aspect, area, radius = (np.concatenate(c) for c in zip(*chunks, strict=True))
        baked = bake_material(name, aspect, area, weighted_median(radius, area) if len(radius) else 1.0,
                              base=(bases or {}).get(name))
        if baked is not None:
            out[name] = baked
    return Textures(out, ("basecolor",) if displaced else KINDS)


def bucket_name(name: str, aspect: float) -> str:
    """The material name of ``name``'s rows whose normal map is baked at ``aspect``."""
    return f"{name} (r/L {aspect:.3g})"


#: The most normal maps ``--aspect-step`` may split one material into.
MAX_ASPECT_BUCKETS = 16


def split_by_aspect(plants, step: float) -> tuple[list, dict]:
    """``plants`` with each relief material's rows split by their aspect ρ/L (radius over
    texture period) into buckets ``step`` apart in ratio around the material's median over
    every plant: rows within a factor √step of the median keep the material, the others go
    to a material :func:`bucket_name` of their bucket's aspect (appended to the mesh's
    names, so the leaves' indices stand), each with its own normal map. Returns the plants
    and {bucket name: material} (``bases`` of :func:`bake_textures`)."""
    from ..geometry.meshes.textures import row_aspects
    from ..geometry.skeletons.relief import default_shell

    rows = [None if p.mesh is None else row_aspects(p.mesh) for p in plants]
    gathered: dict[str, list] = {}
    for plant, r in zip(plants, rows, strict=True):
        if r is None:
            continue
        row_names = np.asarray(plant.mesh.material_names)[plant.mesh.material]
        for name in set(row_names.tolist()):
            use = (row_names == name) & (r[1] > 0)
            if default_shell(name) > 0 and use.any():
                gathered.setdefault(name, []).append((r[0][use], r[1][use]))
    median = {name: weighted_median(np.concatenate([a for a, _ in c]), np.concatenate([w for _, w in c]))
              for name, c in gathered.items()}
    for name, c in gathered.items():     # the maps counted before any is baked
        aspect = np.concatenate([a for a, _ in c])
        k = np.rint(np.log(aspect / median[name]) / np.log(step))
        buckets = len(np.unique(k[np.isfinite(k)]))
        if buckets > MAX_ASPECT_BUCKETS:
            from .formats import ExportError

            raise ExportError(f"--aspect-step {step!r} splits material {name!r} into {buckets:,} normal maps, "
                              f"over {MAX_ASPECT_BUCKETS} (give a larger step, e.g. 2)")
    bases: dict[str, str] = {}
    out = []
    for plant, r in zip(plants, rows, strict=True):
        out.append(plant if r is None else _split_plant(plant, r, median, step, bases))
    return out, bases


def _split_plant(plant, row_aspect, median: dict, step: float, bases: dict):
    """One plant of :func:`split_by_aspect`."""
    from dataclasses import replace

    names = list(plant.mesh.material_names)
    material = plant.mesh.material.copy()
    aspect, area = row_aspect
    for row in np.flatnonzero(area > 0):
        name = plant.mesh.material_names[material[row]]
        if name not in median:
            continue
        k = int(np.rint(np.log(aspect[row] / median[name]) / np.log(step)))
        if k == 0:
            continue
        bucket = bucket_name(name, median[name] * step ** k)
        bases[bucket] = name
        if bucket not in names:
            names.append(bucket)
        material[row] = names.index(bucket)
    if len(names) == len(plant.mesh.material_names):
        return plant
    return replace(plant, mesh=replace(plant.mesh, material=material, material_names=tuple(names)))


def texture_image(textures: MaterialTextures, kind: str, *, v_up: bool = False) -> np.ndarray:
    """The map ``kind`` of :data:`KINDS` as an image, row 0 at the top: as baked (glTF), or
    for formats whose v = 0 is the bottom row (``v_up``: OBJ, USD) flipped, the normal
    map's green negated."""
    image = {"basecolor": textures.base_colour, "normal": textures.normal, "height": textures.height}[kind]
    if not v_up:
        return image
    image = image[::-1].copy()
    if kind == "normal":
        image[..., 1] = 255 - image[..., 1]
    return image


def file_stem(name: str) -> str:
    """A material name as part of a file name: runs of anything but letters, digits, ``-``
    and ``_`` become ``_``."""
    return re.sub(r"[^A-Za-z0-9_-]+", "_", name).strip("_") or "material"


def texture_files(path: str | Path, textures: Textures, names, *, v_up: bool) -> dict:
    """The companion PNGs of ``path``'s export: {material name: {kind: (file path, PNG
    bytes)}} for each of ``names`` that has textures, named ``<stem>_<material>_<kind>.png``
    beside ``path`` (material names made file-safe and unique)."""
    path = Path(path)
    stem = path.name.split(".")[0] or "plant"
    out: dict = {}
    taken: set = set()
    shared: dict = {}          # an aspect bucket's base colour and height are its material's
    for name in dict.fromkeys(names):
        baked = textures.get(name)
        if baked is None:
            continue
        base, k = file_stem(name), 1
        while base in taken:
            k += 1
            base = f"{file_stem(name)}_{k}"
        taken.add(base)
        out[name] = {}
        for kind in textures.kinds:
            key = (baked.base or name, kind) if kind != "normal" else (name, kind)
            if key not in shared:
                shared[key] = (path.with_name(f"{stem}_{base}_{kind}.png"), png_bytes(texture_image(baked, kind,
                                                                                                     v_up=v_up)))
            out[name][kind] = shared[key]
    return out


def png_writes(files: dict) -> list:
    """The (path, write) pairs of :func:`texture_files`' PNGs, each file once."""
    unique = {png: blob for kinds in files.values() for png, blob in kinds.values()}
    return [(png, lambda tmp, blob=blob: Path(tmp).write_bytes(blob)) for png, blob in unique.items()]
