# The package's version is the spadgen program's (CMakeLists.txt: project(spadgen VERSION ...)); the test
# tests/python/test_package.py keeps them equal.
__version__ = "0.1.0"
