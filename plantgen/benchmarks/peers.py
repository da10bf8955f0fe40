"""plantgen's tracers beside a peer's: the compiled CPU tracer (numba, float64), the GLSL
tracer (``plantgen.gl.trace``: RT's traversal, on llvmpipe where there is no GPU) and
Mitsuba 3 (variant ``llvm_ad_rgb``: Embree on the CPU) on the same rays, interleaved, in
one run.

Run: ``python -m plantgen.benchmarks.peers [--scene forest_cut,forest] [--size 320x240]
[--scan-step 2] [--rounds 3] [--no-gl] [--out peers.md]``; issue 44's run is ``--size
1024x768 --scan-step 0.5``. It needs the ``peers`` extra (Mitsuba 3; without it one line
says so).

Scenes: the looks bench's cut of the forest (``forest_cut``) and the whole shipped
``forest``. Rays (those of :mod:`plantgen.benchmarks.cpu_trace`): the primary rays of the
scene's camera at ``--size`` (closest hit); the shadow rays of those that hit, from
plantgen's float64 hit points towards the sun (any hit, counted from 1e-4: Mitsuba's
rays start 1e-4 along instead, it has no t_min); the beams of a terrestrial scanner at
2,1.5,10, every ``--scan-step`` degrees over the whole sphere (closest hit).

What each tracer is given, built from the same skinned frusta and leaf triangles:

- plantgen CPU: the scene's two-level BVH (each distinct plant's tree, a top level over
  the copies) walked by :mod:`plantgen.geometry.rays.native_trace`;
- plantgen RT: the same, uploaded (:func:`plantgen.gl.trace.target_bvh`), each batch of
  rays traced by :func:`plantgen.gl.trace.trace_target` (its upload and read-back of the
  rays included);
- Mitsuba curves: each frustum a two-point ``linearcurve`` segment from its base to its
  top with its two radii (round ends, no oblique planes: the nearest primitive Mitsuba
  has), the leaves a triangle mesh, in a ``shapegroup`` a distinct plant, an
  ``instance`` a copy with its placement as ``to_world``;
- Mitsuba triangles: the GS mesh at m = 0 (16 triangles a frustum, caps on open ends:
  :func:`plantgen.geometry.meshes.mesh.tessellate`) and the leaves, instanced the same way.

Mitsuba's rays are ``mi.Ray3f`` made from the same numpy arrays once (float32), traced by
``scene.ray_intersect_preliminary`` (the distance and primitive, what plantgen's tracers
return) and ``scene.ray_test`` for the shadow rays, each result read back into numpy.
``scene.ray_intersect``, which adds the full surface interaction, is not timed: on the
forest it took 26 to 40 s a call for 4,800 rays here, every call, not only the first
(Mitsuba 3.9.1; apparently Dr.Jit records the instanced shapes' interaction code anew
each time).

*build s*: from the distinct plants' primitives to a traceable scene: plantgen's BVH (and
the CPU tracer's gathered arrays, or RT's upload); Mitsuba's shapes made from float32 arrays
and ``mi.load_dict`` (its Embree build). *peak MiB*: how far the process's peak resident
memory rose from just before the build through the tracer's warm-up traces (its compilers'
and drivers' memory included: Dr.Jit's LLVM kernels, llvmpipe's shader; the numba kernels
are loaded from numba's cache before; Linux only). Then every ray kind is traced by each
tracer in turn, ``--rounds`` times (the median; rays/s of wall time, and of the process's
CPU time: every thread's, what other jobs change least). Agreement with plantgen's float64
tracer: the share of primary rays where a tracer's hit or miss is its, the median absolute
difference of their depths where both hit (scene units, metres), and the share of shadow
rays it finds blocked or free alike.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import gc
import os
import re
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ..errors import PlantgenError, missing_extra
from ..geometry.meshes.mesh import tessellate
from ..geometry.rays import native_trace
from .arguments import image_size, report
from .cpu_trace import SCANNER, SHADOW_T_MIN, scan_rays, scene_rays, shadow_rays
from .scan import machine

__all__ = ["KINDS", "SCENES", "VARIANT", "INSTALL", "load_mitsuba", "mitsuba_description", "measure_scene",
           "markdown", "main"]

#: The scenes of issue 44.
SCENES = ("forest_cut", "forest")
#: The ray kinds, in table order.
KINDS = ("primary", "shadow", "scan")
#: Mitsuba 3's variant: its CPU backend (Dr.Jit's LLVM JIT, Embree for the rays).
VARIANT = "llvm_ad_rgb"
#: The one line a run without the ``peers`` extra prints.
INSTALL = missing_extra("the peer benchmark (Mitsuba 3)", "peers")
NUMBA, GLSL, CURVES, TRIANGLES = ("plantgen CPU (numba, float64)", "plantgen RT (GLSL)", "Mitsuba 3 curves",
                                  "Mitsuba 3 triangles (m = 0)")


def load_mitsuba():
    """(mitsuba, drjit) with :data:`VARIANT` set; a :class:`~plantgen.errors.PlantgenError`
    of one line where the extra is missing or its LLVM backend does not run here."""
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError:
        raise PlantgenError(INSTALL) from None
    try:
        mi.set_variant(VARIANT)
        if not dr.has_backend(dr.JitBackend.LLVM):
            raise RuntimeError("Dr.Jit finds no LLVM library (DRJIT_LIBLLVM_PATH)")
    except (ImportError, RuntimeError, AttributeError) as exc:
        raise PlantgenError(f"Mitsuba 3's {VARIANT} variant does not run here: {str(exc).splitlines()[0]}") from None
    return mi, dr


# ----------------------------------------------------------------------------- memory
def _status_kib(field: str) -> int:
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return 0
    m = re.search(rf"^{field}:\s+(\d+)", text, re.M)
    return int(m.group(1)) if m else 0


def _reset_peak() -> bool:
    """Hand freed memory back to the system (glibc's ``malloc_trim``, after a garbage
    collection: what an earlier scene or tracer freed is not reused unseen) and reset
    the process's peak resident size to its current one (Linux' ``clear_refs`` 5).
    False where the peak cannot be reset."""
    gc.collect()
    with contextlib.suppress(OSError, AttributeError):         # not glibc: freed memory stays
        ctypes.CDLL(None).malloc_trim(0)
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False


# ----------------------------------------------------------------------------- Mitsuba's scenes
def _curve_arrays(frusta) -> tuple[np.ndarray, np.ndarray]:
    """Each row a two-point linear curve, base to top with its radii: the control points
    flat (x, y, z, r each) and the segments' first points."""
    n = len(frusta)
    points = np.empty((n, 2, 4), np.float32)
    points[:, 0, :3], points[:, 0, 3] = frusta.base, frusta.r1
    points[:, 1, :3] = frusta.base + frusta.axis * frusta.length[:, None]
    points[:, 1, 3] = frusta.r2
    return points.reshape(-1), np.arange(0, 2 * n, 2, dtype=np.uint32)


def _triangle_arrays(target) -> tuple[np.ndarray, np.ndarray]:
    """A plant's GS mesh at m = 0 and its leaf triangles: vertices (V, 3), faces (F, 3)."""
    parts_v, parts_f, base = [], [], 0
    if target.rows:
        mesh = tessellate(target.frusta, 0)
        parts_v.append(mesh.vertices)
        parts_f.append(mesh.faces)
        base = len(mesh.vertices)
    if len(target.triangles):
        parts_v.append(target.triangles.reshape(-1, 3))
        parts_f.append(base + np.arange(3 * len(target.triangles)).reshape(-1, 3))
    return (np.concatenate(parts_v).astype(np.float32), np.concatenate(parts_f).astype(np.uint32))


def _plant_arrays(target, kind: str) -> list:
    """(what, arrays) of a distinct plant's shapes: ``kind`` "curves" (its rows as curves,
    its leaves as a mesh) or "triangles" (one mesh)."""
    if kind == "triangles":
        return [("mesh", _triangle_arrays(target))] if len(target) else []
    out = [("curves", _curve_arrays(target.frusta))] if target.rows else []
    if len(target.triangles):
        out.append(("mesh", (target.triangles.reshape(-1, 3).astype(np.float32),
                             np.arange(3 * len(target.triangles), dtype=np.uint32).reshape(-1, 3))))
    return out


def _shape(mi, what: str, arrays, stub: Path, name: str):
    """A Mitsuba shape from float32 arrays: a ``linearcurve`` (loaded from a one-segment
    stub file, its control points then replaced) or a ``Mesh``."""
    if what == "curves":
        points, segments = arrays
        shape = mi.load_dict({"type": "linearcurve", "filename": str(stub)})
        params = mi.traverse(shape)
        params["control_points"] = mi.Float(points)
        params["segment_indices"] = mi.UInt32(segments)
        params["control_point_count"] = len(points) // 4
        params.update()
        return shape
    vertices, faces = arrays
    shape = mi.Mesh(name, len(vertices), len(faces))
    params = mi.traverse(shape)
    params["vertex_positions"] = mi.Float(np.ascontiguousarray(vertices).reshape(-1))
    params["faces"] = mi.UInt32(np.ascontiguousarray(faces).reshape(-1))
    params.update()
    return shape


def mitsuba_description(mi, target, kind: str, stub: Path, arrays=None) -> dict:
    """The ``mi.load_dict`` description of a :class:`~plantgen.geometry.rays.scan.SceneTarget`:
    a ``shapegroup`` a distinct plant (``kind`` "curves" or "triangles"), an ``instance``
    a copy. ``arrays``: each plant's :func:`_plant_arrays`, made beforehand (untimed)."""
    arrays = arrays if arrays is not None else [_plant_arrays(t, kind) for t in target.targets]
    scene = {"type": "scene"}
    for k, (shapes, matrices) in enumerate(zip(arrays, target.matrices, strict=True)):
        if not shapes or not len(matrices):
            continue
        scene[f"plant{k}"] = {"type": "shapegroup", **{f"{what}{i}": _shape(mi, what, a, stub, f"plant{k}_{i}")
                                                       for i, (what, a) in enumerate(shapes)}}
        for c, matrix in enumerate(matrices):
            scene[f"copy{k}_{c}"] = {"type": "instance", "shape": {"type": "ref", "id": f"plant{k}"},
                                     "to_world": mi.ScalarTransform4f(np.asarray(matrix, np.float64).tolist())}
    return scene


# ----------------------------------------------------------------------------- the tracers
class _Plantgen:
    """plantgen's CPU (``gl`` False) or GLSL tracer on a fresh copy of the target (its
    BVH built anew, so that the build is its own)."""

    def __init__(self, target, gl: bool):
        self.target = replace(target, targets=tuple(replace(t) for t in target.targets))
        self.gl = gl

    def build(self) -> None:
        if self.gl:
            from ..gl.trace import target_bvh

            target_bvh(self.target)
        else:
            _ = self.target.bvh, self.target.native

    def trace(self, origins, dirs, any_hit: bool, t_min: float) -> np.ndarray:
        if self.gl:
            from ..gl.trace import trace_target

            return trace_target(self.target, origins, dirs, any_hit=any_hit, t_min=t_min)[0]
        return self.target.first_hits(origins, dirs, any_hit=any_hit, t_min=t_min, native=True)[0]


class _Mitsuba:
    """A Mitsuba scene of the target's plants as curves or triangles; rays converted once."""

    def __init__(self, mi, dr, target, kind: str, stub: Path):
        self.mi, self.dr, self.target, self.kind, self.stub = mi, dr, target, kind, stub
        self.arrays = [_plant_arrays(t, kind) for t in target.targets]
        self.scene, self.rays = None, {}

    def build(self) -> None:
        self.scene = self.mi.load_dict(mitsuba_description(self.mi, self.target, self.kind, self.stub, self.arrays))

    def trace(self, origins, dirs, any_hit: bool, t_min: float) -> np.ndarray:
        key = (id(origins), any_hit)
        if key not in self.rays:                 # the peer's own rays, made once (untimed after the warm-up)
            o = np.ascontiguousarray((origins + t_min * dirs).T, np.float32)
            d = np.ascontiguousarray(dirs.T, np.float32)
            self.rays[key] = self.mi.Ray3f(self.mi.Point3f(o), self.mi.Vector3f(d))
        ray = self.rays[key]
        if any_hit:
            hit = np.asarray(self.scene.ray_test(ray, coherent=False))
            return np.where(hit, 1.0, np.inf)
        t = np.asarray(self.scene.ray_intersect_preliminary(ray, coherent=False).t, np.float64)
        return np.where(t < 3e38, t + t_min, np.inf)


def _ready(tracer, rays: dict) -> dict:
    """Build ``tracer`` and trace every kind once (the warm-up): build seconds, peak MiB
    over both, and the warm-up's distances."""
    reset = _reset_peak()
    before = _status_kib("VmRSS")
    t0 = time.perf_counter()
    tracer.build()
    build = time.perf_counter() - t0
    out = {kind: tracer.trace(*r) for kind, r in rays.items()}
    peak = (_status_kib("VmHWM") - before) / 1024 if reset else float("nan")
    return {"build_s": build, "peak_mib": peak, "t": out}


def _agreement(reference: np.ndarray, t: np.ndarray) -> tuple[float, float]:
    a, b = np.isfinite(reference), np.isfinite(t)
    both = a & b
    diff = float(np.median(np.abs(t[both] - reference[both]))) if both.any() else float("nan")
    return float((a == b).mean()) if len(a) else 1.0, diff


def _rays(scene: str, size, scan_step: float) -> tuple:
    """(staging, target, {kind: (origins, dirs, any_hit, t_min)}): the shadow rays start at
    plantgen's float64 hits of the primary rays."""
    staging, target, O, D = scene_rays(scene, size)
    t, _ = target.first_hits(O, D, native=True)
    so, sd = shadow_rays(staging, O, D, t)
    scan_o, scan_d = scan_rays(target, scan_step)
    return staging, target, {"primary": (O, D, False, 0.0), "shadow": (so, sd, True, SHADOW_T_MIN),
                             "scan": (scan_o, scan_d, False, 0.0)}


def _tracers(target, mitsuba, gl: bool, stub: Path, say) -> tuple[dict, dict]:
    """The tracers to time by name, and the notes of those that could not run."""
    mi, dr = mitsuba
    tracers, notes = {NUMBA: _Plantgen(target, gl=False)}, {}
    if gl:
        from ..gl.context import GLContextError, renderer_name

        try:
            notes["renderer"] = renderer_name()
            tracers[GLSL] = _Plantgen(target, gl=True)
        except GLContextError as exc:
            notes[GLSL] = f"no GL context: {str(exc).splitlines()[0]}"
            say(notes[GLSL])
    tracers[CURVES] = _Mitsuba(mi, dr, target, "curves", stub)
    tracers[TRIANGLES] = _Mitsuba(mi, dr, target, "triangles", stub)
    return tracers, notes


def measure_scene(scene: str, mitsuba, size=(320, 240), scan_step: float = 2.0, rounds: int = 3, gl: bool = True,
                  say=print) -> dict:
    """Every tracer on ``scene``'s rays (module docstring); ``mitsuba``: :func:`load_mitsuba`'s pair."""
    native_trace.warm_up()
    staging, target, rays = _rays(scene, size, scan_step)
    with tempfile.TemporaryDirectory() as tmp:
        stub = Path(tmp) / "stub.txt"
        stub.write_text("0 0 0 1\n0 1 0 1\n")
        tracers, notes = _tracers(target, mitsuba, gl, stub, say)
        ready = {}
        for name, tracer in tracers.items():
            ready[name] = _ready(tracer, rays)
            say(f"{scene}, {name}: build {ready[name]['build_s']:.2f} s, peak {ready[name]['peak_mib']:.0f} MiB")
        times = {(name, kind): ([], []) for name in tracers for kind in KINDS}
        for _ in range(rounds):
            for kind in KINDS:
                for name, tracer in tracers.items():
                    c, t0 = time.process_time(), time.perf_counter()
                    tracer.trace(*rays[kind])
                    times[name, kind][0].append(time.perf_counter() - t0)
                    times[name, kind][1].append(time.process_time() - c)
    reference = ready[NUMBA]["t"]
    rows = {}
    for name in tracers:
        rate, rate_cpu = ({kind: len(rays[kind][0]) / max(statistics.median(times[name, kind][i]), 1e-9)
                           for kind in KINDS} for i in (0, 1))
        agree, diff = _agreement(reference["primary"], ready[name]["t"]["primary"])
        rows[name] = {"build_s": ready[name]["build_s"], "peak_mib": ready[name]["peak_mib"], "rate": rate,
                      "rate_cpu": rate_cpu,
                      "agree": agree, "depth_diff": diff,
                      "agree_shadow": _agreement(reference["shadow"], ready[name]["t"]["shadow"])[0]}
        say(f"{scene}, {name}: " + ", ".join(f"{k} {v:,.0f}/s" for k, v in rate.items()) + f"; agrees {agree:.4f}")
    mi, dr = mitsuba
    return {"scene": scene, "size": tuple(size), "scan_step": scan_step, "rounds": rounds, "rows": rows,
            "notes": notes, "counts": {kind: len(rays[kind][0]) for kind in KINDS},
            "copies": sum(len(m) for m in target.matrices), "plants": len(target.targets),
            "primitives": sum(len(t) for t in target.targets), "hits": float(np.isfinite(reference["primary"]).mean()),
            "shadowed": float(np.isfinite(reference["shadow"]).mean()),
            "versions": f"Mitsuba {mi.__version__}, Dr.Jit {dr.__version__} ({VARIANT}, {_jit_threads(dr)} threads)",
            "threads": _numba_threads(), "machine": machine()}


def _jit_threads(dr) -> int:
    return int(dr.thread_count()) if hasattr(dr, "thread_count") else os.cpu_count() or 1


def _numba_threads() -> int:
    import numba

    return numba.get_num_threads()


# ----------------------------------------------------------------------------- the table
def _cell(rate: float, curves: float | None, triangles: float | None) -> str:
    ratios = " / ".join(f"{rate / peer:.2f}" for peer in (curves, triangles) if peer)
    return f"{rate:,.0f} ({ratios})" if ratios else f"{rate:,.0f}"


def _heading(r: dict) -> list[str]:
    w, h = r["size"]
    c = r["counts"]
    return [f"## {r['scene']}: {r['copies']:,} copies of {r['plants']} plants, {r['primitives']:,} distinct "
            f"primitives; {w}x{h}", "",
            f"Rays: {c['primary']:,} primary (closest hit, {r['hits']:.3f} hit), {c['shadow']:,} shadow rays "
            f"towards the sun from their hits (any hit, {r['shadowed']:.3f} blocked), {c['scan']:,} scan beams "
            f"from {SCANNER} at {r['scan_step']}° (closest hit). Rays/s of wall time, the median of "
            f"{r['rounds']} interleaved rounds after a warm-up; in brackets the ratio to Mitsuba's curves / "
            "triangles.", "",
            "| tracer | build s | peak MiB | primary rays/s | shadow rays/s | scan rays/s | primary: hit or miss "
            "as plantgen's | its median abs. depth diff. | shadow: blocked or not as plantgen's |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]


def _cells(r: dict, row: dict, key: str) -> str:
    peers = r["rows"].get(CURVES), r["rows"].get(TRIANGLES)
    return " | ".join(_cell(row[key][k], *(p[key][k] if p else None for p in peers)) for k in KINDS)


def markdown(results: list[dict]) -> str:
    """The tables: a section a scene."""
    lines = []
    for r in results:
        lines += _heading(r)
        for name, row in r["rows"].items():
            same = ("(reference)", "", "(reference)") if name == NUMBA else \
                (f"{row['agree']:.4f}", f"{row['depth_diff']:.1e}", f"{row['agree_shadow']:.4f}")
            lines.append(f"| {name} | {row['build_s']:.2f} | {row['peak_mib']:,.0f} | {_cells(r, row, 'rate')} | "
                         f"{' | '.join(same)} |")
        lines += ["", "The same rounds in the process's CPU time (every thread: numba's, Dr.Jit's, llvmpipe's), "
                  "what the other jobs on a shared machine change least:", "",
                  "| tracer | primary rays/s of CPU | shadow rays/s of CPU | scan rays/s of CPU |",
                  "|---|---:|---:|---:|"]
        lines += [f"| {name} | {_cells(r, row, 'rate_cpu')} |" for name, row in r["rows"].items()]
        lines += ["", f"GL renderer: {r['notes'].get('renderer', r['notes'].get(GLSL, 'not run (--no-gl)'))}; "
                  f"{r['versions']}; numba {r['threads']} threads. Machine: {r['machine']} (at the end). "
                  f"{datetime.now(UTC).strftime('%Y-%m-%d %H:%M UTC')}.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default=",".join(SCENES), help="comma-separated scenes (forest_cut: the cut)")
    parser.add_argument("--size", default="320x240", type=image_size, help="primary rays (issue 44: 1024x768)")
    parser.add_argument("--scan-step", default=2.0, type=float, help="degrees between beams (issue 44: 0.5)")
    parser.add_argument("--rounds", default=3, type=int)
    parser.add_argument("--no-gl", action="store_true", help="leave out plantgen's GLSL tracer")
    parser.add_argument("--out", default=None, type=Path)
    a = parser.parse_args(argv)
    try:
        mitsuba = load_mitsuba()
    except PlantgenError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    results = [measure_scene(s.strip(), mitsuba, a.size, a.scan_step, a.rounds, not a.no_gl)
               for s in a.scene.split(",") if s.strip()]
    return report(markdown(results), a.out)


if __name__ == "__main__":
    raise SystemExit(main())
