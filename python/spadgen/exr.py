"""A pure-Python (NumPy + zlib) reader for the OpenEXR images spadgen writes.

spadgen writes single-part scanline images with ZIP compression and 32-bit FLOAT channels. This reader also
takes the other lossless scanline layouts that cost nothing extra (NONE, RLE, ZIPS, ZIP compression; HALF,
FLOAT and UINT channels; any data window) and refuses, with a message naming the file and the feature, what
it does not read: tiled, multi-part and deep files, subsampled channels, and the PIZ, PXR24, B44(A) and
DWA(A/B) compressions.

    from spadgen.exr import ExrFile
    gt = ExrFile("out/ground_truth.exr")
    gt.channel_names            # ['layer0.range', ..., 'range', 'z']  (the file's order: sorted)
    depth = gt["range"]          # (H, W) float32, read-only; the file is decoded on first access
    gt.attributes["spadgen_seed"]

The layout follows the OpenEXR file format specification ("OpenEXR File Layout"): magic number, version
field, header attributes up to an empty name, the line offset table, then one chunk per block of scanlines
(y, packed size, data), each block holding, line by line, every channel's samples in channel-list order.
"""
from __future__ import annotations

import os
import stat
import struct
import zlib
from dataclasses import dataclass

import numpy as np

__all__ = ["ExrError", "ExrChannel", "ExrFile", "read_exr"]

MAGIC = 20000630

# Compression codes (the `compression` attribute) and the scanlines each chunk holds.
COMPRESSIONS = {0: "NONE", 1: "RLE", 2: "ZIPS", 3: "ZIP", 4: "PIZ", 5: "PXR24", 6: "B44", 7: "B44A", 8: "DWAA", 9: "DWAB"}
LINES_PER_CHUNK = {"NONE": 1, "RLE": 1, "ZIPS": 1, "ZIP": 16, "PIZ": 32, "PXR24": 16, "B44": 32, "B44A": 32,
                   "DWAA": 32, "DWAB": 256}
SUPPORTED = ("NONE", "RLE", "ZIPS", "ZIP")

# Pixel types of the channel list: name and little-endian NumPy dtype.
PIXEL_TYPES = {0: ("UINT", np.dtype("<u4")), 1: ("HALF", np.dtype("<f2")), 2: ("FLOAT", np.dtype("<f4"))}

_TILED, _LONG_NAMES, _DEEP, _MULTIPART = 0x200, 0x400, 0x800, 0x1000


class ExrError(ValueError):
    """The file is not an EXR image this reader can read (the message names the file and the reason)."""


@dataclass(frozen=True)
class ExrChannel:
    name: str
    pixel_type: str      # "UINT", "HALF" or "FLOAT"
    dtype: np.dtype      # the NumPy dtype of its samples
    x_sampling: int
    y_sampling: int


def _cstring(buf, pos, path):
    end = buf.find(b"\0", pos)
    if end < 0:
        raise ExrError(f"{path}: truncated header (unterminated name)")
    return buf[pos:end].decode("utf-8", "replace"), end + 1


def _parse_chlist(value, path):
    channels, pos = [], 0
    while pos < len(value) and value[pos] != 0:
        name, pos = _cstring(value, pos, path)
        if pos + 16 > len(value):
            raise ExrError(f"{path}: truncated channel list")
        ptype, _plinear, xs, ys = struct.unpack_from("<iB3xii", value, pos)
        pos += 16
        if ptype not in PIXEL_TYPES:
            raise ExrError(f"{path}: channel '{name}' has unknown pixel type {ptype}")
        tname, dtype = PIXEL_TYPES[ptype]
        if any(c.name == name for c in channels):  # (the second was dropped, and every line read short)
            raise ExrError(f"{path}: the channel list names {name!r} twice")
        channels.append(ExrChannel(name, tname, dtype, xs, ys))
    return channels


def _parse_attribute(type_name, value, path):
    """The value of the attribute types spadgen and OpenEXR write; other types stay bytes."""
    if type_name == "string":
        return value.decode("utf-8", "replace")
    if type_name == "chlist":
        return _parse_chlist(value, path)
    if type_name in ("compression", "lineOrder"):
        if len(value) != 1:
            raise ExrError(f"{path}: a {type_name} attribute of {len(value)} bytes (it is one byte)")
        if type_name == "compression":
            return COMPRESSIONS.get(value[0], f"unknown ({value[0]})")
        return {0: "INCREASING_Y", 1: "DECREASING_Y", 2: "RANDOM_Y"}.get(value[0], value[0])
    fmt = {"int": "<i", "float": "<f", "double": "<d", "box2i": "<4i", "box2f": "<4f", "v2i": "<2i",
           "v2f": "<2f", "v3i": "<3i", "v3f": "<3f", "m33f": "<9f", "m44f": "<16f"}.get(type_name)
    if fmt and struct.calcsize(fmt) == len(value):
        v = struct.unpack(fmt, value)
        return v[0] if len(v) == 1 else v
    return value


def _undo_predictor_and_interleave(t):
    """Reverses the byte predictor and the two-half interleave that ZIP and RLE apply before compressing
    (OpenEXR ImfZip.cpp / ImfRle: each byte stored as the difference to the previous one plus 128, after
    the even-indexed bytes were moved to the first half and the odd-indexed to the second)."""
    d = np.frombuffer(t, np.uint8).copy()
    if d.size > 1:
        d[1:] -= np.uint8(128)  # wraps modulo 256, like the C++ unsigned arithmetic
        d = np.cumsum(d, dtype=np.uint8)
    out = np.empty_like(d)
    half = (d.size + 1) // 2
    out[0::2] = d[:half]
    out[1::2] = d[half:]
    return out


def _rle_decode(data, expected, path):
    out, i, n = bytearray(), 0, len(data)
    while i < n:
        count = data[i] - 256 if data[i] > 127 else data[i]
        i += 1
        if count < 0:  # -count literal bytes
            out += data[i:i - count]
            i -= count
        else:          # count + 1 copies of the next byte
            if i >= n:
                raise ExrError(f"{path}: corrupt RLE data")
            out += bytes([data[i]]) * (count + 1)
            i += 1
        if len(out) > expected:
            raise ExrError(f"{path}: RLE data decodes to more bytes than its scanlines hold")
    return bytes(out)


def _file_identity(f):
    """Which file f is: a file replaced by a rename (a run folder swapped) has another inode; the modification
    time is left out (touching the same bytes is no replacement)."""
    st = os.fstat(f.fileno())
    return st.st_dev, st.st_ino, st.st_size


class ExrFile:
    """One EXR image: its header on opening, its channels (by name) on first access, decoded all at once
    and kept. Every channel is a read-only (H, W) array of its stored type (float32 for FLOAT, float16 for
    HALF, uint32 for UINT) covering the data window; ``data_window`` gives its (x_min, y_min, x_max, y_max)."""

    def __init__(self, path):
        self.path = os.fspath(path)
        # Opened only when a regular file (a FIFO would block the open for ever). Which file it is (device,
        # inode, size) is kept: the channels, decoded later, must come from the same one
        # (a run folder swapped for a newer run's meanwhile is not read as the rest of this one's).
        if not stat.S_ISREG(os.stat(self.path).st_mode):
            raise ExrError(f"{self.path}: not a regular file; expected an OpenEXR file")
        with open(self.path, "rb") as f:
            self._identity = _file_identity(f)
            self._read_whole_header(f)
        self._channels = None

    def _read_whole_header(self, f):
        head = f.read(8)
        if len(head) < 8 or struct.unpack("<i", head[:4])[0] != MAGIC:
            raise ExrError(f"{self.path}: not an OpenEXR file (bad magic number)")
        version = struct.unpack("<I", head[4:8])[0]
        if version & 0xFF != 2:
            raise ExrError(f"{self.path}: OpenEXR file format version {version & 0xFF} is not supported (2 is)")
        if version & _MULTIPART:
            raise ExrError(f"{self.path}: multi-part EXR files are not supported (spadgen writes single-part scanline files)")
        if version & _DEEP:
            raise ExrError(f"{self.path}: deep-data EXR files are not supported")
        if version & _TILED:
            raise ExrError(f"{self.path}: tiled EXR files are not supported (spadgen writes scanline files)")
        self._read_header(f)
        self._offsets_at = f.tell()

    def _read_header(self, f):
        self.header = {}
        self.attribute_types = {}
        sizes = {}  # each attribute's value in bytes
        buf, pos = bytearray(), 0

        def need(n):  # at least n bytes from pos in buf
            nonlocal buf
            while len(buf) - pos < n:
                more = f.read(1 << 16)
                if not more:
                    raise ExrError(f"{self.path}: truncated header")
                buf += more

        def name():
            nonlocal pos
            while buf.find(b"\0", pos) < 0:
                need(len(buf) - pos + 1)
            s, pos = _cstring(buf, pos, self.path)
            return s

        while True:
            attr = name()
            if attr == "":
                break
            type_name = name()
            need(4)
            size = struct.unpack_from("<i", buf, pos)[0]
            pos += 4
            if size < 0:  # (pos would walk back and read the same attribute for ever)
                raise ExrError(f"{self.path}: the header attribute {attr!r} has a negative size ({size})")
            need(size)
            self.header[attr] = _parse_attribute(type_name, bytes(buf[pos:pos + size]), self.path)
            self.attribute_types[attr] = type_name
            sizes[attr] = size
            pos += size
        f.seek(8 + pos)
        for required, kind in (("channels", "chlist"), ("compression", "compression"), ("dataWindow", "box2i"),
                               ("lineOrder", "lineOrder")):
            if required not in self.header:
                raise ExrError(f"{self.path}: header lacks the required attribute '{required}'")
            if self.attribute_types[required] != kind or (kind == "box2i" and not isinstance(self.header[required], tuple)):
                raise ExrError(f"{self.path}: the header attribute '{required}' is of type "
                               f"{self.attribute_types[required]!r} ({sizes[required]} bytes), not {kind}")
        self.compression = self.header["compression"]
        self.channels = {c.name: c for c in self.header["channels"]}
        self.data_window = tuple(self.header["dataWindow"])
        x0, y0, x1, y1 = self.data_window
        self.width, self.height = x1 - x0 + 1, y1 - y0 + 1
        if self.width < 1 or self.height < 1:
            raise ExrError(f"{self.path}: empty data window {self.data_window}")

    @property
    def channel_names(self):
        return list(self.channels)

    @property
    def attributes(self):
        """The header's string attributes (spadgen's provenance: spadgen_seed, spadgen_crop, ...)."""
        return {k: v for k, v in self.header.items() if self.attribute_types[k] == "string"}

    def __contains__(self, name):
        return name in self.channels

    def __iter__(self):
        return iter(self.channels)

    def __len__(self):
        return len(self.channels)

    def keys(self):
        return self.channels.keys()

    def __getitem__(self, name):
        if name not in self.channels:
            raise KeyError(f"{self.path}: no channel '{name}' (channels: {', '.join(self.channels)})")
        if self._channels is None:
            self._channels = self._decode()
        return self._channels[name]

    def read(self):
        """Every channel, as a dict name -> (H, W) array."""
        return {name: self[name] for name in self.channels}

    def _decode(self):
        comp = self.compression
        if comp not in SUPPORTED:
            raise ExrError(f"{self.path}: {comp} compression is not supported (this reader takes "
                           f"{', '.join(SUPPORTED)}; spadgen writes ZIP)")
        for c in self.channels.values():
            if c.x_sampling != 1 or c.y_sampling != 1:
                raise ExrError(f"{self.path}: channel '{c.name}' is subsampled ({c.x_sampling} x {c.y_sampling}), "
                               "which is not supported")
        W, H = self.width, self.height
        y_min = self.data_window[1]
        lpc = LINES_PER_CHUNK[comp]
        chunks = -(-H // lpc)
        with open(self.path, "rb") as f:
            if _file_identity(f) != self._identity:
                raise ExrError(f"{self.path}: the file was replaced since its header was read (a newer run published "
                               "into its folder): open it, or its run, again")
            data = f.read()
        if self._offsets_at + 8 * chunks > len(data):
            raise ExrError(f"{self.path}: truncated line offset table")
        offsets = struct.unpack_from(f"<{chunks}Q", data, self._offsets_at)
        chans = list(self.channels.values())
        widths = [W * c.dtype.itemsize for c in chans]
        starts = np.concatenate([[0], np.cumsum(widths)]).astype(int)
        line_bytes = int(starts[-1])
        # What the image holds decoded, against what the file can hold: deflate packs at most about 1032 bytes
        # into one, RLE 64 (a header that names a huge data window asked for gigabytes before any chunk was read).
        most = len(data) * (1100 if comp in ("ZIP", "ZIPS") else 70 if comp == "RLE" else 1)
        if H * line_bytes > most:
            raise ExrError(f"{self.path}: its data window {self.data_window} and {len(chans)} channels hold "
                           f"{H * line_bytes} bytes, more than its {len(data)} bytes can hold with {comp} compression")
        # The scanlines whole, then each channel cut out once (per chunk and channel, a file of 3000 channels
        # took 27 s).
        lines_all = np.empty((H, line_bytes), np.uint8)
        filled = np.zeros(chunks, bool)
        for off in offsets:
            if off + 8 > len(data):
                raise ExrError(f"{self.path}: a chunk offset points past the end of the file (truncated file?)")
            y, size = struct.unpack_from("<ii", data, off)
            block = (y - y_min) // lpc
            if off + 8 + size > len(data) and size >= 0 and not (y - y_min) % lpc and 0 <= block < chunks:
                raise ExrError(f"{self.path}: cut short: the chunk at byte {off} (y = {y}) holds {size} bytes, past the "
                               f"file's end at byte {len(data)} (truncated file?)")
            if (y - y_min) % lpc or not 0 <= block < chunks or off + 8 + size > len(data) or size < 0:
                raise ExrError(f"{self.path}: corrupt chunk at byte {off} (y = {y}, size = {size})")
            lines = min(lpc, H - block * lpc)
            expected = lines * line_bytes
            packed = data[off + 8:off + 8 + size]
            if size >= expected:  # stored uncompressed: compressing did not make it smaller
                raw = np.frombuffer(packed, np.uint8, expected)
            elif comp in ("ZIP", "ZIPS"):
                try:  # (at most one byte more than its scanlines hold: a chunk cannot inflate without bound)
                    inflate = zlib.decompressobj()
                    unpacked = inflate.decompress(packed, expected + 1)
                    if not inflate.eof and len(unpacked) <= expected:  # (zlib.decompress said so of a cut stream)
                        raise zlib.error("incomplete or truncated stream")
                    raw = _undo_predictor_and_interleave(unpacked)
                except zlib.error as e:
                    raise ExrError(f"{self.path}: corrupt ZIP data in the chunk at y = {y}: {e}") from None
            elif comp == "RLE":
                raw = _undo_predictor_and_interleave(_rle_decode(packed, expected, self.path))
            else:  # NONE with a short chunk
                raise ExrError(f"{self.path}: the chunk at y = {y} holds {size} bytes, its scanlines {expected}")
            if raw.size != expected:
                raise ExrError(f"{self.path}: the chunk at y = {y} decodes to {raw.size} bytes, its scanlines hold {expected}")
            r0 = block * lpc
            lines_all[r0:r0 + lines] = raw.reshape(lines, line_bytes)
            filled[block] = True
        if not filled.all():
            raise ExrError(f"{self.path}: {int((~filled).sum())} of {chunks} chunks are missing")
        del data  # (the file's bytes: not held beside the image)
        # Each channel copied out of the scanlines whole (a view of them would need numpy 1.23, and be misaligned
        # beside HALF channels for torch).
        out = {}
        for c, a, b in zip(chans, starts[:-1], starts[1:]):
            out[c.name] = np.ascontiguousarray(lines_all[:, a:b]).view(c.dtype).reshape(H, W)
            out[c.name].flags.writeable = False
        return out

    def __repr__(self):
        return (f"ExrFile({self.path!r}, {self.width} x {self.height}, {self.compression}, "
                f"channels={self.channel_names})")


def read_exr(path):
    """Every channel of an EXR file (dict name -> (H, W) array) and its string attributes."""
    f = ExrFile(path)
    return f.read(), f.attributes
