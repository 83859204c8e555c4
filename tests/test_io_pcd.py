"""PCD v0.7 (ascii, binary, binary_compressed) and the LZF decoder, against hand-made files
and a naive reference LZF compressor written here (back references, overlapping ones too)."""

from __future__ import annotations

import numpy as np
import pytest

from nurbskit.errors import InputError
from nurbskit.io import read_points, write_points
from nurbskit.io.lzf import LZFError, compress_literal, decompress

from _extras import require_extra


def naive_lzf_compress(data: bytes) -> bytes:
    """A slow, obviously correct LZF encoder: greedy longest match within 8 KB, 3..264 bytes,
    overlapping matches allowed; literal runs of at most 32 bytes."""
    out, lit, i, n = bytearray(), bytearray(), 0, len(data)

    def flush():
        nonlocal lit
        while lit:
            chunk, lit = lit[:32], lit[32:]
            out.append(len(chunk) - 1)
            out.extend(chunk)

    while i < n:
        best_len, best_off = 0, 0
        for off in range(1, min(i, 8192) + 1):
            length = 0
            while i + length < n and length < 264 and data[i + length - off] == data[i + length]:
                length += 1
            if length > best_len:
                best_len, best_off = length, off
        if best_len >= 3:
            flush()
            length, off = best_len - 2, best_off - 1
            if length < 7:
                out.append((length << 5) | (off >> 8))
            else:
                out.append((7 << 5) | (off >> 8))
                out.append(length - 7)
            out.append(off & 255)
            i += best_len
        else:
            lit.append(data[i])
            i += 1
    flush()
    return bytes(out)


@pytest.mark.parametrize("data", [
    b"", b"a", b"abcabcabcabcabcabc", b"\x00" * 1000, bytes(range(256)) * 3,
    b"hello world, hello world, hello hello hello!", np.random.default_rng(1).integers(0, 4, 700).astype(np.uint8).tobytes(),
])
def test_lzf_decoder_against_reference_encoder(data):
    packed = naive_lzf_compress(data)
    assert decompress(packed, len(data), use_c=False) == data
    assert decompress(compress_literal(data), len(data), use_c=False) == data


def test_lzf_overlapping_copy_by_hand():
    # "ab", then copy 8 bytes from 2 back: the copy reads what it writes
    stream = bytes([1]) + b"ab" + bytes([(6 << 5) | 0, 1])
    assert decompress(stream, 10, use_c=False) == b"ababababab"


def test_lzf_with_python_lzf_as_oracle():
    lzf = require_extra("lzf", "pcd")
    data = np.repeat(np.random.default_rng(0).integers(0, 50, 3000), 7).astype(np.uint8).tobytes()
    assert decompress(lzf.compress(data), len(data), use_c=False) == data


@pytest.mark.parametrize("stream, size, message", [
    (bytes([5]) + b"ab", 6, "passes the end"),
    (bytes([0x20, 5]), 3, "only 0 bytes were produced"),
    (bytes([0]) + b"a", 3, "decodes to 1 bytes, 3 were announced"),
])
def test_lzf_corrupt_streams(stream, size, message):
    with pytest.raises(LZFError, match=message):
        decompress(stream, size, use_c=False)


def _organised_cloud():
    rng = np.random.default_rng(5)
    h, w = 4, 6
    xyz = rng.normal(size=(h * w, 3)).astype(np.float32)
    xyz[[1, 7, 8, 20]] = np.nan  # depth holes
    rgb = rng.integers(0, 256, (h * w, 3)).astype(np.uint32)
    label = rng.integers(0, 4, h * w).astype(np.uint32)
    return h, w, xyz, rgb, label


def _pcd_header(fields, sizes, types, w, h, mode):
    return (f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS {' '.join(fields)}\n"
            f"SIZE {' '.join(map(str, sizes))}\nTYPE {' '.join(types)}\nCOUNT {' '.join('1' for _ in fields)}\n"
            f"WIDTH {w}\nHEIGHT {h}\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {w * h}\nDATA {mode}\n").encode()


@pytest.mark.parametrize("mode", ["ascii", "binary", "binary_compressed"])
def test_organised_cloud_with_nan_holes(tmp_path, mode):
    h, w, xyz, rgb, label = _organised_cloud()
    packed = ((rgb[:, 0] << 16) | (rgb[:, 1] << 8) | rgb[:, 2]).view(np.float32)
    rec = np.zeros(h * w, [("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<f4"), ("label", "<u4")])
    rec["x"], rec["y"], rec["z"] = xyz.T
    rec["rgb"], rec["label"] = packed, label
    head = _pcd_header(["x", "y", "z", "rgb", "label"], [4] * 5, ["F", "F", "F", "F", "U"], w, h, mode)
    if mode == "binary":
        body = rec.tobytes()
    elif mode == "binary_compressed":
        soa = b"".join(rec[n].tobytes() for n in rec.dtype.names)
        comp = naive_lzf_compress(soa)
        body = np.array([len(comp), len(soa)], "<u4").tobytes() + comp
    else:
        body = "".join(f"{float(xyz[i, 0])!r} {float(xyz[i, 1])!r} {float(xyz[i, 2])!r} "
                       f"{float(packed[i])!r} {int(label[i])}\n" for i in range(h * w)).encode()
    path = tmp_path / f"org_{mode}.pcd"
    path.write_bytes(head + body)
    cloud = read_points(path)
    keep = ~np.isnan(xyz).any(axis=1)
    assert cloud.dropped == 4 and cloud.num_points == h * w - 4
    np.testing.assert_array_equal(cloud.points, xyz[keep].astype(np.float64))
    np.testing.assert_array_equal(cloud.colors, rgb[keep].astype(np.uint8))
    np.testing.assert_array_equal(cloud.labels, label[keep])
    with pytest.raises(InputError, match="NaN"):
        read_points(path, nonfinite="error")
    assert read_points(path, nonfinite="keep").num_points == h * w


@pytest.mark.parametrize("data", ["ascii", "binary", "binary_compressed"])
@pytest.mark.parametrize("coord", [np.float32, np.float64])
def test_write_read_round_trip(tmp_path, data, coord):
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(300, 3))
    nrm = rng.normal(size=(300, 3))
    col = rng.integers(0, 256, (300, 3)).astype(np.uint8)
    lab = rng.integers(-3, 9, 300)
    path = tmp_path / "rt.pcd"
    write_points(path, pts, nrm, col, lab, data=data, coordinate_dtype=coord)
    back = read_points(path)
    expect = pts.astype(coord).astype(np.float64)
    np.testing.assert_array_equal(back.points, expect)
    np.testing.assert_array_equal(back.normals, nrm.astype(coord).astype(np.float64))
    np.testing.assert_array_equal(back.colors, col)
    np.testing.assert_array_equal(back.labels, lab)


def test_written_compressed_pcd_decodes_with_python_lzf(tmp_path):
    lzf = require_extra("lzf", "pcd")
    path = tmp_path / "c.pcd"
    write_points(path, np.arange(30.0).reshape(10, 3), data="binary_compressed")
    raw = path.read_bytes()
    pos = raw.index(b"DATA binary_compressed\n") + 23
    csize, usize = np.frombuffer(raw, "<u4", 2, pos)
    soa = lzf.decompress(raw[pos + 8: pos + 8 + csize], int(usize) + 1)
    np.testing.assert_array_equal(np.frombuffer(soa, "<f4", 10), np.arange(0, 30, 3))


def test_points_count_disagrees_with_width_height(tmp_path):
    path = tmp_path / "lie.pcd"
    path.write_bytes(_pcd_header(["x", "y", "z"], [4] * 3, ["F"] * 3, 2, 2, "ascii").replace(b"POINTS 4", b"POINTS 5")
                     + b"0 0 0\n1 1 1\n2 2 2\n3 3 3\n")
    with pytest.raises(InputError, match="POINTS 5 but WIDTH x HEIGHT"):
        read_points(path)


def test_truncated_binary_and_compressed(tmp_path):
    path = tmp_path / "t.pcd"
    path.write_bytes(_pcd_header(["x", "y", "z"], [4] * 3, ["F"] * 3, 10, 1, "binary") + b"\0" * 100)
    with pytest.raises(InputError, match="10 points.*truncated"):
        read_points(path)
    soa = np.zeros(30, "<f4").tobytes()
    comp = compress_literal(soa)
    path.write_bytes(_pcd_header(["x", "y", "z"], [4] * 3, ["F"] * 3, 10, 1, "binary_compressed")
                     + np.array([len(comp), len(soa)], "<u4").tobytes() + comp[:-10])
    with pytest.raises(InputError, match="compressed bytes but only"):
        read_points(path)


def test_huge_declared_cloud_refused(tmp_path):
    path = tmp_path / "huge.pcd"
    n = 10**12
    path.write_bytes(_pcd_header(["x", "y", "z"], [4] * 3, ["F"] * 3, n, 1, "binary").replace(
        f"POINTS {n}".encode(), f"POINTS {n}".encode()) + b"\0" * 120)
    with pytest.raises(InputError, match="1,000,000,000,000 points"):
        read_points(path)
