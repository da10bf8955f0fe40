"""Node.js packages the export tests run as independent readers: the Khronos glTF validator
(``gltf-validator``) and three.js (``three``, its GLTFLoader).

CI installs both with ``npm install --prefix .ci/node gltf-validator three``; where they
are not installed a test installs them into the user cache (needs the npm registry).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

needs_node = pytest.mark.skipif(shutil.which("node") is None,
                                reason="Node.js is not installed: the Khronos glTF validator and three.js "
                                       "are Node packages")

VALIDATE_JS = r"""
const validator = require('gltf-validator');
const fs = require('fs');
const path = require('path');
const file = process.argv[1];
const external = (uri) => new Promise((resolve, reject) => {
  try { resolve(new Uint8Array(fs.readFileSync(path.join(path.dirname(file), decodeURIComponent(uri))))); }
  catch (e) { reject(String(e)); }
});
validator.validateBytes(new Uint8Array(fs.readFileSync(file)),
                        {maxIssues: 1000, uri: file, externalResourceFunction: external})
  .then(report => console.log(JSON.stringify(report.issues)))
  .catch(err => { console.error(String(err)); process.exit(3); });
"""

# Node has no image decoder: every script below gives three.js's ImageBitmapLoader one that
# fetches an image's bytes (a .glb's buffer view, or the file beside a .gltf) and reads the
# PNG header's width and height (what the scripts report); the rest is three.js's own.
NODE_IMAGES = r"""
globalThis.self = globalThis;
globalThis.createImageBitmap = async () => { throw new Error('not used'); };
THREE.ImageBitmapLoader.prototype.load = function (url, onLoad, onProgress, onError) {
  const bytes = url.startsWith('blob:') ? fetch(url).then((r) => r.arrayBuffer())
    : Promise.resolve(fs.readFileSync(path.join(path.dirname(process.argv[2]), decodeURIComponent(url))));
  bytes.then((b) => {
    const v = new DataView(b.buffer ? b.buffer.slice(b.byteOffset, b.byteOffset + b.byteLength) : b);
    onLoad({width: v.getUint32(16), height: v.getUint32(20), close() {}});
  }).catch(onError);
};
"""


# What every three.js script begins with: Node's modules, three.js and its GLTFLoader from
# THREE_MODULES, the image shim above, and the file's bytes (its first argument).
THREE_PRELUDE = """import fs from 'fs';
import path from 'path';
import { pathToFileURL } from 'url';
const modules = process.env.THREE_MODULES;
const THREE = await import(pathToFileURL(path.join(modules, 'three/build/three.module.js')).href);
const { GLTFLoader } = await import(pathToFileURL(path.join(modules,
  'three/examples/jsm/loaders/GLTFLoader.js')).href);
""" + NODE_IMAGES + """
const buf = fs.readFileSync(process.argv[2]);"""


def three_script(script: str) -> str:
    """A three.js script with :data:`THREE_PRELUDE` in place."""
    return script.replace("${THREE_PRELUDE}", THREE_PRELUDE)


# three.js's GLTFLoader in Node: every mesh it builds, with its world matrix per instance
# (an InstancedMesh's instance matrices times its node's world matrix).
THREE_JS = r"""
${THREE_PRELUDE}
new GLTFLoader().parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', (gltf) => {
  const out = [];
  gltf.scene.updateMatrixWorld(true);
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    const m = new THREE.Matrix4();
    const matrices = [];
    for (let i = 0; i < (o.isInstancedMesh ? o.count : 1); i++) {
      if (o.isInstancedMesh) { o.getMatrixAt(i, m); m.premultiply(o.matrixWorld); } else { m.copy(o.matrixWorld); }
      matrices.push(Array.from(m.elements));
    }
    out.push({name: o.name, instanced: !!o.isInstancedMesh, triangles: o.geometry.index.count / 3,
              material: o.material.name, matrices: matrices});
  });
  console.log(JSON.stringify(out));
}, (err) => { console.error(String(err)); process.exit(3); });
"""


# three.js playing a .glb's animation: at each time, the AnimationMixer sets the clip's
# time, the skeletons update and every SkinnedMesh's vertices are skinned as three.js
# draws them (SkinnedMesh.getVertexPosition, then the mesh's world matrix). Positions go
# to a float32 file, time by time, mesh by mesh in traversal order.
THREE_SWAY_JS = r"""
${THREE_PRELUDE}
const times = JSON.parse(process.argv[3]);
new GLTFLoader().parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', (gltf) => {
  const mixer = new THREE.AnimationMixer(gltf.scene);
  for (const clip of gltf.animations) mixer.clipAction(clip).play();
  const meshes = [];
  gltf.scene.traverse((o) => { if (o.isSkinnedMesh) meshes.push(o); });
  const chunks = [];
  const v = new THREE.Vector3();
  for (const t of times) {
    mixer.setTime(t);
    gltf.scene.updateMatrixWorld(true);
    for (const m of meshes) {
      m.skeleton.update();
      const n = m.geometry.attributes.position.count;
      const out = new Float32Array(3 * n);
      for (let i = 0; i < n; i++) {
        m.getVertexPosition(i, v).applyMatrix4(m.matrixWorld);
        out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
      }
      chunks.push(Buffer.from(out.buffer));
    }
  }
  fs.writeFileSync(process.argv[4], Buffer.concat(chunks));
  const assoc = gltf.parser.associations;
  const node = (m) => { const own = assoc.get(m) || {}; return own.nodes !== undefined ? own.nodes
    : (assoc.get(m.parent) || {}).nodes; };
  console.log(JSON.stringify({
    meshes: meshes.map((m) => ({name: m.name, node: node(m), primitive: (assoc.get(m) || {}).primitives,
      count: m.geometry.attributes.position.count, material: m.material.name, bones: m.skeleton.bones.length})),
    animations: gltf.animations.map((a) => ({name: a.name, duration: a.duration, tracks: a.tracks.length}))}));
}, (err) => { console.error(String(err)); process.exit(3); });
"""


# three.js's GLTFLoader in Node: a scene's cameras (fov, aspect, world position and
# direction), lights (type, intensity, world direction: towards its target) and the
# world positions of the mesh named "Ground".
THREE_SCENE_JS = r"""
${THREE_PRELUDE}
new GLTFLoader().parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', (gltf) => {
  gltf.scene.updateMatrixWorld(true);
  const v = (x) => [x.x, x.y, x.z];
  const cameras = gltf.cameras.map((c) => {
    c.updateMatrixWorld(true);
    return {fov: c.fov, aspect: c.aspect, position: v(c.getWorldPosition(new THREE.Vector3())),
            direction: v(c.getWorldDirection(new THREE.Vector3())), up: v(c.up.clone().applyQuaternion(
              c.getWorldQuaternion(new THREE.Quaternion())))};
  });
  const lights = [], ground = [];
  gltf.scene.traverse((o) => {
    if (o.isLight) {
      const from = o.getWorldPosition(new THREE.Vector3()), to = o.target.getWorldPosition(new THREE.Vector3());
      lights.push({type: o.type, intensity: o.intensity, direction: v(to.sub(from).normalize())});
    }
    if (o.isMesh && o.name.startsWith('Ground')) {
      const p = o.geometry.attributes.position;
      for (let i = 0; i < p.count; i++) ground.push(v(new THREE.Vector3().fromBufferAttribute(p, i)
        .applyMatrix4(o.matrixWorld)));
    }
  });
  console.log(JSON.stringify({cameras, lights, ground}));
}, (err) => { console.error(String(err)); process.exit(3); });
"""


THREE_JS, THREE_SWAY_JS, THREE_SCENE_JS = (three_script(script) for script in (THREE_JS, THREE_SWAY_JS, THREE_SCENE_JS))


def node_modules(package: str) -> Path:
    """node_modules holding ``package``: $PLANTGEN_NODE_MODULES, .ci/node, or the user cache
    (installed there with npm if missing)."""
    candidates = [os.environ.get("PLANTGEN_NODE_MODULES"), os.environ.get("PLANTGEN_GLTF_VALIDATOR"),
                  REPO / ".ci" / "node", Path.home() / ".cache" / "plantgen" / package]
    for prefix in filter(None, candidates):
        modules = Path(prefix) / "node_modules"
        if (modules / package).is_dir():
            return modules
    cache = Path(candidates[-1])
    cache.mkdir(parents=True, exist_ok=True)
    npm = shutil.which("npm")
    assert npm, f"node is installed but npm is not: install {package} with npm to run this test"
    done = subprocess.run([npm, "install", "--prefix", str(cache), package], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, f"cannot install {package}: {done.stderr[-500:]}"
    return cache / "node_modules"


def khronos_issues(path: Path) -> dict:
    """The Khronos glTF validator's report on ``path`` (.glb, or .gltf with its .bin)."""
    env = dict(os.environ, NODE_PATH=str(node_modules("gltf-validator")))
    done = subprocess.run(["node", "-e", VALIDATE_JS, str(path)], capture_output=True, text=True, env=env,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def assert_khronos_valid(path: Path) -> dict:
    """No error and no warning from the validator; returns its report."""
    issues = khronos_issues(path)
    assert issues["numErrors"] == 0, [m for m in issues["messages"] if m["severity"] == 0]
    assert issues["numWarnings"] == 0, issues["messages"]
    return issues


def three_js_meshes(path: Path, tmp_path: Path) -> list[dict]:
    """What three.js's GLTFLoader makes of a .glb (see :data:`THREE_JS`)."""
    script = tmp_path / "load_with_three.mjs"
    script.write_text(THREE_JS)
    env = dict(os.environ, THREE_MODULES=str(node_modules("three")))
    done = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def three_js_sway(path: Path, times, tmp_path: Path) -> tuple[dict, list[list]]:
    """three.js playing the animations of a .glb (see :data:`THREE_SWAY_JS`): its report
    (``meshes``: every SkinnedMesh's name, the glTF node and primitive it comes from,
    vertex count, material, bones;
    ``animations``: name, duration, tracks) and, per time, per skinned mesh, the skinned
    world positions (count, 3)."""
    import numpy as np

    script = tmp_path / "play_with_three.mjs"
    script.write_text(THREE_SWAY_JS)
    out = tmp_path / "skinned.f32"
    env = dict(os.environ, THREE_MODULES=str(node_modules("three")))
    done = subprocess.run(["node", str(script), str(path), json.dumps([float(t) for t in times]), str(out)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    data = np.fromfile(out, dtype=np.float32)
    positions, at = [], 0
    for _ in times:
        frame = []
        for mesh in report["meshes"]:
            frame.append(data[at:at + 3 * mesh["count"]].reshape(-1, 3).astype(np.float64))
            at += 3 * mesh["count"]
        positions.append(frame)
    assert at == len(data)
    return report, positions


def three_js_scene(path: Path, tmp_path: Path) -> dict:
    """A .glb's cameras, lights and ground as three.js's GLTFLoader makes them (see
    :data:`THREE_SCENE_JS`)."""
    script = tmp_path / "scene_with_three.mjs"
    script.write_text(THREE_SCENE_JS)
    env = dict(os.environ, THREE_MODULES=str(node_modules("three")))
    done = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


# three.js's GLTFLoader in Node: every mesh's material as three.js builds it (its colour
# map and normal map: the PNG's width and height, :data:`NODE_IMAGES`; the normal scale,
# whether the geometry has tangents and vertex colours).
THREE_MATERIALS_JS = r"""
${THREE_PRELUDE}
const image = (t) => t ? [t.image.width, t.image.height] : null;
new GLTFLoader().parse(buf.buffer.slice(buf.byteOffset, buf.byteOffset + buf.byteLength), '', (gltf) => {
  const out = [];
  gltf.scene.traverse((o) => {
    if (!o.isMesh) return;
    const m = o.material;
    out.push({mesh: o.name, material: m.name, type: m.type, map: image(m.map), normalMap: image(m.normalMap),
              normalScale: m.normalScale ? [m.normalScale.x, m.normalScale.y] : null,
              tangents: !!o.geometry.attributes.tangent, vertexColors: !!m.vertexColors,
              colorSpace: m.map ? m.map.colorSpace : null, color: [m.color.r, m.color.g, m.color.b],
              wrap: m.map ? [m.map.wrapS, m.map.wrapT] : null, extras: m.userData || {}});
  });
  console.log(JSON.stringify(out));
}, (err) => { console.error(String(err)); process.exit(3); });
"""


def three_js_materials(path: Path, tmp_path: Path) -> list[dict]:
    """Every mesh's material as three.js's GLTFLoader makes it from a .glb or .gltf (see
    :data:`THREE_MATERIALS_JS`)."""
    script = tmp_path / "materials_with_three.mjs"
    script.write_text(three_script(THREE_MATERIALS_JS))
    env = dict(os.environ, THREE_MODULES=str(node_modules("three")))
    done = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)
