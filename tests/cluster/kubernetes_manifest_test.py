#!/usr/bin/env python3
"""The shipped Kubernetes Indexed Job (examples/kubernetes/dataset-indexed-job.yaml) against the contract
spadgen reads: an Indexed Job whose pods get JOB_COMPLETION_INDEX from Kubernetes and JOB_COMPLETIONS from
the manifest, equal to spec.completions, running `spadgen dataset run`. Then the pods' environment is
replayed with the real program on a small dataset, one process per index as the Job runs them, and the
result must equal a serial run byte for byte (there is no Kubernetes cluster on the test machine).

    kubernetes_manifest_test.py SOURCE_DIR SPADGEN_BINARY
"""
import os
import subprocess
import sys
import tempfile

import yaml

src, spadgen = sys.argv[1], sys.argv[2]
manifest = yaml.safe_load(open(os.path.join(src, "examples/kubernetes/dataset-indexed-job.yaml")))
assert manifest["kind"] == "Job" and manifest["apiVersion"] == "batch/v1", manifest["kind"]
spec = manifest["spec"]
assert spec["completionMode"] == "Indexed", "spadgen reads JOB_COMPLETION_INDEX, which only Indexed Jobs set"
container = spec["template"]["spec"]["containers"][0]
env = {e["name"]: e["value"] for e in container["env"]}
completions = spec["completions"]
assert int(env["JOB_COMPLETIONS"]) == completions, f"JOB_COMPLETIONS {env['JOB_COMPLETIONS']} != completions {completions}"
args = container["args"]
assert args[:2] == ["dataset", "run"] and "-o" in args, args
mounts = {m["mountPath"] for m in container["volumeMounts"]}
assert args[2] in mounts, f"the dataset file {args[2]} is not mounted ({mounts})"
assert os.path.dirname(args[args.index("-o") + 1]) in mounts, "the output folder is not on a mounted volume"
cpu = str(container["resources"]["requests"]["cpu"])
assert "--threads" in args and args[args.index("--threads") + 1] == cpu, \
    f"--threads is not the CPU request {cpu} ({args}): a pod without a cpuset starts a thread per core of its node"

# The image copies the source tree: the host's build folders stay out of the build context (.dockerignore),
# as their CMakeCache.txt names another source folder, which cmake in the image refuses. Docker matches
# top-level names with Go's filepath.Match, which fnmatch agrees with for these patterns.
import fnmatch
dockerfile = open(os.path.join(src, "examples/kubernetes/Dockerfile")).read()
assert "COPY . /src/spadgen" in dockerfile and "-B build" in dockerfile, "the Dockerfile changed: check what it copies"
ignored = [p.strip() for p in open(os.path.join(src, ".dockerignore")) if p.strip() and not p.startswith("#")]
for name in ("build", "build-sanitizers", "build-fuzz", ".git"):
    assert any(fnmatch.fnmatchcase(name, p) for p in ignored), f".dockerignore does not leave out {name}/ ({ignored})"
for name in ("CMakeLists.txt", "render", "sensor", "scenes", "python", ".ci"):
    assert not any(fnmatch.fnmatchcase(name, p) for p in ignored), f".dockerignore leaves out {name}, which the image builds from"

with tempfile.TemporaryDirectory() as w:
    dataset = os.path.join(w, "dataset.json")
    with open(dataset, "w") as f:
        f.write('{"seed": 8, "scenes": ["%s/scenes/paper/multi_object.json"], "samples": 5,\n'
                ' "set": {"render.samples_per_pixel": 2, "acquisition.gate_sweep.stop_ns": 4.2, "camera.crop": [496, 232, 24, 20]},\n'
                ' "random": {"laser.average_power_mW": {"uniform": [0.5, 4]}}}\n' % src)
    subprocess.run([spadgen, "dataset", "run", dataset, "-o", os.path.join(w, "serial"), "-q"], check=True)
    out = os.path.join(w, "job")
    # The pods in the reverse order of their index: the order they finish in must not matter.
    for index in reversed(range(completions)):
        pod_env = dict(os.environ, JOB_COMPLETION_INDEX=str(index), **env)
        for k in ("SLURM_ARRAY_TASK_ID", "SLURM_ARRAY_TASK_COUNT"):
            pod_env.pop(k, None)
        r = subprocess.run([spadgen] + args[:2] + [dataset, "-o", out], env=pod_env, capture_output=True, text=True)
        assert r.returncode == 0, r.stderr
        assert f"of shard {index}/{completions} to generate" in r.stderr, r.stderr
    cmp = subprocess.run([sys.executable, os.path.join(src, "tests/cluster/compare_datasets.py"), os.path.join(w, "serial"), out])
    assert cmp.returncode == 0, "the Indexed Job's dataset differs from the serial run"
print(f"PASS: the Indexed Job manifest ({completions} completions) writes the serial run's dataset")
