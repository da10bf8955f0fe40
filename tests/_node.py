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

# three.js's GLTFLoader in Node: every mesh it builds, with its world matrix per instance
# (an InstancedMesh's instance matrices times its node's world matrix).
THREE_JS = r"""
import fs from 'fs';
import path from 'path';
import { pathToFileURL } from 'url';
const modules = process.env.THREE_MODULES;
const THREE = await import(pathToFileURL(path.join(modules, 'three/build/three.module.js')).href);
const { GLTFLoader } = await import(pathToFileURL(path.join(modules,
  'three/examples/jsm/loaders/GLTFLoader.js')).href);
const buf = fs.readFileSync(process.argv[2]);
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
