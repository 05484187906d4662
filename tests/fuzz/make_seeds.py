#!/usr/bin/env python3
"""Writes the seed corpora of the fuzzers into tests/fuzz/corpus/<harness>/seed-*.

Real meshes: tiny cuts of the shared meshes (../shared/meshes: the first faces of each file,
their vertices renumbered, in the file's own format and dialect: OBJ with a/t/n corners,
binary and ascii PLY with normals, OFF), plus small hand-made ones. Broken meshes: each
real one truncated, with an index out of range, a non-finite coordinate, a huge count, a
polygon of two corners, a missing header line. The method and mesh-construction harnesses
get a few byte strings per method (their first byte picks the method).

Run it again after changing it: it rewrites seed-* and leaves the crash-* reproducers and
what the fuzzers added alone. Deterministic (no randomness), so the corpus diff shows what
changed.
"""
import os
import struct
import sys

here = os.path.dirname(os.path.abspath(__file__))
shared = os.path.join(here, "..", "..", "..", "shared", "meshes")
corpus = os.path.join(here, "corpus")


def cut_obj(path, n_faces):
    """The first n_faces faces of an OBJ and their vertices, with corner suffixes kept."""
    verts, faces = [], []
    for line in open(path, errors="replace"):
        t = line.split()
        if not t:
            continue
        if t[0] == "v":
            verts.append(t[1:4])
        elif t[0] == "f" and len(faces) < n_faces:
            faces.append(t[1:])
    used, out_f = {}, []
    for f in faces:
        corners = []
        for c in f:
            parts = c.split("/")
            i = int(parts[0])
            i = i - 1 if i > 0 else len(verts) + i
            if i not in used:
                used[i] = len(used)
            parts[0] = str(used[i] + 1)
            corners.append("/".join(parts))
        out_f.append(corners)
    inv = sorted(used, key=used.get)
    lines = ["# cut of %s: %d faces" % (os.path.basename(path), len(out_f))]
    lines += ["v " + " ".join(verts[i]) for i in inv]
    lines += ["vt 0.5 0.5"] * 3
    lines += ["f " + " ".join(c) for c in out_f]
    return [[float(x) for x in verts[i]] for i in inv], \
        [[used_index(c) for c in f] for f in out_f], "\n".join(lines) + "\n"


def used_index(corner):
    return int(corner.split("/")[0]) - 1


def cut_off(path, n_faces):
    tok = [l.split() for l in open(path) if l.strip() and not l.startswith("#")]
    nv, nf = int(tok[1][0]), int(tok[1][1])
    verts = [[float(x) for x in t[:3]] for t in tok[2:2 + nv]]
    faces = [[int(x) for x in t[1:1 + int(t[0])]] for t in tok[2 + nv:2 + nv + min(nf, n_faces)]]
    return renumber(verts, faces)


def cut_ply(path, n_faces):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    nv = int(header.split("element vertex ")[1].split()[0])
    n_props = header.split("element face")[0].count("property float")
    stride = 4 * n_props
    verts = [list(struct.unpack_from("<3f", data, end + stride * i)) for i in range(nv)]
    faces, p = [], end + stride * nv
    for _ in range(n_faces):
        k = data[p]
        faces.append(list(struct.unpack_from("<%di" % k, data, p + 1)))
        p += 1 + 4 * k
    return renumber(verts, faces)


def renumber(verts, faces):
    used = {}
    for f in faces:
        for i in f:
            used.setdefault(i, len(used))
    inv = sorted(used, key=used.get)
    return [verts[i] for i in inv], [[used[i] for i in f] for f in faces]


def write_obj(V, F):
    return "".join("v %r %r %r\n" % tuple(v) for v in V) + \
        "".join("f " + " ".join(str(i + 1) for i in f) + "\n" for f in F)


def write_off(V, F, header="OFF"):
    return "%s\n%d %d 0\n" % (header, len(V), len(F)) + \
        "".join("%r %r %r\n" % tuple(v) for v in V) + \
        "".join("%d %s\n" % (len(f), " ".join(map(str, f))) for f in F)


def write_ply_ascii(V, F):
    h = ("ply\nformat ascii 1.0\ncomment seed\nelement vertex %d\nproperty float x\n"
         "property float y\nproperty float z\nproperty uchar red\nelement face %d\n"
         "property list uchar int vertex_indices\nelement edge 1\n"
         "property list uchar uint extra\nend_header\n" % (len(V), len(F)))
    return (h + "".join("%r %r %r 7\n" % tuple(v) for v in V) +
            "".join("%d %s\n" % (len(f), " ".join(map(str, f))) for f in F) + "2 0 1\n").encode()


def write_ply_binary(V, F, index_type="i", count_type="B"):
    names = {"i": "int", "I": "uint", "H": "ushort", "B": "uchar"}
    h = ("ply\nformat binary_little_endian 1.0\nelement vertex %d\nproperty double x\n"
         "property double y\nproperty double z\nproperty float nx\nelement face %d\n"
         "property list %s %s vertex_indices\nend_header\n"
         % (len(V), len(F), names[count_type], names[index_type])).encode()
    body = b"".join(struct.pack("<3df", *v, 0.5) for v in V)
    body += b"".join(struct.pack("<" + count_type, len(f)) +
                     struct.pack("<%d%s" % (len(f), index_type), *f) for f in F)
    return h + body


def broken_text(text, kind):
    """Variants of a text mesh that a reader must refuse (or read without harm)."""
    lines = text.splitlines(keepends=True)
    return {
        "truncated": text[:len(text) * 2 // 3],
        "nan": text.replace("v ", "v nan ", 1) if kind == "obj" else
               "".join(lines[:2]) + "nan 0 0\n" + "".join(lines[3:]),
        "bad-index": text + ("f 1 2 99999\n" if kind == "obj" else ""),
        "two-corners": text + ("f 1 2\n" if kind == "obj" else ""),
        "huge-count": ("OFF\n2147483647 1 0\n0 0 0\n" if kind == "off" else
                       "v 0 0 0\nf 1 -2 3\n"),
        "no-newline": text.rstrip("\n"),
        "crlf": text.replace("\n", "\r\n"),
    }


def main():
    def put(harness, name, data):
        d = os.path.join(corpus, harness)
        os.makedirs(d, exist_ok=True)
        if isinstance(data, str):
            data = data.encode()
        with open(os.path.join(d, "seed-" + name), "wb") as f:
            f.write(data)

    tetra_V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]
    tetra_F = [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
    quad_V = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1], [2, 2, 2]]
    quad_F = [[0, 1, 2, 3], [0, 1, 4], [1, 2, 4, 3, 0]]  # a quad, a triangle, a pentagon
    meshes = {"tetra": (tetra_V, tetra_F), "polygons": (quad_V, quad_F)}
    if os.path.isdir(shared):
        V, F, text = cut_obj(os.path.join(shared, "spot.obj"), 24)
        put("mesh_obj", "spot-cut.obj", text)
        for k, v in broken_text(text, "obj").items():
            put("mesh_obj", "spot-cut-%s.obj" % k, v)
        _, _, text = cut_obj(os.path.join(shared, "stanford-bunny.obj"), 30)
        put("mesh_obj", "bunny-cut.obj", text)
        meshes["bumpy"] = cut_off(os.path.join(shared, "bumpy.off"), 30)
        meshes["knight"] = cut_off(os.path.join(shared, "decimated-knight.off"), 20)
        meshes["horse"] = cut_ply(os.path.join(shared, "horse.ply"), 24)
    else:
        print("make_seeds: %s not found, hand-made meshes only" % shared, file=sys.stderr)
    for name, (V, F) in meshes.items():
        obj, off = write_obj(V, F), write_off(V, F)
        put("mesh_obj", name + ".obj", obj)
        put("mesh_off", name + ".off", off)
        put("mesh_off", name + "-coff.off", write_off(V, F, "COFF"))
        put("mesh_ply", name + "-ascii.ply", write_ply_ascii(V, F))
        put("mesh_ply", name + "-binary.ply", write_ply_binary(V, F))
        put("mesh_ply", name + "-binary-u16.ply", write_ply_binary(V, F, "H", "I"))
        for k, v in broken_text(obj, "obj").items():
            put("mesh_obj", "%s-%s.obj" % (name, k), v)
        for k, v in broken_text(off, "off").items():
            put("mesh_off", "%s-%s.off" % (name, k), v)
        b = write_ply_binary(V, F)
        put("mesh_ply", name + "-binary-truncated.ply", b[:len(b) - 5])
        put("mesh_ply", name + "-no-end-header.ply", b.replace(b"end_header\n", b""))
        put("mesh_ply", name + "-big-list.ply",
            b.replace(b"list uchar int", b"list uint int").replace(b"uchar", b"uint"))
    put("mesh_ply", "huge-element.ply",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
        "property float z\nelement junk 2147483647\nend_header\n0 0 0\n")
    put("mesh_off", "empty.off", "OFF\n0 0 0\n")
    put("mesh_obj", "points.obj", "v 0 0 0\nv 1 1 1\n")
    # mesh construction (byte 0: the vertex count - 1; then a corner-count byte, 6 for a
    # triangle, 1 a quad, 2 a pentagon, 3 a hexagon, and the corners) and the methods
    # (byte 0 picks the method)
    for i in range(6):
        put("method", "method-%d-grid" % i, bytes([i, 0, 3, 3, 0, 1, 2, 5, 0, 0, 0]))
        put("method", "method-%d-bumpy" % i,
            bytes([i, 0, 4, 4, 0x18]) + bytes((7 * j) % 256 for j in range(60)))
        put("method", "method-%d-two-handles" % i,
            bytes([i, 0, 4, 2, 0x9, 0, 0x12, 0, 1, 2, 0, 3, 4, 0, 2, 3]) + bytes(range(40)))
    put("mesh_build", "tetra", bytes([3, 1]) + bytes(12 * [2]) + bytes([6, 0, 2, 1, 6, 0, 1, 3,
                                                                     6, 0, 3, 2, 6, 1, 2, 3]))
    put("mesh_build", "polygons", bytes([7, 1]) + bytes(range(24)) + bytes([2, 0, 1, 2, 3, 4,
                                                                            3, 0, 1, 2, 3, 4, 5]))


if __name__ == "__main__":
    main()
