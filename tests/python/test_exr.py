"""The pure-Python EXR reader against the OpenEXR library: fixtures written by OpenEXR in every layout the
reader takes (NONE, RLE, ZIPS, ZIP; HALF, FLOAT, UINT; a data window off the origin; decreasing line order)
and every image of real spadgen runs, each compared bit for bit with what OpenEXR reads (exr_tool dump);
and the layouts it refuses, refused with a message that names them."""
import pathlib
import signal
import struct
import zlib
import subprocess

import numpy as np
import pytest

from spadgen.exr import ExrError, ExrFile, read_exr

WIDTH, HEIGHT, X0, Y0 = 37, 41, 3, -2  # exr_tool's fixture


def fixture_value(channel, x, y):
    """exr_tool.cpp's fixture_value, repeated."""
    i = y * WIDTH + x
    if channel == "half":
        return 65504.0 if (x, y) == (0, 0) else -np.inf if (x, y) == (1, 0) else (i - 700.0) / 8.0
    if channel == "float":
        return np.inf if (x, y) == (0, 1) else np.sin(i) * 1e3 + i * 1e-3
    if channel == "layer0.range":
        return 0.45 + 1e-4 * i
    return 4294967295.0 - i * 104729.0


def dump(exr_tool, path, tmp_path):
    """What OpenEXR reads: {channel: array in its stored type}, {string attribute: value}."""
    out = tmp_path / (pathlib.Path(path).name + ".dump")
    out.mkdir()
    subprocess.run([exr_tool, "dump", str(path), str(out)], check=True)
    dtypes = {"HALF": "<f2", "FLOAT": "<f4", "UINT": "<u4"}
    channels = {}
    for line in (out / "channels.txt").read_text().splitlines():
        name, kind, w, h = line.split(" ")
        channels[name] = np.fromfile(out / f"{name}.bin", dtypes[kind]).reshape(int(h), int(w))
    attributes = dict(line.split("\t", 1) for line in (out / "attributes.txt").read_text().splitlines())
    return channels, attributes


def assert_same_bits(ours, theirs):
    assert ours.dtype == theirs.dtype and ours.shape == theirs.shape
    # Bit for bit: NaN, infinities and -0.0 included.
    assert np.array_equal(ours.view(f"u{ours.dtype.itemsize}"), theirs.view(f"u{theirs.dtype.itemsize}"))


@pytest.mark.parametrize("compression,options", [("NONE", []), ("RLE", []), ("ZIPS", []), ("ZIP", []),
                                                 ("ZIP", ["decreasing"])])
def test_fixture_equals_openexr_and_the_values_written(exr_tool, tmp_path, compression, options):
    path = tmp_path / f"fixture_{compression}.exr"
    subprocess.run([exr_tool, "write", str(path), compression] + options, check=True)
    f = ExrFile(path)
    assert f.compression == compression
    assert f.data_window == (X0, Y0, X0 + WIDTH - 1, Y0 + HEIGHT - 1)
    assert (f.width, f.height) == (WIDTH, HEIGHT)
    assert f.channel_names == ["float", "half", "layer0.range", "uint"]  # the file's (sorted) order
    assert f.attributes["spadgen_fixture"] == "written by exr_tool"
    assert f.header["lineOrder"] == ("DECREASING_Y" if options else "INCREASING_Y")
    theirs, attributes = dump(exr_tool, path, tmp_path)
    assert attributes == f.attributes
    dtypes = {"half": np.float16, "float": np.float32, "layer0.range": np.float32, "uint": np.uint32}
    for name, dtype in dtypes.items():
        assert_same_bits(f[name], theirs[name])
        expected = np.array([[fixture_value(name, x, y) for x in range(WIDTH)] for y in range(HEIGHT)]).astype(dtype)
        assert_same_bits(f[name], expected)
        assert not f[name].flags.writeable
    assert f["uint"].max() == 4294967295  # beyond float32's exact integers


@pytest.mark.parametrize("compression", ["PIZ", "PXR24", "B44", "DWAA"])
def test_other_compressions_are_refused_by_name(exr_tool, tmp_path, compression):
    path = tmp_path / f"fixture_{compression}.exr"
    subprocess.run([exr_tool, "write", str(path), compression], check=True)
    f = ExrFile(path)  # the header still reads
    assert f.channel_names == ["float", "half", "layer0.range", "uint"]
    with pytest.raises(ExrError, match=f"{compression} compression is not supported"):
        f["float"]


def test_tiled_files_are_refused(exr_tool, tmp_path):
    path = tmp_path / "tiled.exr"
    subprocess.run([exr_tool, "write", str(path), "ZIP", "tiled"], check=True)
    with pytest.raises(ExrError, match="tiled EXR files are not supported"):
        ExrFile(path)


def test_not_an_exr_and_truncated_files_are_errors(exr_tool, tmp_path):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"P6\n1 1\n255\n\0\0\0")
    with pytest.raises(ExrError, match="not an OpenEXR file"):
        ExrFile(bad)
    path = tmp_path / "whole.exr"
    subprocess.run([exr_tool, "write", str(path), "ZIP"], check=True)
    data = path.read_bytes()
    cut = tmp_path / "cut.exr"
    cut.write_bytes(data[:len(data) - 200])
    with pytest.raises(ExrError, match="cut.exr: cut short: the chunk at byte .* past the file's end"):
        ExrFile(cut)["float"]  # it said "corrupt chunk"
    cut.write_bytes(data[:40])
    with pytest.raises(ExrError, match="truncated header"):
        ExrFile(cut)


def test_damaged_headers_and_chunks_are_errors_not_hangs(make_run, tmp_path):
    """A run's EXR with bytes changed (a negative attribute size looped for ever; attributes of other types,
    a huge data window and inflating chunks escaped as other errors or asked for gigabytes): every read ends,
    within seconds, in the image or an ExrError. 400 seeded mutations of the header and of the first chunk."""
    original = (make_run("sweep") / "labels.exr").read_bytes()
    header_end = original.index(b"\0\0", original.index(b"lineOrder"))  # around the header's attributes
    path = tmp_path / "m.exr"

    def read_within_a_second(data):
        """None when the image reads, else its ExrError (another exception, or over 5 s, fails)."""
        path.write_bytes(bytes(data))

        def late(*_):
            raise TimeoutError(f"reading took over 5 s: the file's first bytes {bytes(data[:48])!r}")
        signal.signal(signal.SIGALRM, late)
        signal.alarm(5)  # (a small file: milliseconds; a loop never ends)
        try:
            ExrFile(path).read()
        except ExrError as e:
            return e
        finally:
            signal.alarm(0)
        return None

    # the attribute size of the channel list negative (the reported loop)
    looped = bytearray(original)
    struct.pack_into("<i", looped, 8 + len(b"channels\0chlist\0"), -20)
    assert "negative size" in str(read_within_a_second(looped))
    rng = np.random.default_rng(5)
    for i in range(400):
        data = bytearray(original)
        for _ in range(int(rng.integers(1, 4))):
            at = int(rng.integers(8, header_end + 64 if i % 2 else min(len(data), header_end + 400)))
            data[at] = int(rng.integers(0, 256)) if i % 3 else data[at] ^ 0x80
        read_within_a_second(data)


@pytest.mark.parametrize("run_name", ["sweep", "intensity"])
def test_every_image_of_a_run_equals_openexr(make_run, exr_tool, tmp_path, run_name):
    run = make_run(run_name)
    images = sorted(run.glob("*.exr"))
    assert {p.name for p in images} >= {"ground_truth.exr", "ambient.exr", "sensor_maps.exr"}
    assert ("laser.exr" in {p.name for p in images}) == (run_name == "sweep")  # the 2D run traces no laser
    for path in images:
        channels, attributes = read_exr(path)
        theirs, their_attributes = dump(exr_tool, path, tmp_path)
        assert sorted(channels) == sorted(theirs), path.name
        for name in theirs:
            assert channels[name].dtype == np.float32  # spadgen writes FLOAT channels
            assert_same_bits(channels[name], theirs[name])
        assert attributes == their_attributes
        assert attributes["spadgen_crop"].startswith("[")


def crafted_exr(channels, width, height, compression=0, chunk=None, attributes=()):
    """A small scanline EXR written by hand (FLOAT channels, zeros): the header OpenEXR needs, the offset table,
    one chunk per 1 (NONE) or 16 (ZIP) lines whose data chunk(y, raw) gives (default: the lines stored as they
    are). attributes: (name, type, value bytes) added or replacing the defaults."""
    def attr(name, kind, value):
        return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value
    chlist = b"".join(c.encode() + b"\0" + struct.pack("<iB3xii", 2, 0, 1, 1) for c in channels) + b"\0"
    box = struct.pack("<4i", 0, 0, width - 1, height - 1)
    base = {"channels": ("chlist", chlist), "compression": ("compression", bytes([compression])),
            "dataWindow": ("box2i", box), "displayWindow": ("box2i", box), "lineOrder": ("lineOrder", b"\0"),
            "pixelAspectRatio": ("float", struct.pack("<f", 1)), "screenWindowCenter": ("v2f", struct.pack("<2f", 0, 0)),
            "screenWindowWidth": ("float", struct.pack("<f", 1))}
    for name, kind, value in attributes:
        base[name] = (kind, value)
    header = struct.pack("<iI", 20000630, 2) + b"".join(attr(n, k, v) for n, (k, v) in base.items()) + b"\0"
    lpc = 16 if compression == 3 else 1
    line = 4 * width * len(channels)
    chunks = []
    for y in range(0, height, lpc):
        raw = bytes(line * min(lpc, height - y))
        data = chunk(y, raw) if chunk else raw
        chunks.append(struct.pack("<ii", y, len(data)) + data)
    at = len(header) + 8 * len(chunks)
    offsets = []
    for c in chunks:
        offsets.append(at)
        at += len(c)
    return header + struct.pack(f"<{len(chunks)}Q", *offsets) + b"".join(chunks)


def zip_zeros(y, raw):
    # ZIP's byte predictor over zeros: the first byte 0, the others 128 (OpenEXR's differences plus 128)
    return zlib.compress(bytes([0]) + bytes([128]) * (len(raw) - 1), 9)


def test_crafted_headers_and_chunks(tmp_path):
    path = tmp_path / "c.exr"
    path.write_bytes(crafted_exr(["A", "B"], 3, 2))
    f = ExrFile(path)
    assert f.channel_names == ["A", "B"] and (f["B"] == 0).all() and f["A"].shape == (2, 3)
    # a channel named twice (the second was dropped and every line read short, without a word)
    path.write_bytes(crafted_exr(["A", "A"], 3, 2))
    with pytest.raises(ExrError, match="names 'A' twice"):
        ExrFile(path)
    # a required attribute of another type (a TypeError escaped from the message itself)
    path.write_bytes(crafted_exr(["A"], 3, 2, attributes=[("compression", "int", struct.pack("<i", 0))]))
    with pytest.raises(ExrError, match="'compression' is of type 'int' \\(4 bytes\\), not compression"):
        ExrFile(path)
    path.write_bytes(crafted_exr(["A"], 3, 2, attributes=[("dataWindow", "int", struct.pack("<i", 0))]))
    with pytest.raises(ExrError, match="'dataWindow' is of type 'int'"):
        ExrFile(path)
    # a large image of zeros compresses about 1000 times (deflate's limit is about 1032): read whole and fast
    path.write_bytes(crafted_exr(["A", "B", "C"], 1024, 64, compression=3, chunk=zip_zeros))
    assert path.stat().st_size * 100 < 1024 * 64 * 12
    f = ExrFile(path)
    assert (f["C"] == 0).all() and f["C"].shape == (64, 1024)
    # a ZIP chunk cut short (its checksum gone) is corrupt (zlib.decompressobj reads it without a word)
    path.write_bytes(crafted_exr(["A"], 8, 16, compression=3, chunk=lambda y, raw: zip_zeros(y, raw)[:-4]))
    with pytest.raises(ExrError, match="corrupt ZIP data in the chunk at y = 0"):
        ExrFile(path)["A"]
