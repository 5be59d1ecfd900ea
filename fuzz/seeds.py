#!/usr/bin/env python3
"""Writes the fuzzing harnesses' seed corpora and dictionaries into OUT (fuzz/README.md):

  OUT/seeds/scene_file/  the shipped scene files (scenes/paper/*.json)
  OUT/seeds/set/         --set lines: every key at its default (from docs/scene-file.md), and the overrides
                         the README and the hardening tests use
  OUT/seeds/gltf/        the shipped glTF files and tests/data/gltf with their buffers embedded, small
                         hand-made files for each feature the loader reads, each as .gltf and as .glb
  OUT/seeds/dataset/     the shipped dataset files, and small ones on flat_target.json with every
                         distribution, seeds, repeats and a grid over two scenes
  OUT/seeds/arrays/      .npy files of every dtype spadgen reads (format 1.0 and 2.0, shapes of rank 0 to 3,
                         empty ones), and Zarr stores (the harness's input layout: fuzz_arrays.cpp) of every
                         dtype, uncompressed and Blosc (a stored Blosc buffer), one chunk or several, with
                         fill values
  OUT/scene_file.dict, OUT/set.dict, OUT/gltf.dict, OUT/dataset.dict, OUT/arrays.dict   libFuzzer
                         dictionaries (keys, choices, JSON tokens)

Usage: fuzz/seeds.py OUT   (from anywhere; the repository is this file's parent folder)
"""
import base64
import json
import pathlib
import re
import struct
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent

# A 2x2 RGBA PNG, as the fuzz_gltf harness also writes beside its input (image.png).
PNG = base64.b64decode(
    "iVBORw0KGgoAAAANSUhEUgAAAAIAAAACCAYAAABytg0kAAAAE0lEQVR4nGP4z8DwHwyBNAg0AABJSQl4KKDbdwAAAABJRU5ErkJggg==")
# An 8x8 JPEG of one colour (200, 40, 90; quality 95), for the JPEG decoder (the loader's tests use it too).
JPEG = (ROOT / "tests" / "data" / "images" / "solid_8x8.jpg").read_bytes()


def schema_keys():
    """(dotted key, type, default, choices) of every key, from the table docs/scene-file.md holds (a test
    keeps it equal to `spadgen schema`)."""
    keys = []
    for line in (ROOT / "docs/scene-file.md").read_text().splitlines():
        m = re.match(r"^\| `([a-zA-Z0-9_.]+)` \| ([^|]*)\| [^|]*\| ([^|]*)\| ([^|]*)\|", line)
        if not m:
            continue
        default = m.group(3).strip().strip("`")
        keys.append((m.group(1), m.group(2).strip(), default, re.findall(r'"([^"]+)"', m.group(4))))
    if len(keys) < 50:
        sys.exit("fuzz/seeds.py: found only %d keys in docs/scene-file.md" % len(keys))
    return keys


def dict_entry(value):
    out = ""
    for b in value.encode():
        c = chr(b)
        out += "\\" + c if c in '"\\' else c if 32 <= b < 127 else "\\x%02X" % b
    return '"' + out + '"\n'


JSON_TOKENS = ["{", "}", "[", "]", ":", ",", '""', "true", "false", "null", "0", "-1", "0.5", "1e309", "-1e309",
               "1e-320", "1e308", "9007199254740993", "18446744073709551616", "-0", "//", "/*", "*/", "\\u0000",
               "\\ud800", "\\\"", "\xef\xbb\xbf"]


def write_dicts(out, keys):
    names, dotted, choices = set(), set(), set()
    for key, _, _, ch in keys:
        parts = key.split(".")
        names.update(parts)
        dotted.add(key + "=")
        for i in range(1, len(parts)):
            dotted.add(".".join(parts[:i]) + ".")
        choices.update(ch)
    with open(out / "scene_file.dict", "w") as f:
        f.write("# scene-file keys and sections, choices, JSON tokens (fuzz/seeds.py)\n")
        for n in sorted(names):
            f.write(dict_entry('"%s"' % n))
        for c in sorted(choices):
            f.write(dict_entry('"%s"' % c))
        for t in JSON_TOKENS:
            f.write(dict_entry(t))
    with open(out / "set.dict", "w") as f:
        f.write("# --set keys (dotted, with '='), their sections, choices, JSON tokens (fuzz/seeds.py)\n")
        for d in sorted(dotted):
            f.write(dict_entry(d))
        for c in sorted(choices):
            f.write(dict_entry(c))
        for t in JSON_TOKENS + ["\n", "=", "[0,0,64,64]", "[1e20,0,1]"]:
            f.write(dict_entry(t))
    gltf_words = [
        "asset", "version", "2.0", "generator", "scene", "scenes", "nodes", "children", "mesh", "meshes", "camera",
        "cameras", "matrix", "translation", "rotation", "scale", "primitives", "attributes", "POSITION", "NORMAL",
        "TEXCOORD_0", "TEXCOORD_1", "TANGENT", "COLOR_0", "JOINTS_0", "WEIGHTS_0", "indices", "material", "mode",
        "targets", "weights", "accessors", "bufferView", "byteOffset", "componentType", "normalized", "count",
        "type", "SCALAR", "VEC2", "VEC3", "VEC4", "MAT2", "MAT3", "MAT4", "max", "min", "sparse", "values",
        "bufferViews", "buffer", "byteLength", "byteStride", "target", "buffers", "uri", "images", "mimeType",
        "image/png", "image/jpeg", "textures", "sampler", "source", "samplers", "wrapS", "wrapT", "magFilter",
        "minFilter", "materials", "pbrMetallicRoughness", "baseColorFactor", "baseColorTexture", "index",
        "texCoord", "metallicFactor", "roughnessFactor", "emissiveFactor", "doubleSided", "alphaMode", "MASK",
        "BLEND", "OPAQUE", "alphaCutoff", "extensions", "extensionsUsed", "extensionsRequired", "extras", "name",
        "perspective", "orthographic", "yfov", "aspectRatio", "znear", "zfar", "xmag", "ymag", "skins",
        "animations", "KHR_materials_transmission", "transmissionFactor", "KHR_materials_ior", "ior",
        "KHR_materials_volume", "thicknessFactor", "attenuationDistance", "attenuationColor",
        "KHR_materials_emissive_strength", "emissiveStrength", "KHR_lights_punctual", "lights", "light", "point",
        "spot", "directional", "color", "intensity", "range", "innerConeAngle", "outerConeAngle",
        "KHR_mesh_quantization", "KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_texture_transform",
        "KHR_materials_specular", "buffer.bin", "image.png", "data:application/octet-stream;base64,",
        "data:image/png;base64,", "%20"]
    with open(out / "gltf.dict", "w") as f:
        f.write("# glTF 2.0 properties and values, the extensions spadgen reads or names, GLB chunks (fuzz/seeds.py)\n")
        for w in gltf_words:
            f.write(dict_entry('"%s"' % w))
        for n in [5120, 5121, 5122, 5123, 5125, 5126, 34962, 34963, 10497, 33071, 33648, 9728, 9729]:
            f.write(dict_entry(str(n)))
        for t in JSON_TOKENS:
            f.write(dict_entry(t))
        f.write('"glTF\\x02\\x00\\x00\\x00"\n"JSON"\n"BIN\\x00"\n')


def set_seeds(out, keys):
    d = out / "seeds" / "set"
    d.mkdir(parents=True, exist_ok=True)
    lines = []
    for key, _, default, _ in keys:
        if default != "required":
            lines.append("%s=%s" % (key, default))
    lines += [
        "laser.average_power_mW=5", "camera.crop=[0,0,64,64]", "camera.position_m=[0,0,1.6]", "seeds.noise=2",
        "acquisition.mode=intensity\nacquisition.intensity.exposure=dual\nacquisition.frames=4080",
        "render.window_start_ns=0\nrender.window_stop_ns=36\ncamera.height_px=1000", "camera.gltf_camera=Camera",
        "outputs.light=true\noutputs.transient=true\noutputs.transient_crop=[10,10,4,4]",
        "acquisition.gate_sweep.step_ps=1e-6", "camera.position_m=[1e20,0,1]", "laser.offset_m=[0,0,1e17]",
        "sensor.gate.length_fwhm_ps=1e6", "camera.pixel_pitch_um=1e-200", "laser.repetition_rate_MHz=1e-100",
        "seed=-1", "camera.f_numbr=2", "camera=1", "camera.crop=[[[[[[]]]]]]", "laser.beam=gltf_light",
        "gltf=multi_object.gltf", "description=x=y", "camera.vertical_fov_deg=null",
    ]
    for i, text in enumerate(lines):
        (d / ("set_%03d" % i)).write_text(text)


def scene_file_seeds(out):
    d = out / "seeds" / "scene_file"
    d.mkdir(parents=True, exist_ok=True)
    for f in sorted((ROOT / "scenes/paper").glob("*.json")):
        (d / f.name).write_bytes(f.read_bytes())
    (d / "minimal.json").write_text('{"gltf": "flat_target.gltf"}')
    (d / "comments.json").write_text('// c\n{"gltf": "flat_target.gltf", /* c */ "camera": {"crop": [0, 0, 8, 8]}}')


def glb(doc, binary):
    """A GLB of the document and its binary chunk (both padded to 4 bytes)."""
    if binary:
        doc = dict(doc)
        doc["buffers"] = [dict(doc["buffers"][0])]
        doc["buffers"][0].pop("uri", None)
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    out = struct.pack("<I4s", len(text), b"JSON") + text
    if binary:
        binary += b"\0" * (-len(binary) % 4)
        out += struct.pack("<I4s", len(binary), b"BIN\0") + binary
    return struct.pack("<4sII", b"glTF", 2, 12 + len(out)) + out


class Builder:
    """A small glTF: one buffer, views and accessors appended as the meshes need them."""

    def __init__(self):
        self.bin = b""
        self.doc = {"asset": {"version": "2.0", "generator": "spadgen fuzz/seeds.py"}, "scene": 0,
                    "scenes": [{"name": "main", "nodes": []}], "nodes": [], "meshes": [], "accessors": [],
                    "bufferViews": [], "buffers": []}

    def view(self, data, target=None):
        self.bin += b"\0" * (-len(self.bin) % 4)
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target:
            v["target"] = target
        self.bin += data
        self.doc["bufferViews"].append(v)
        return len(self.doc["bufferViews"]) - 1

    def accessor(self, fmt, values, ctype, atype, ncomp, normalized=False, bounds=False):
        acc = {"bufferView": self.view(struct.pack("<%d%s" % (len(values), fmt), *values)), "componentType": ctype,
               "count": len(values) // ncomp, "type": atype}
        if normalized:
            acc["normalized"] = True
        if bounds:
            acc["min"] = [min(values[i::ncomp]) for i in range(ncomp)]
            acc["max"] = [max(values[i::ncomp]) for i in range(ncomp)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def mesh(self, prim, name="mesh"):
        self.doc["meshes"].append({"name": name, "primitives": [prim]})
        return len(self.doc["meshes"]) - 1

    def node(self, node, root=True):
        self.doc["nodes"].append(node)
        i = len(self.doc["nodes"]) - 1
        if root:
            self.doc["scenes"][0]["nodes"].append(i)
        return i

    def quad(self, material=None, with_uv=False):
        pos = self.accessor("f", [-1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0], 5126, "VEC3", 3, bounds=True)
        attrs = {"POSITION": pos, "NORMAL": self.accessor("f", [0, 0, 1] * 4, 5126, "VEC3", 3)}
        if with_uv:
            attrs["TEXCOORD_0"] = self.accessor("f", [0, 1, 1, 1, 1, 0, 0, 0], 5126, "VEC2", 2)
        prim = {"attributes": attrs, "indices": self.accessor("H", [0, 1, 2, 0, 2, 3], 5123, "SCALAR", 1)}
        if material is not None:
            prim["material"] = material
        return self.mesh(prim, "quad")

    def finish(self):
        self.doc["buffers"] = [{"byteLength": len(self.bin),
                                "uri": "data:application/octet-stream;base64," + base64.b64encode(self.bin).decode()}]
        return self.doc, self.bin


def handmade():
    files = {}
    # A quad, a perspective camera, lights of each type.
    b = Builder()
    b.node({"name": "target", "mesh": b.quad(), "translation": [0, 0, -1]})
    b.doc["cameras"] = [{"name": "cam", "type": "perspective", "perspective": {"yfov": 0.5, "aspectRatio": 2.048,
                                                                               "znear": 0.01}}]
    b.node({"name": "Camera", "camera": 0, "rotation": [0, 0, 0, 1]})
    b.doc["extensionsUsed"] = ["KHR_lights_punctual"]
    b.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"name": "laser", "type": "spot", "intensity": 10, "spot": {"innerConeAngle": 0.1, "outerConeAngle": 0.3}},
        {"name": "bulb", "type": "point", "color": [1, 0.5, 0.2], "intensity": 3, "range": 5},
        {"name": "sun", "type": "directional", "intensity": 1000}]}}
    for i, n in enumerate(["laser", "bulb", "sun"]):
        b.node({"name": n, "translation": [0, 0.1 * i, 0], "extensions": {"KHR_lights_punctual": {"light": i}}})
    files["camera_lights"] = b.finish()
    # Materials with every extension spadgen reads, and textured quads (PNG by bufferView and by data URI, JPEG).
    b = Builder()
    b.doc["extensionsUsed"] = ["KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume",
                               "KHR_materials_emissive_strength"]
    b.doc["materials"] = [
        {"name": "glass", "pbrMetallicRoughness": {"baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0,
                                                   "roughnessFactor": 0}, "doubleSided": True,
         "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}, "KHR_materials_ior": {"ior": 1.5},
                        "KHR_materials_volume": {"thicknessFactor": 0.002, "attenuationDistance": 1,
                                                 "attenuationColor": [0.9, 0.9, 0.9]}}},
        {"name": "lamp", "emissiveFactor": [1, 1, 1], "extensions": {"KHR_materials_emissive_strength": {
            "emissiveStrength": 100}}},
        {"name": "chart", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0, "texCoord": 0},
                                                   "metallicFactor": 0}},
        {"name": "chart2", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}}]
    png_view = b.view(PNG)
    b.doc["images"] = [{"bufferView": png_view, "mimeType": "image/png"},
                       {"uri": "data:image/png;base64," + base64.b64encode(PNG).decode()},
                       {"bufferView": b.view(JPEG), "mimeType": "image/jpeg"}]
    b.doc["samplers"] = [{"wrapS": 33071, "wrapT": 33648}]
    b.doc["textures"] = [{"source": 0, "sampler": 0}, {"source": 1}, {"source": 2}]
    b.doc["materials"].append({"name": "photo", "pbrMetallicRoughness": {"baseColorTexture": {"index": 2}}})
    for i in range(4):
        b.node({"name": "m%d" % i, "mesh": b.quad(i, with_uv=i >= 2), "translation": [i, 0, -2]})
    files["materials"] = b.finish()
    # Node hierarchy (matrix, TRS, scale), two scenes, a sparse accessor, strips and fans, quantized attributes.
    b = Builder()
    b.doc["extensionsUsed"] = ["KHR_mesh_quantization"]
    b.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    q = b.accessor("h", [-32767, -32767, 0, 0, 32767, -32767, 0, 0, 0, 32767, 0, 0], 5122, "VEC4", 4, normalized=True)
    b.doc["accessors"][q]["type"] = "VEC3"
    b.doc["accessors"][q]["count"] = 3
    b.doc["bufferViews"][b.doc["accessors"][q]["bufferView"]]["byteStride"] = 8
    quant = b.mesh({"attributes": {"POSITION": q}}, "quantized")
    strip = b.mesh({"attributes": {"POSITION": b.accessor("f", [0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0], 5126, "VEC3", 3,
                                                          bounds=True)}, "mode": 5}, "strip")
    fan = b.mesh({"attributes": {"POSITION": b.accessor("f", [0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0], 5126, "VEC3", 3,
                                                        bounds=True)}, "mode": 6}, "fan")
    base = b.accessor("f", [0, 0, 0, 1, 0, 0, 0, 1, 0], 5126, "VEC3", 3, bounds=True)
    b.doc["accessors"][base]["sparse"] = {"count": 1, "indices": {"bufferView": b.view(struct.pack("<B", 2)),
                                                                  "componentType": 5121},
                                          "values": {"bufferView": b.view(struct.pack("<3f", 0, 2, 0))}}
    sparse = b.mesh({"attributes": {"POSITION": base}}, "sparse")
    lines = b.mesh({"attributes": {"POSITION": base}, "mode": 1}, "lines")
    child = b.node({"name": "child", "mesh": quant, "scale": [2, 2, 2], "rotation": [0, 0.7071068, 0, 0.7071068]},
                   root=False)
    grand = b.node({"name": "grand", "mesh": strip, "translation": [0, 0, -1]}, root=False)
    b.doc["nodes"][child]["children"] = [grand]
    b.node({"name": "parent", "children": [child],
            "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, -3, 1]})
    b.node({"name": "fan", "mesh": fan})
    b.node({"name": "sparse", "mesh": sparse})
    other = b.node({"name": "lines", "mesh": lines}, root=False)
    b.doc["scenes"].append({"name": "other", "nodes": [other]})
    files["hierarchy"] = b.finish()
    # External buffer and image: the names the harness writes beside its input.
    b = Builder()
    b.doc["buffers"] = [{"uri": "buffer.bin", "byteLength": 44}]
    b.doc["bufferViews"] = [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}]
    b.doc["accessors"] = [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0],
                           "max": [1, 1, 0]}, {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}]
    b.doc["images"] = [{"uri": "image.png"}]
    b.doc["textures"] = [{"source": 0}]
    b.doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    b.doc["meshes"] = [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0}]}]
    b.node({"mesh": 0})
    files["external"] = (b.doc, None)
    return files


def embed(path):
    """A shipped .gltf with its external buffers embedded; its images replaced by a 2x2 PNG."""
    doc = json.loads(path.read_text())
    blobs = []
    for buf in doc["buffers"]:
        uri = buf["uri"]
        blobs.append(base64.b64decode(uri.split(",", 1)[1]) if uri.startswith("data:") else (path.parent / uri).read_bytes())
    for img in doc.get("images", []):
        if "bufferView" in img:
            view = doc["bufferViews"][img["bufferView"]]
            buf = view["buffer"]
            start = view.get("byteOffset", 0)
            blob = blobs[buf]
            # The image's bytes replaced by the small PNG, the views after it moved.
            blobs[buf] = blob[:start] + PNG + b"\0" * (-len(PNG) % 4) + blob[start + view["byteLength"]:]
            shift = len(PNG) + (-len(PNG) % 4) - view["byteLength"]
            for v in doc["bufferViews"]:
                if v["buffer"] == buf and v.get("byteOffset", 0) > start:
                    v["byteOffset"] = v.get("byteOffset", 0) + shift
            view["byteLength"] = len(PNG)
    for buf, blob in zip(doc["buffers"], blobs):
        buf["byteLength"] = len(blob)
        buf["uri"] = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    return doc, blobs[0] if len(blobs) == 1 else None


DATASET_WORDS = ["description", "seed", "scenes", "samples", "set", "grid", "random", "seeds", "repeats", "uniform",
                 "log_uniform", "normal", "uniform_int", "choice", "min", "max", "light", "chip", "noise", "per_sample",
                 "../../scenes/paper/flat_target.json", "../../scenes/paper/test_chart.json", "nodes.target.",
                 "materials.white_paper.", "translation_m[2]", "rotation_deg[1]", "scale[0]", "base_color[0]",
                 "roughness", "transmission"]


def dataset_seeds(out, keys):
    d = out / "seeds" / "dataset"
    d.mkdir(parents=True, exist_ok=True)
    for f in sorted((ROOT / "examples/datasets").glob("*.json")):
        (d / f.name).write_bytes(f.read_bytes())
    flat = '"scenes": ["../../scenes/paper/flat_target.json"]'
    texts = [
        '{%s}' % flat,
        '{%s, "samples": 5, "seed": 7}' % flat,
        '{%s, "samples": 100000000, "grid": {"laser.average_power_mW": [1, 2, 3]}}' % flat,
        '{"scenes": ["../../scenes/paper/flat_target.json", "../../scenes/paper/test_chart.json"], '
        '"grid": {"camera.f_number": [1.4, 2.8], "sensor.preset": ["pixel_A", "pixel_B"]}}',
        '{%s, "samples": 4, "random": {"laser.average_power_mW": {"uniform": [1, 5]}, '
        '"ambient.illuminance_lux": {"log_uniform": [1, 1000]}, '
        '"nodes.target.translation_m[2]": {"normal": [0, 0.1], "min": -0.2, "max": 0.2}, '
        '"acquisition.frames": {"uniform_int": [1, 255]}, "sensor.preset": {"choice": ["pixel_A", "pixel_B"]}}}' % flat,
        '{%s, "samples": 3, "set": {"render.samples_per_pixel": 2, "camera.crop": [0, 0, 8, 8]}, '
        '"seeds": {"chip": 1, "light": "per_sample"}, "repeats": 3}' % flat,
        '// c\n{%s, /* c */ "random": {"materials.white_paper.roughness": {"uniform": [0.1, 0.9]}}}' % flat,
    ]
    for i, text in enumerate(texts):
        (d / ("dataset_%02d.json" % i)).write_text(text)
    with open(out / "dataset.dict", "w") as f:
        f.write("# dataset-file keys, distributions, scene paths and scene-file keys (fuzz/seeds.py)\n")
        for w in DATASET_WORDS:
            f.write(dict_entry('"%s"' % w))
        for key, _, _, _ in keys:
            f.write(dict_entry('"%s"' % key))
        for t in JSON_TOKENS:
            f.write(dict_entry(t))


def gltf_seeds(out):
    d = out / "seeds" / "gltf"
    d.mkdir(parents=True, exist_ok=True)
    files = handmade()
    for p in [ROOT / "scenes/paper/flat_target.gltf", ROOT / "scenes/paper/test_chart.gltf",
              ROOT / "tests/data/gltf/blender_like/scene.gltf"]:
        files[p.parent.name + "_" + p.stem] = embed(p)
    for name, (doc, binary) in files.items():
        (d / (name + ".gltf")).write_text(json.dumps(doc, indent=1))
        (d / (name + ".glb")).write_bytes(glb(doc, binary))


# The dtypes spadgen's array readers take: (.npy / .zarray descr, struct format of one element).
DTYPES = [("<f4", "f"), ("<f8", "d"), ("|u1", "B"), ("<u2", "H"), ("<i4", "i"), ("<i8", "q")]


def npy_file(descr, fmt, shape, version=1):
    """A .npy file as np.save writes it: the header dict padded with spaces and a newline so that the data
    start at a multiple of 64 bytes."""
    dims = "(%s)" % ("".join("%d," % d for d in shape) if len(shape) == 1 else ", ".join(str(d) for d in shape))
    header = "{'descr': '%s', 'fortran_order': False, 'shape': %s, }" % (descr, dims)
    prefix = 10 if version == 1 else 12
    pad = -(prefix + len(header) + 1) % 64
    header = (header + " " * pad + "\n").encode()
    count = 1
    for d in shape:
        count *= d
    values = [(i * 37 % 11) for i in range(count)]
    length = struct.pack("<H", len(header)) if version == 1 else struct.pack("<I", len(header))
    return b"\x93NUMPY" + bytes([version, 0]) + length + header + struct.pack("<%d%s" % (count, fmt), *values)


def blosc_stored(raw, typesize):
    """A Blosc 1 buffer holding raw as it is (the memcpyed flag): the 16-byte header, then the bytes."""
    flags = 0x02  # BLOSC_MEMCPYED, no shuffle
    return struct.pack("<BBBBIII", 2, 1, flags, typesize, len(raw), len(raw), len(raw) + 16) + raw


def zarr_input(zarray, chunk, fill_mode=False):
    text = json.dumps(zarray).encode()
    return bytes([3 if fill_mode else 1]) + struct.pack("<H", len(text)) + text + chunk


def arrays_seeds(out):
    d = out / "seeds" / "arrays"
    d.mkdir(parents=True, exist_ok=True)
    for descr, fmt in DTYPES:
        tag = descr[1:]
        for shape in [(), (0,), (5,), (3, 4), (2, 3, 4), (4, 0, 2)]:
            for version in (1, 2):
                name = "npy_%s_%s_v%d.npy" % (tag, "x".join(map(str, shape)) or "scalar", version)
                (d / name).write_bytes(b"\x00" + npy_file(descr, fmt, shape, version))
        size = struct.calcsize(fmt)
        for shape, chunks in [((6,), (6,)), ((6,), (4,)), ((3, 4), (3, 4)), ((3, 4), (2, 3)), ((2, 2, 3), (1, 2, 3))]:
            n = 1
            for c in chunks:
                n *= c
            raw = struct.pack("<%d%s" % (n, fmt), *[(i * 7 % 5) for i in range(n)])
            base = {"zarr_format": 2, "shape": list(shape), "chunks": list(chunks), "dtype": descr, "order": "C",
                    "compressor": None, "fill_value": None, "filters": None, "dimension_separator": "."}
            stem = "zarr_%s_%s_%s" % (tag, "x".join(map(str, shape)), "x".join(map(str, chunks)))
            (d / (stem + "_raw")).write_bytes(zarr_input(base, raw))
            blosc = dict(base, compressor={"id": "blosc", "cname": "zstd", "clevel": 1, "shuffle": 1, "blocksize": 0})
            (d / (stem + "_blosc")).write_bytes(zarr_input(blosc, blosc_stored(raw, size)))
            filled = dict(base, fill_value="NaN" if descr[1] == "f" else 7)
            (d / (stem + "_fill")).write_bytes(zarr_input(filled, raw, fill_mode=True))
    words = ["zarr_format", "shape", "chunks", "dtype", "order", "compressor", "fill_value", "filters",
             "dimension_separator", "blosc", "id", "cname", "zstd", "lz4", "clevel", "shuffle", "blocksize", "NaN",
             "Infinity", "-Infinity", "descr", "fortran_order", "False", "True", "\x93NUMPY"]
    with open(out / "arrays.dict", "w") as f:
        for w in words:
            f.write(dict_entry('"%s"' % w))
            f.write(dict_entry("'%s'" % w))
        for descr, _ in DTYPES:
            f.write(dict_entry('"%s"' % descr))
            f.write(dict_entry("'%s'" % descr))
        for t in JSON_TOKENS:
            f.write(dict_entry(t))


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    out = pathlib.Path(sys.argv[1])
    out.mkdir(parents=True, exist_ok=True)
    keys = schema_keys()
    write_dicts(out, keys)
    set_seeds(out, keys)
    scene_file_seeds(out)
    gltf_seeds(out)
    dataset_seeds(out, keys)
    arrays_seeds(out)


if __name__ == "__main__":
    main()
