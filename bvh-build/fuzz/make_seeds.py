#!/usr/bin/env python3
"""Writes the seed corpora of the importer fuzz targets into seeds/<target>/, cut from scenes/.

The shipped meshes are megabytes (seconds per execution); the seeds keep the first few
triangles of each, in every form the readers take, so that each execution stays well under a
millisecond. Run from anywhere: python3 bvh-build/fuzz/make_seeds.py
"""

import base64
import json
import re
import struct
from pathlib import Path

FUZZ = Path(__file__).resolve().parent
SCENES = FUZZ.parent.parent / "scenes"
SEEDS = FUZZ / "seeds"


def read_glb(path):
    b = path.read_bytes()
    json_len = struct.unpack_from("<I", b, 12)[0]
    doc = json.loads(b[20 : 20 + json_len])
    at = 20 + json_len
    bin_len = struct.unpack_from("<I", b, at)[0]
    return doc, b[at + 8 : at + 8 + bin_len]


FORMATS = {5126: ("f", 4), 5125: ("I", 4), 5123: ("H", 2), 5121: ("B", 1)}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}


def accessor(doc, blob, i, first=None):
    """The first `first` elements (all when None) of accessor i, as lists."""
    a = doc["accessors"][i]
    view = doc["bufferViews"][a["bufferView"]]
    fmt, size = FORMATS[a["componentType"]]
    width = WIDTH[a["type"]]
    stride = view.get("byteStride", size * width)
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    count = a["count"] if first is None else min(first, a["count"])
    return [list(struct.unpack_from("<" + fmt * width, blob, start + k * stride)) for k in range(count)]


def cut(doc, blob, mesh, triangles):
    """The first `triangles` triangles of a mesh's first primitive, re-indexed: (positions,
    normals or None, texcoords or None, triangles)."""
    prim = doc["meshes"][mesh]["primitives"][0]
    idx = [v[0] for v in accessor(doc, blob, prim["indices"], 3 * triangles)]
    used = sorted(set(idx))
    remap = {v: k for k, v in enumerate(used)}
    attrs = prim["attributes"]

    def pick(name):
        if name not in attrs:
            return None
        values = accessor(doc, blob, attrs[name])
        return [values[v] for v in used]

    tris = [[remap[v] for v in idx[k : k + 3]] for k in range(0, len(idx), 3)]
    return pick("POSITION"), pick("NORMAL"), pick("TEXCOORD_0"), tris


def obj_text(p, n, t, tris, name=None, material=None, base=0):
    out = []
    if name:
        out.append(f"o {name}")
    out += [f"v {x:.6g} {y:.6g} {z:.6g}" for x, y, z in p]
    if n:
        out += [f"vn {x:.6g} {y:.6g} {z:.6g}" for x, y, z in n]
    if t:
        out += [f"vt {u:.6g} {v:.6g}" for u, v in t]
    if material:
        out.append(f"usemtl {material}")
    for tri in tris:
        c = [i + 1 + base for i in tri]
        if n and t:
            out.append("f " + " ".join(f"{i}/{i}/{i}" for i in c))
        elif n:
            out.append("f " + " ".join(f"{i}//{i}" for i in c))
        else:
            out.append("f " + " ".join(str(i) for i in c))
    return "\n".join(out) + "\n"


def pad(b, fill=b"\0"):
    return b + fill * (-len(b) % 4)


class GltfWriter:
    """Collects meshes into one buffer and writes them as GLB or as .gltf with a data: URI."""

    def __init__(self):
        self.blob = b""
        self.doc = {"asset": {"version": "2.0"}, "bufferViews": [], "accessors": [], "meshes": [], "nodes": []}

    def view(self, data):
        self.blob = pad(self.blob)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)})
        self.blob += data
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, values, kind, component):
        fmt, _ = FORMATS[component]
        flat = [x for v in values for x in (v if isinstance(v, list) else [v])]
        a = {"bufferView": self.view(struct.pack("<" + fmt * len(flat), *flat)), "componentType": component,
             "count": len(values), "type": kind}
        if kind == "VEC3" and component == 5126:
            a["min"] = [min(v[k] for v in values) for k in range(3)]
            a["max"] = [max(v[k] for v in values) for k in range(3)]
        self.doc["accessors"].append(a)
        return len(self.doc["accessors"]) - 1

    def mesh(self, name, p, n, indices, index_type=5125, mode=4, material=None):
        attrs = {"POSITION": self.accessor(p, "VEC3", 5126)}
        if n:
            attrs["NORMAL"] = self.accessor(n, "VEC3", 5126)
        prim = {"attributes": attrs, "indices": self.accessor(indices, "SCALAR", index_type), "mode": mode}
        if material is not None:
            prim["material"] = material
        self.doc["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def finish(self):
        self.doc["buffers"] = [{"byteLength": len(self.blob)}]
        if not self.doc["nodes"]:
            self.doc["nodes"] = [{"mesh": m} for m in range(len(self.doc["meshes"]))]
        self.doc.setdefault("scenes", [{"nodes": list(range(len(self.doc["nodes"])))}])
        self.doc.setdefault("scene", 0)

    def glb(self):
        self.finish()
        text = pad(json.dumps(self.doc, separators=(",", ":")).encode(), b" ")
        blob = pad(self.blob)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
        return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body

    def gltf(self):
        self.finish()
        self.doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(self.blob).decode()
        return json.dumps(self.doc).encode()


def strip_textures(material):
    """A shipped material without its texture references (the seeds carry no images)."""
    out = {}
    for k, v in material.items():
        if k.endswith("Texture"):
            continue
        if isinstance(v, dict):
            v = strip_textures(v)
        out[k] = v
    return out


def coarse(description):
    """A description with every sphere and torus at a few segments (the shipped counts removed)."""
    out = []
    for line in description.splitlines():
        if re.match(r"\s*(segments|rings|sides)\s*=", line):
            continue
        out.append(line)
        if re.match(r'\s*type\s*=\s*"sphere"', line):
            out += ["segments = 6", "rings = 3"]
        elif re.match(r'\s*type\s*=\s*"torus"', line):
            out += ["segments = 6", "sides = 3"]
    return "\n".join(out) + "\n"


def write(target, name, data):
    d = SEEDS / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data if isinstance(data, bytes) else data.encode())


def main():
    bunny, bunny_bin = read_glb(SCENES / "bunny.glb")
    car, car_bin = read_glb(SCENES / "toycar.glb")
    bp, _, _, btris = cut(bunny, bunny_bin, 0, 24)
    body = cut(car, car_bin, 0, 8)
    glass = cut(car, car_bin, 2, 6)

    # OBJ: plain, with normals and texture coordinates, objects and materials (the library after
    # a NUL byte), polygons and negative indices.
    write("obj", "bunny.obj", obj_text(bp, None, None, btris))
    write("obj", "car-body.obj", obj_text(*body))
    mtl = "newmtl ToyCar\nKd 0.55 0.06 0.05\nKs 0.5 0.5 0.5\nNs 100\nnewmtl Glass\nKd 0.3 0.8 0.3\nd 0.1\nNi 1.5\nillum 7\n"
    two = "mtllib car.mtl\n" + obj_text(*body, name="body", material="ToyCar")
    two += obj_text(*glass, name="glass", material="Glass", base=len(body[0]))
    write("obj", "car-with-mtl.obj", two + "\0" + mtl)
    write("obj", "polygons.obj", "g quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 1.5 0\nf 1 2 3 4\n"
          "g pentagon\nf -5 -4 -3 -1 -2\nl 1 2\np 3\nf 1 2\n")

    # glTF: the bunny's first triangles as GLB (u32, u16 and u8 indices, a strip), the car's
    # three meshes with their materials, TRS nodes and the camera as GLB and as .gltf.
    for index_type, name in [(5125, "bunny-u32.glb"), (5123, "bunny-u16.glb"), (5121, "bunny-u8.glb")]:
        w = GltfWriter()
        w.mesh("bunny", bp, None, [i for t in btris for i in t], index_type)
        write("gltf", name, w.glb())
    w = GltfWriter()
    w.mesh("strip", bp[:6], None, [0, 1, 2, 3, 4, 5], 5123, mode=5)
    w.mesh("fan", bp[:6], None, [0, 1, 2, 3, 4, 5], 5123, mode=6)
    write("gltf", "strip-and-fan.glb", w.glb())
    for ext in ["glb", "gltf"]:
        w = GltfWriter()
        w.doc["materials"] = [strip_textures(m) for m in car["materials"]]
        w.doc["extensionsUsed"] = [e for e in car["extensionsUsed"] if e != "KHR_texture_transform"]
        w.doc["cameras"] = car["cameras"]
        fabric = cut(car, car_bin, 1, 6)
        for k, (name, (p, n, _, tris)) in enumerate([("ToyCar", body), ("Fabric", fabric), ("Glass", glass)]):
            w.mesh(name, p, n, [i for t in tris for i in t], 5125, material=k)
        w.doc["nodes"] = [dict(n) for n in car["nodes"]]
        w.doc["scenes"], w.doc["scene"] = car["scenes"], car.get("scene", 0)
        write("gltf", f"car.{ext}", w.glb() if ext == "glb" else w.gltf())

    # Descriptions: the shipped ones (their meshes are served as stubs, their spheres and tori
    # made coarse: thousands of triangles per execution would slow the fuzzing tenfold) and
    # small ones.
    for toml in sorted(SCENES.glob("*.toml")):
        write("description", toml.name, coarse(toml.read_text()))
    write("description", "one-quad.toml", '[[object]]\ntype = "quad"\nsize = [1.0, 1.0]\n')
    write("description", "small-shapes.toml",
          'smooth_normals = true\nindirections = 3\n[material.m]\nkd = [0.5, 0.5, 0.5]\nkt = 0.5\n\n'
          '[[object]]\ntype = "sphere"\nradius = 1.0\nsegments = 5\nrings = 3\nmaterial = "m"\n'
          'translate = [1e6, 0.0, 0.0]\n\n'
          '[[object]]\ntype = "torus"\nmajor = 2.0\nminor = 0.5\nsegments = 4\nsides = 3\nscale = [1.0, -1.0, 2.0]\n'
          'axis = [0.0, 1.0, 1.0]\nangle = 30.0\n\n'
          '[[object]]\ntype = "box"\nsize = [1.0, 2.0, 3.0]\nrotate = [10.0, 20.0, 30.0]\nframe = false\n\n'
          '[[object]]\ntype = "mesh"\nfile = "part.obj"\noverrides = { Glass = "m" }\nsmooth_normals = false\n\n'
          '[[camera]]\nname = "c"\neye = [1e6, 0.0, 9.0]\nat = [1e6, 0.0, 0.0]\nfov = 50\n\n'
          '[[light]]\nposition = [1e6, 5.0, 5.0]\ncolour = [1.0, 1.0, 1.0]\n')


if __name__ == "__main__":
    main()
