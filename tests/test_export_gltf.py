"""glTF export: structural validation, and the animated node hierarchy gives the body back."""

from __future__ import annotations

import json
import shutil
import struct
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physpose.export import export
from physpose.export.gltf import (CHUNK_BIN, CHUNK_JSON, FLOAT, GLB_MAGIC, UINT16, UINT32,
                                  accessor_array, read_glb, write_glb)
from physpose.render.bodymotion import reconstruction_motion
from synthetic_result import make_reconstruction, save_result

WEB = Path(__file__).resolve().parents[1] / "web"
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_TYPE_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


@pytest.fixture(scope="module")
def glb(tmp_path_factory):
    rec = make_reconstruction(num_frames=30)
    motion = reconstruction_motion(rec, "physics")
    flags = {"detected": [True] * 30, "physics_restart": [f == 5 for f in range(30)],
             "physics_invalid": None}   # as export() writes them (the validator sees extras)
    path = write_glb(motion, rec.fps, tmp_path_factory.mktemp("glb") / "m.glb", flags)
    return path, motion, rec


def structural_problems(path: Path) -> list[str]:
    """Every violation of the glTF binary layout rules this exporter must follow."""
    data = path.read_bytes()
    problems = []
    magic, version, length = struct.unpack_from("<III", data, 0)
    if (magic, version, length) != (GLB_MAGIC, 2, len(data)):
        problems.append(f"header {magic:#x} v{version} length {length} != {len(data)}")
    json_len, json_type = struct.unpack_from("<II", data, 12)
    bin_at = 20 + json_len
    bin_len, bin_type = struct.unpack_from("<II", data, bin_at)
    if (json_type, bin_type) != (CHUNK_JSON, CHUNK_BIN):
        problems.append("chunks are not JSON then BIN")
    if json_len % 4 or bin_len % 4 or bin_at % 4 or bin_at + 8 + bin_len != len(data):
        problems.append("chunks not 4-byte aligned or not filling the file")
    doc = json.loads(data[20:20 + json_len])
    if doc["buffers"][0]["byteLength"] > bin_len:
        problems.append("buffer longer than the BIN chunk")
    for i, view in enumerate(doc["bufferViews"]):
        if view.get("byteOffset", 0) + view["byteLength"] > doc["buffers"][view["buffer"]][
                "byteLength"]:
            problems.append(f"bufferView {i} runs past its buffer")
    for i, acc in enumerate(doc["accessors"]):
        view = doc["bufferViews"][acc["bufferView"]]
        size = _COMPONENT_BYTES[acc["componentType"]]
        need = acc.get("byteOffset", 0) + acc["count"] * size * _TYPE_WIDTH[acc["type"]]
        if need > view["byteLength"] or acc["count"] < 1:
            problems.append(f"accessor {i} needs {need} bytes of a {view['byteLength']} view")
        if (view.get("byteOffset", 0) + acc.get("byteOffset", 0)) % size:
            problems.append(f"accessor {i} is misaligned")
    for m in doc["meshes"]:
        for prim in m["primitives"]:
            pos = doc["accessors"][prim["attributes"]["POSITION"]]
            if "min" not in pos or "max" not in pos or pos["type"] != "VEC3":
                problems.append(f"mesh {m['name']}: POSITION lacks min/max")
            idx = doc["accessors"][prim["indices"]]
            if idx["componentType"] not in (UINT16, UINT32):
                problems.append(f"mesh {m['name']}: bad index type")
            if accessor_array(doc, data[bin_at + 8:], prim["indices"]).max() >= pos["count"]:
                problems.append(f"mesh {m['name']}: index out of range")
    for anim in doc["animations"]:
        for s in anim["samplers"]:
            times = accessor_array(doc, data[bin_at + 8:], s["input"])
            if len(times) > 1 and not np.all(np.diff(times) > 0):
                problems.append("sampler input times not strictly increasing")
            if doc["accessors"][s["output"]]["count"] != len(times):
                problems.append("sampler output count differs from its input")
    # Node hierarchy: every node has at most one parent and no node is its own ancestor.
    parent = {}
    for i, node in enumerate(doc["nodes"]):
        for c in node.get("children", []):
            if c in parent:
                problems.append(f"node {c} has two parents")
            parent[c] = i
    for start in range(len(doc["nodes"])):
        seen, n = set(), start
        while n in parent:
            if n in seen:
                problems.append(f"cycle through node {start}")
                break
            seen.add(n)
            n = parent[n]
    return problems


def animated_world_positions(doc: dict, blob: bytes) -> tuple[np.ndarray, dict[str, int]]:
    """Apply the animation at each key time: world positions (T, N, 3) of all nodes (y up)."""
    nodes = doc["nodes"]
    anim = doc["animations"][0]
    t = doc["accessors"][anim["samplers"][0]["input"]]["count"]
    trans = np.array([n.get("translation", [0, 0, 0]) for n in nodes], float)[None].repeat(t, 0)
    rot = np.array([n.get("rotation", [0, 0, 0, 1]) for n in nodes], float)[None].repeat(t, 0)
    for ch in anim["channels"]:
        values = accessor_array(doc, blob, anim["samplers"][ch["sampler"]]["output"])
        (trans if ch["target"]["path"] == "translation" else rot)[:, ch["target"]["node"]] = values
    pos = np.zeros((t, len(nodes), 3))
    mats = np.zeros((t, len(nodes), 3, 3))

    def visit(i, p_pos, p_mat):
        r = Rotation.from_quat(rot[:, i]).as_matrix()  # scipy uses x, y, z, w like glTF
        pos[:, i] = p_pos + np.einsum("tij,tj->ti", p_mat, trans[:, i])
        mats[:, i] = p_mat @ r
        for c in nodes[i].get("children", []):
            visit(c, pos[:, i], mats[:, i])

    for root in doc["scenes"][doc["scene"]]["nodes"]:
        visit(root, np.zeros((t, 3)), np.broadcast_to(np.eye(3), (t, 3, 3)))
    return pos, {n.get("name"): i for i, n in enumerate(nodes)}


def test_glb_passes_structural_checks(glb):
    path, _, _ = glb
    assert structural_problems(path) == []


def test_structural_checks_catch_a_broken_file(glb, tmp_path):
    path, _, _ = glb
    data = bytearray(path.read_bytes())
    data[8:12] = struct.pack("<I", len(data) + 4)  # wrong total length
    broken = tmp_path / "broken.glb"
    broken.write_bytes(bytes(data))
    assert any("header" in p for p in structural_problems(broken))


def test_round_trip_gives_body_positions_within_a_millimetre(glb):
    path, motion, rec = glb
    doc, blob = read_glb(path)
    pos, index = animated_world_positions(doc, blob)
    y_up_to_z_up = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # x, -z, y
    bodies = pos[:, [index[n] for n in motion.tree.names]] @ y_up_to_z_up.T
    assert np.abs(bodies - motion.pos).max() < 1e-3
    times = accessor_array(doc, blob, doc["animations"][0]["samplers"][0]["input"])
    assert np.allclose(times, np.arange(30) / rec.fps)


def test_every_geom_is_a_mesh_with_outward_normals(glb):
    path, motion, _ = glb
    doc, blob = read_glb(path)
    names = {m["name"] for m in doc["meshes"]}
    assert {"geom_" + g.name for g in motion.tree.geoms} | {"ground", "scene_step"} <= names
    node_names = [n["name"] for n in doc["nodes"]]
    assert len(node_names) == len(set(node_names))
    for mesh in doc["meshes"]:
        prim = mesh["primitives"][0]
        v = accessor_array(doc, blob, prim["attributes"]["POSITION"])
        n = accessor_array(doc, blob, prim["attributes"]["NORMAL"])
        f = accessor_array(doc, blob, prim["indices"]).reshape(-1, 3).astype(int)
        assert np.allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
        face_normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
        # Counter-clockwise winding: geometric normals agree with the vertex normals.
        assert np.all(np.einsum("fi,fi->f", face_normal, n[f[:, 0]]) > 0), mesh["name"]
        accessor = doc["accessors"][prim["attributes"]["POSITION"]]
        assert np.allclose(accessor["min"], v.min(axis=0)) and accessor["componentType"] == FLOAT


def test_export_writes_glb_into_the_result_folder(tmp_path):
    folder = save_result(tmp_path, physics=False)
    path = export(folder, "glb")
    assert path == folder / "motion.glb" and structural_problems(path) == []


def test_khronos_validator_reports_no_issues(glb):
    """The official glTF validator (npm gltf-validator, installed by `make setup`)."""
    script = WEB / "validate_gltf.mjs"
    if shutil.which("node") is None or not (WEB / "node_modules" / "gltf-validator").is_dir():
        pytest.skip("node or web/node_modules/gltf-validator missing; run `make setup`")
    path, _, _ = glb
    run = subprocess.run(["node", str(script), str(path)], capture_output=True, text=True,
                         cwd=WEB, timeout=120, check=True)
    issues = json.loads(run.stdout)["issues"]
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
