"""The JSON Schema that `spadgen schema --json-schema` prints, checked with a real validator (python3-jsonschema):
every shipped scene file validates, and the mistakes spadgen rejects (unknown key, wrong choice, value out of
range, wrong type, key in the wrong section, the same of the glTF's nodes and materials) fail the schema too, while
spadgen accepts what the schema accepts.

Usage: json_schema_test.py SPADGEN SOURCE_DIR. Prints one line per case and "N passed, N failed"."""
import copy
import json
import pathlib
import subprocess
import sys

import jsonschema


def strip_comments(text):
    """JSON with // and /* */ comments (as scene files allow) to plain JSON; strings are left alone."""
    out, i, n = [], 0, len(text)
    while i < n:
        c = text[i]
        if c == '"':
            j = i + 1
            while text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            out.append(text[i:j + 1])
            i = j + 1
        elif text.startswith("//", i):
            i = text.find("\n", i)
            i = n if i < 0 else i
        elif text.startswith("/*", i):
            i = text.index("*/", i) + 2
        else:
            out.append(c)
            i += 1
    return "".join(out)


def main():
    spadgen, source = sys.argv[1], pathlib.Path(sys.argv[2])
    schema = json.loads(subprocess.run([spadgen, "schema", "--json-schema"], check=True, capture_output=True,
                                       text=True).stdout)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    passed = failed = 0

    def check(name, ok, detail=""):
        nonlocal passed, failed
        print(("ok   " if ok else "FAIL ") + name + (": " + detail if detail and not ok else ""))
        passed, failed = passed + ok, failed + (not ok)

    scenes = sorted((source / "scenes" / "paper").glob("*.json"))
    check("shipped scene files found", len(scenes) >= 4, str(scenes))
    base = None
    for path in scenes:
        doc = json.loads(strip_comments(path.read_text()))
        errors = [e.message for e in validator.iter_errors(doc)]
        check("valid: " + path.name, not errors, "; ".join(errors))
        if path.name == "flat_target.json":
            base = (path, doc)

    # Each mistake: the schema rejects it, and so does spadgen (the same file through `spadgen info`).
    mutations = {
        "unknown key": lambda d: d["camera"].__setitem__("f_numbr", 2),
        "key in the wrong section": lambda d: d["camera"].__setitem__("wavelength_nm", 510),
        "unknown section": lambda d: d.__setitem__("lazer", {}),
        "wrong choice": lambda d: d["laser"].__setitem__("beam", "spot"),
        "out of range": lambda d: d["camera"].__setitem__("f_number", 100),
        "open lower bound": lambda d: d.setdefault("sensor", {}).setdefault("pixel_A", {}).__setitem__("fill_factor", 0),
        "wrong type": lambda d: d["camera"].__setitem__("width_px", "1024"),
        "not an integer": lambda d: d["camera"].__setitem__("width_px", 10.5),
        "vector of two": lambda d: d["camera"].__setitem__("position_m", [0, 0]),
        "missing gltf": lambda d: d.pop("gltf"),
        "unknown key of a node": lambda d: d.setdefault("nodes", {}).__setitem__("target", {"translaton_m": [0, 0, 1]}),
        "node rotation out of range": lambda d: d.setdefault("nodes", {}).__setitem__("target", {"rotation_deg": [0, 400, 0]}),
        "node scale of two": lambda d: d.setdefault("nodes", {}).__setitem__("target", {"scale": [1, 1]}),
        "node given as a vector": lambda d: d.setdefault("nodes", {}).__setitem__("target", [0, 0, 1]),
        "empty node name": lambda d: d.setdefault("nodes", {}).__setitem__("", {}),
        "material colour above 1": lambda d: d.setdefault("materials", {}).__setitem__("white_paper", {"base_color": [1.2, 0, 0]}),
        "material ior below 1": lambda d: d.setdefault("materials", {}).__setitem__("white_paper", {"ior": 0.9}),
        "material key of a node": lambda d: d.setdefault("materials", {}).__setitem__("white_paper", {"scale": [1, 1, 1]}),
    }
    path, doc = base
    for name, mutate in mutations.items():
        bad = copy.deepcopy(doc)
        mutate(bad)
        check("schema rejects: " + name, not validator.is_valid(bad))
        probe = path.parent / (".json_schema_probe_" + str(abs(hash(name))) + ".json")
        try:
            probe.write_text(json.dumps(bad))
            r = subprocess.run([spadgen, "info", str(probe)], capture_output=True, text=True)
        finally:
            probe.unlink()
        check("spadgen rejects: " + name, r.returncode == 1, r.stderr.strip()[:200])
    # A nullable key given null, a key given its default explicitly: both accepted by both.
    good = copy.deepcopy(doc)
    good["camera"]["crop"] = None
    good.setdefault("seeds", {})["noise"] = 3
    check("schema accepts null and explicit keys", validator.is_valid(good))
    # The glTF's nodes and materials by name (flat_target.gltf: node "target", material "white_paper"), a null
    # component keeping the glTF's: accepted by both.
    edited = copy.deepcopy(doc)
    edited["nodes"] = {"target": {"translation_m": [None, None, 0.1], "rotation_deg": [10, 0, 0], "scale": [1, 1, 1]}}
    edited["materials"] = {"white_paper": {"base_color": [0.3, 0.3, 0.3], "roughness": 1, "metallic": 0,
                                           "transmission": 0, "ior": 1.5, "thickness_mm": 0}}
    errors = [e.message for e in validator.iter_errors(edited)]
    check("schema accepts nodes and materials", not errors, "; ".join(errors))
    probe = path.parent / ".json_schema_probe_edited.json"
    try:
        probe.write_text(json.dumps(edited))
        r = subprocess.run([spadgen, "info", str(probe)], capture_output=True, text=True)
    finally:
        probe.unlink()
    check("spadgen accepts nodes and materials", r.returncode == 0, r.stderr.strip()[:200])
    print(f"{passed} passed, {failed} failed")
    return 0 if failed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
