#!/usr/bin/env python3
"""Regenerates the malformed-input corpus (one file per failure class of issue 22).
Run from this folder: python3 generate.py. Each file is tiny; the test `malformed` in
../malformed.rs renders every one of them and expects exit 2, a message naming the file, and no
output.
texture-jpeg-frame-bomb.jpg is not generated here: it is a fuzz find (fuzz/README.md), a 329-byte
progressive JPEG declaring 8212x3860 pixels."""
import base64, json, struct

def gltf(name, *, accessors=None, views=None, nodes=None, attrs=None, indices=1, extra_bin=b"", mode=4):
    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    idx = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    data = pos + idx + extra_bin
    doc = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(data), "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
        "bufferViews": views or [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "accessors": accessors or [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "meshes": [{"primitives": [dict({"attributes": attrs or {"POSITION": 0}, "mode": mode}, **({"indices": indices} if indices is not None else {}))]}],
        "nodes": nodes or [{"mesh": 0}],
        "scenes": [{"nodes": [0]}],
        "scene": 0,
    }
    open(name, "w").write(json.dumps(doc, indent=1) + "\n")

POS = {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}
IDX = {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
# byteStride smaller than a VEC3 of floats.
gltf("gltf-stride-too-small.gltf", views=[{"buffer": 0, "byteOffset": 0, "byteLength": 36, "byteStride": 4}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}])
# Index accessors of FLOAT and of a signed type.
gltf("gltf-float-indices.gltf", accessors=[POS, dict(IDX, componentType=5126, bufferView=0)])
gltf("gltf-signed-indices.gltf", accessors=[POS, dict(IDX, componentType=5122)])
# Index count 2^32 - 1.
gltf("gltf-index-count-huge.gltf", accessors=[POS, dict(IDX, count=4294967295)])
# COLOR_0 of an integer type the spec does not allow.
gltf("gltf-color-uint.gltf", accessors=[POS, IDX, {"bufferView": 0, "componentType": 5125, "count": 3, "type": "VEC3"}], attrs={"POSITION": 0, "COLOR_0": 2})
# POSITION of the wrong type (VEC2) and of the wrong component type (unsigned byte).
gltf("gltf-position-vec2.gltf", accessors=[dict(POS, type="VEC2"), IDX])
gltf("gltf-position-ubyte.gltf", accessors=[dict(POS, componentType=5121), IDX])
# An accessor reaching past its buffer view.
gltf("gltf-accessor-past-view.gltf", accessors=[dict(POS, count=1000), IDX])
# Sparse indices out of range (index 100 of a 3-element accessor).
sparse = struct.pack("<H", 100) + b"\0\0" + struct.pack("<3f", 5, 5, 5)
gltf("gltf-sparse-out-of-range.gltf", extra_bin=sparse,
     views=[{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6},
            {"buffer": 0, "byteOffset": 44, "byteLength": 2}, {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
     accessors=[dict(POS, sparse={"count": 1, "indices": {"bufferView": 2, "componentType": 5123}, "values": {"bufferView": 3}}), IDX])
# Node transforms overflowing positions to infinity (finite matrices, infinite product).
gltf("gltf-transform-overflow.gltf", nodes=[{"mesh": 0, "scale": [3e38, 3e38, 3e38], "translation": [3e38, 0, 0]}])
# A mesh index out of range of the node list would be caught by gltf-json; a buffer view past the buffer:
gltf("gltf-view-past-buffer.gltf", views=[{"buffer": 0, "byteOffset": 0, "byteLength": 36000}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}])

# PLY whose header under-counts vertices: the 4th vertex line is read as a face.
open("ply-undercount.ply", "w").write(
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n")
# Binary PLY whose body is longer than the header says: a triangle more than its one face.
tri = struct.pack("<B3i", 3, 0, 1, 2)
open("ply-binary-trailing.ply", "wb").write(
    b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    b"element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + tri + tri)
# PLY with a coordinate declared as a list.
open("ply-coordinate-list.ply", "w").write(
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty list uchar float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
    "1 0 0 0\n1 1 0 0\n1 0 1 0\n3 0 1 2\n")
# OBJ with texture index 0 (OBJ indices start at 1).
open("obj-texture-index-0.obj", "w").write("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/0 2/0 3/0\n")
# A truncated JPEG and a truncated PNG (used as textures by the test's scene).
import io, zlib
def png(w, h):
    raw = b"".join(b"\0" + bytes([200, 100, 50]) * w for _ in range(h))
    def chunk(t, d):
        return struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xffffffff)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)) + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b"")
p = png(64, 64)
open("texture-truncated.png", "wb").write(p[: len(p) // 2])
