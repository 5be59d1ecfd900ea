"""The dataset file's JSON Schema (`spadgen dataset schema --json-schema`) with a real validator
(python3-jsonschema): the shipped example dataset files validate and spadgen accepts them; mistakes spadgen
rejects (unknown key, wrong distribution, seeds of the wrong type, samples out of range) fail the schema too.

Usage: dataset_schema_test.py SPADGEN SOURCE_DIR."""
import json
import pathlib
import subprocess
import sys
import tempfile

import jsonschema

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "scenes"))
from json_schema_test import strip_comments  # noqa: E402


def main():
    spadgen, source = sys.argv[1], pathlib.Path(sys.argv[2])
    schema = json.loads(subprocess.run([spadgen, "dataset", "schema", "--json-schema"], check=True, capture_output=True,
                                       text=True).stdout)
    jsonschema.Draft202012Validator.check_schema(schema)
    validator = jsonschema.Draft202012Validator(schema)
    failed = 0

    def check(name, ok, detail=""):
        nonlocal failed
        print(("ok   " if ok else "FAIL ") + name + (": " + detail if detail and not ok else ""))
        failed += not ok

    def spadgen_accepts(doc, where):
        path = pathlib.Path(where) / "d.json"
        path.write_text(json.dumps(doc))
        r = subprocess.run([spadgen, "dataset", "plan", str(path)], capture_output=True, text=True)
        return r.returncode == 0, r.stdout + r.stderr

    examples = sorted((source / "examples" / "datasets").glob("*.json"))
    check("shipped example dataset files found", len(examples) >= 1, str(examples))
    for path in examples:
        doc = json.loads(strip_comments(path.read_text()))
        errors = [e.message for e in validator.iter_errors(doc)]
        check("valid: " + path.name, not errors, "; ".join(errors))
        r = subprocess.run([spadgen, "dataset", "plan", str(path)], capture_output=True, text=True)
        check("spadgen accepts: " + path.name, r.returncode == 0 and "error:" not in r.stdout, r.stdout[-400:] + r.stderr)

    scene = str(source / "scenes" / "paper" / "flat_target.json")
    good = {"seed": 1, "scenes": [scene], "samples": 3, "set": {"render.samples_per_pixel": 2},
            "grid": {"laser.average_power_mW": [1, 2]},
            "random": {"ambient.illuminance_lux": {"log_uniform": [1, 100]},
                       "camera.f_number": {"normal": [2, 0.2], "min": 1.5, "max": 3},
                       "render.max_bounces": {"uniform_int": [1, 3]}, "sensor.preset": {"choice": ["pixel_A", "pixel_B"]}},
            "seeds": {"chip": 4, "noise": "per_sample"}, "repeats": 2}
    with tempfile.TemporaryDirectory() as tmp:
        check("valid: a file with every key", not list(validator.iter_errors(good)))
        ok, out = spadgen_accepts(good, tmp)
        check("spadgen accepts it", ok, out)
        mistakes = {
            "unknown top-level key": dict(good, sampels=3),
            "samples 0": dict(good, samples=0),
            "a distribution spadgen does not know": dict(good, random={"camera.f_number": {"gauss": [2, 1]}}),
            "two distributions at once": dict(good, random={"camera.f_number": {"uniform": [2, 3], "log_uniform": [2, 3]}}),
            "min with a uniform": dict(good, random={"camera.f_number": {"uniform": [2, 3], "min": 2}}),
            "a grid key with no values": dict(good, grid={"camera.f_number": []}),
            "a seed that is a string": dict(good, seeds={"chip": "one"}),
            "an unknown seed": dict(good, seeds={"chips": 1}),
            "repeats 0": dict(good, repeats=0),
            "no scenes": {k: v for k, v in good.items() if k != "scenes"},
        }
        for name, doc in mistakes.items():
            check("schema rejects: " + name, bool(list(validator.iter_errors(doc))))
            ok, out = spadgen_accepts(doc, tmp)
            check("spadgen rejects: " + name, not ok, out)
    print("failed:", failed)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
