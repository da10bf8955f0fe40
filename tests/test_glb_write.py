"""The glTF writer's output (plantgen.exporters.gltf): its pieces go to the file in one
gathering write, and the file is the same whatever the system's write leaves for the next
call, or where it has no gathering write; the JSON's bounds are numpy's along axis 0,
the sign of a zero bound included."""

from __future__ import annotations

import json
import os
import struct

import numpy as np
import pytest

from plantgen.exporters import Plant, gltf, write_plants
from plantgen.exporters.textures import bake_textures
from plantgen.geometry.meshes.mesh import tessellate
from plantgen.geometry.skeletons.skin import skin_skeleton
from plantgen.pipeline import grow_file


@pytest.fixture(scope="module")
def saguaro():
    skeleton = grow_file("saguaro").skeleton
    mesh = tessellate(skin_skeleton(skeleton), 1)
    return [Plant("saguaro", skeleton, mesh, None)], bake_textures([mesh])


def _write(plants, textures, folder, name="saguaro.glb"):
    folder.mkdir()
    return [p.read_bytes() for p in write_plants(plants, folder / name, textures=textures)]


def test_short_writes_and_no_writev_leave_the_same_file(saguaro, tmp_path, monkeypatch):
    plants, textures = saguaro
    [whole] = _write(plants, textures, tmp_path / "whole")
    calls = []
    writev = os.writev

    def short(fd, buffers):               # at most 4 pieces and 1,000 bytes a call
        calls.append(len(buffers))
        take, left = [], 1000
        for b in buffers:
            if left <= 0:
                break
            take.append(memoryview(b)[:left])
            left -= len(take[-1])
        return writev(fd, take)
    monkeypatch.setattr(gltf, "WRITE_PIECES", 4)
    monkeypatch.setattr(os, "writev", short)
    [pieces] = _write(plants, textures, tmp_path / "short")
    assert pieces == whole and len(calls) > len(whole) // 1000 and max(calls) == 4
    monkeypatch.delattr(os, "writev")
    [plain] = _write(plants, textures, tmp_path / "plain")
    assert plain == whole
    magic, version, total = struct.unpack("<III", whole[:12])
    assert (magic, version, total) == (gltf.GLB_MAGIC, 2, len(whole))


def test_the_bin_is_the_glbs_binary_chunk(saguaro, tmp_path):
    plants, _ = saguaro                  # no maps: the .gltf's images would be files, not views
    [glb] = _write(plants, None, tmp_path / "glb")
    [binary, text] = _write(plants, None, tmp_path / "gltf", "saguaro.gltf")
    json_length = struct.unpack("<I", glb[12:16])[0]
    chunk_length = struct.unpack("<I", glb[20 + json_length:24 + json_length])[0]
    assert len(binary) == json.loads(text)["buffers"][0]["byteLength"]
    assert chunk_length == len(binary) + (-len(binary)) % 4
    assert glb[28 + json_length:] == binary + bytes(chunk_length - len(binary))


def _columns():
    rng = np.random.default_rng(45)
    zeros = [rng.choice(np.array([-0.0, 0.0, 1.0, 2.0]), size=n) for n in (2, 17, 1000, 10001) for _ in range(5)]
    return zeros + [np.array([3.0, -1.5, 7.25]), np.array([1.0, np.nan, -1.0]), rng.normal(size=5000)]


def test_bounds_are_numpys_along_axis_0():
    # a column's own minimum and numpy's along axis 0 may pick different signs of a zero
    # bound on long columns (their SIMD loops differ): a zero bound is numpy's along axis 0
    for column in _columns():
        rows = np.stack([column, -column, column * 3], axis=1).astype(np.float32)
        for array in (rows, rows[:, 0]):
            lo, hi = gltf._bounds(array)
            want_lo, want_hi = np.atleast_1d(np.min(array, axis=0)), np.atleast_1d(np.max(array, axis=0))
            assert np.array_equal(lo, want_lo, equal_nan=True) and np.array_equal(hi, want_hi, equal_nan=True)
            assert np.array_equal(np.signbit(lo), np.signbit(want_lo))
            assert np.array_equal(np.signbit(hi), np.signbit(want_hi))
