"""The package itself: its version is the program's (CMakeLists.txt's project VERSION, `spadgen --version`),
it installs offline with pip from Debian's setuptools (no build isolation, nothing downloaded), and importing
it pulls in neither matplotlib nor PyTorch."""
import re
import shutil
import subprocess
import sys

import spadgen
from conftest import SOURCE


def test_version_is_the_programs(spadgen_bin):
    cmake = (SOURCE / "CMakeLists.txt").read_text()
    project = re.search(r"project\(spadgen\s+VERSION\s+([0-9.]+)", cmake)
    assert project, "CMakeLists.txt: no project(spadgen VERSION ...)"
    assert spadgen.__version__ == project.group(1), \
        "python/spadgen/_version.py must equal CMakeLists.txt's project VERSION"
    program = subprocess.run([spadgen_bin, "--version"], check=True, capture_output=True, text=True).stdout.strip()
    assert program == spadgen.__version__


def test_installs_offline_with_pip(tmp_path):
    # From a copy: setuptools builds in the source folder (build/, *.egg-info), which must stay clean.
    src = tmp_path / "src"
    shutil.copytree(SOURCE / "python", src, ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
    target = tmp_path / "site"
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-build-isolation", "--no-deps", "--no-index",
                        "--disable-pip-version-check", "--no-cache-dir", "--target", str(target), str(src)], capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (target / f"spadgen-{spadgen.__version__}.dist-info").is_dir()
    code = ("import spadgen, spadgen.exr, spadgen.camera, spadgen.estimate, spadgen.plot, spadgen.run, spadgen.dataset; "
            "print(spadgen.__version__); print(spadgen.__file__)")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True,
                         env={"PYTHONPATH": str(target), "PATH": "/usr/bin:/bin"}, cwd=tmp_path).stdout.split("\n")
    assert out[0] == spadgen.__version__
    assert out[1].startswith(str(target))


def test_import_pulls_in_neither_matplotlib_nor_torch():
    code = "import sys, spadgen; print(sorted(m for m in ('matplotlib', 'torch') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout.strip()
    assert out == "[]"
