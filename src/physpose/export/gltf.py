"""glTF 2.0 binary (.glb) export of the animated capsule body over a ground plane.

Node layout: a root node "world" turns physpose's z-up world into glTF's y-up; under it a ground
quad, any static obstacles, and one node per MuJoCo body (parent-child as in the body tree) with
its geoms as child mesh nodes. Each body node has translation and rotation samplers (LINEAR)
with one key per analysis frame. Units metres, written by this module with struct + json.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from physpose.errors import PhysposeError
from physpose.export.meshes import geom_mesh, plane_mesh
from physpose.render.bodymotion import BodyMotion, GeomShape

GLB_MAGIC = 0x46546C67  # "glTF"
CHUNK_JSON = 0x4E4F534A  # "JSON"
CHUNK_BIN = 0x004E4942   # "BIN\0"
FLOAT, UINT16, UINT32 = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
# Rotation of -90 degrees about x (x, y, z, w): world z up -> glTF y up.
Q_WORLD2GLTF = (-np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5))
_GROUND_MARGIN = 1.0  # m of ground beyond the motion's extent
_GROUND_RGBA = (0.78, 0.8, 0.82, 1.0)


class _Builder:
    """Collects buffer views and accessors into one little-endian binary buffer."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, array: np.ndarray, kind: str, component: int, target: int | None = None,
            minmax: bool = False) -> int:
        dtype = {FLOAT: "<f4", UINT16: "<u2", UINT32: "<u4"}[component]
        data = np.ascontiguousarray(array, dtype=dtype)
        view = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": data.nbytes}
        if target is not None:
            view["target"] = target
        self.blob += data.tobytes()
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.views.append(view)
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[kind]
        acc = {"bufferView": len(self.views) - 1, "byteOffset": 0, "componentType": component,
               "count": int(data.size // width), "type": kind}
        if minmax:
            flat = data.reshape(-1, width)
            acc["min"] = [float(v) for v in flat.min(axis=0)]
            acc["max"] = [float(v) for v in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def build_gltf(motion: BodyMotion, fps: float,
               frame_flags: dict | None = None) -> tuple[dict, bytes]:
    """The glTF JSON document and its binary buffer for a body motion at `fps` frames/s.

    frame_flags: per-frame lists (name -> one entry per frame, or None) stored as the
    animation's `extras`, glTF's place for application data: viewers ignore it, scripts read it.
    """
    tree = motion.tree
    buf = _Builder()
    nodes: list[dict] = [{"name": "world", "rotation": list(Q_WORLD2GLTF), "children": []}]
    meshes: list[dict] = []
    materials: list[dict] = []
    material_of: dict[tuple, int] = {}

    def mesh_node(name: str, verts, norms, faces, rgba, pos=(0, 0, 0), quat=(1, 0, 0, 0)) -> int:
        key = tuple(round(c, 4) for c in rgba)
        if key not in material_of:
            material_of[key] = len(materials)
            materials.append({"name": f"material{len(materials)}", "pbrMetallicRoughness": {
                "baseColorFactor": list(key), "metallicFactor": 0.0, "roughnessFactor": 0.8}})
        index_type = UINT16 if len(verts) < 65536 else UINT32
        prim = {"attributes": {
            "POSITION": buf.add(verts, "VEC3", FLOAT, ARRAY_BUFFER, minmax=True),
            "NORMAL": buf.add(norms, "VEC3", FLOAT, ARRAY_BUFFER)},
            "indices": buf.add(faces.reshape(-1), "SCALAR", index_type, ELEMENT_ARRAY_BUFFER),
            "material": material_of[key], "mode": 4}
        meshes.append({"name": name, "primitives": [prim]})
        nodes.append({"name": name, "mesh": len(meshes) - 1, "translation": list(map(float, pos)),
                      "rotation": _xyzw(np.asarray(quat, float)).tolist()})
        return len(nodes) - 1

    center = motion.pos[:, 0, :2].mean(axis=0)
    half = float(np.abs(motion.pos[..., :2] - center).max()) + _GROUND_MARGIN
    nodes[0]["children"].append(mesh_node("ground", *plane_mesh(center, half), _GROUND_RGBA))
    for g in tree.scene:
        nodes[0]["children"].append(_geom_node(mesh_node, g, "scene_"))

    local_pos, local_quat = motion.local()
    body_nodes = []
    for b, name in enumerate(tree.names):
        body_nodes.append(len(nodes))
        nodes.append({"name": name, "translation": local_pos[0, b].tolist(),
                      "rotation": _xyzw(local_quat[0, b]).tolist(), "children": []})
    for b, p in enumerate(tree.parents):
        parent = nodes[0] if p < 0 else nodes[body_nodes[p]]
        parent["children"].append(body_nodes[b])
    for g in tree.geoms:
        nodes[body_nodes[g.body]]["children"].append(_geom_node(mesh_node, g, "geom_"))

    times = np.arange(motion.num_frames, dtype=float) / fps
    t_acc = buf.add(times, "SCALAR", FLOAT, minmax=True)
    samplers, channels = [], []
    for b, node in enumerate(body_nodes):
        for path, values, kind in (("translation", local_pos[:, b], "VEC3"),
                                   ("rotation", _xyzw(local_quat[:, b]), "VEC4")):
            samplers.append({"input": t_acc, "output": buf.add(values, kind, FLOAT),
                             "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})
    for node in nodes:
        if node.get("children") == []:
            del node["children"]
    doc = {
        "asset": {"version": "2.0", "generator": "physpose"},
        "scene": 0, "scenes": [{"name": "physpose", "nodes": [0]}],
        "nodes": nodes, "meshes": meshes, "materials": materials,
        "animations": [{"name": "motion", "samplers": samplers, "channels": channels,
                        **({"extras": frame_flags} if frame_flags else {})}],
        "accessors": buf.accessors, "bufferViews": buf.views,
        "buffers": [{"byteLength": len(buf.blob)}],
    }
    return doc, bytes(buf.blob)


def _geom_node(mesh_node, g: GeomShape, prefix: str) -> int:
    # Prefixed: MuJoCo lets a geom share its body's name, node names should be unique.
    return mesh_node(prefix + g.name, *geom_mesh(g), g.rgba, g.pos, g.quat)


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    q = np.asarray(q_wxyz, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.concatenate([q[..., 1:], q[..., :1]], axis=-1)


def write_glb(motion: BodyMotion, fps: float, path: str | Path,
              frame_flags: dict | None = None) -> Path:
    """Write the body motion as a binary glTF file (frame_flags: see build_gltf); returns the
    path."""
    path = Path(path)
    doc, blob = build_gltf(motion, fps, frame_flags)
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    out = struct.pack("<III", GLB_MAGIC, 2, total)
    out += struct.pack("<II", len(text), CHUNK_JSON) + text
    out += struct.pack("<II", len(blob), CHUNK_BIN) + blob
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(out)
    return path


def read_glb(path: str | Path) -> tuple[dict, bytes]:
    """Split a .glb file into its JSON document and binary chunk."""
    path = Path(path)
    data = path.read_bytes()
    if len(data) < 20:
        raise PhysposeError("file too short to be a .glb", path=path)
    magic, version, length = struct.unpack_from("<III", data, 0)
    if magic != GLB_MAGIC or version != 2 or length != len(data):
        raise PhysposeError("not a glTF 2.0 binary file (bad header)", path=path)
    json_len, json_type = struct.unpack_from("<II", data, 12)
    if json_type != CHUNK_JSON:
        raise PhysposeError("the first chunk of a .glb must be JSON", path=path)
    doc = json.loads(data[20:20 + json_len])
    blob = b""
    at = 20 + json_len
    if at < len(data):
        bin_len, bin_type = struct.unpack_from("<II", data, at)
        if bin_type != CHUNK_BIN:
            raise PhysposeError("the second chunk of a .glb must be BIN", path=path)
        blob = data[at + 8:at + 8 + bin_len]
    return doc, blob


def accessor_array(doc: dict, blob: bytes, index: int) -> np.ndarray:
    """The data of accessor `index` as an array (count,) or (count, width)."""
    acc = doc["accessors"][index]
    view = doc["bufferViews"][acc["bufferView"]]
    dtype = {FLOAT: "<f4", UINT16: "<u2", UINT32: "<u4"}[acc["componentType"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[acc["type"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    arr = np.frombuffer(blob, dtype=dtype, count=acc["count"] * width, offset=start)
    return arr if width == 1 else arr.reshape(acc["count"], width)
