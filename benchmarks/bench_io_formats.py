"""How fast does nurbskit read and write point files, against peers in the same process?

Question: are binary PLY and PCD read and written at disk speed (> 200 MB/s), and is
text read at least as fast as numpy's own ``np.loadtxt``?

Method: a cloud of N points (default 1,000,000; ``--quick`` 100,000) with float32
coordinates and normals, written to a temporary directory. Each operation runs once to
warm up, then ``--repeats`` times (median reported). Two threads (OMP/MKL and torch).
Peers, on the same file in the same run: trimesh's loader and exporter (PLY), numpy's
``np.loadtxt`` (text), python-lzf's C decoder when installed (PCD binary_compressed),
and a raw ``read_bytes`` of the file (what the disk and page cache deliver; the ceiling
for any parser). MB/s is the file size divided by the median time. Other processes may
share the two cores: absolute times can be contended; ratios within one run are fairer.

Run: ``python benchmarks/bench_io_formats.py [--quick]``; writes
``benchmarks/results/io_formats.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "2")
os.environ.setdefault("MKL_NUM_THREADS", "2")

import numpy as np  # noqa: E402

HERE = Path(__file__).resolve().parent


def timed(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="100,000 points and 3 repeats")
    parser.add_argument("--points", type=int, default=None)
    parser.add_argument("--repeats", type=int, default=None)
    args = parser.parse_args(argv)
    n = args.points or (100_000 if args.quick else 1_000_000)
    repeats = args.repeats or (3 if args.quick else 5)

    import torch
    import trimesh

    torch.set_num_threads(2)
    from nurbskit.io import read_points, write_points

    rng = np.random.default_rng(0)
    pts = rng.normal(size=(n, 3)).astype(np.float32).astype(np.float64)
    nrm = rng.normal(size=(n, 3)).astype(np.float32).astype(np.float64)
    rows = []

    def add(fmt, op, tool, seconds, size, note=""):
        rows.append({"format": fmt, "operation": op, "tool": tool, "seconds": seconds,
                     "mb_per_s": size / seconds / 1e6 if seconds > 0 else None, "file_mb": size / 1e6, "note": note})

    with tempfile.TemporaryDirectory(prefix="nurbskit-bench-io-") as tmp:
        tmp = Path(tmp)
        # ---- binary PLY --------------------------------------------------------------
        ply = tmp / "cloud.ply"
        write_points(ply, pts, nrm)
        size = ply.stat().st_size
        add("PLY binary", "read", "raw read_bytes (ceiling)", timed(lambda: ply.read_bytes(), repeats), size)
        add("PLY binary", "read", "nurbskit", timed(lambda: read_points(ply), repeats), size)
        add("PLY binary", "read", "trimesh", timed(lambda: trimesh.load(ply, process=False), repeats), size)
        out = tmp / "out.ply"
        add("PLY binary", "write", "nurbskit", timed(lambda: write_points(out, pts, nrm), repeats), size)
        tm_cloud = trimesh.PointCloud(pts)
        tm_out = tmp / "tm.ply"
        add("PLY binary", "write", "trimesh (points only)",
            timed(lambda: tm_cloud.export(tm_out), repeats), tm_out.stat().st_size if tm_out.exists() else size)

        # ---- PCD ---------------------------------------------------------------------
        for mode in ("binary", "binary_compressed"):
            pcd = tmp / f"cloud_{mode}.pcd"
            write_points(pcd, pts, nrm, data=mode)
            size = pcd.stat().st_size
            add(f"PCD {mode}", "read", "raw read_bytes (ceiling)", timed(lambda: pcd.read_bytes(), repeats), size)
            add(f"PCD {mode}", "read", "nurbskit", timed(lambda: read_points(pcd), repeats), size,
                "LZF: python-lzf C decoder" if mode != "binary" and _has_lzf() else "")
            add(f"PCD {mode}", "write", "nurbskit", timed(lambda: write_points(tmp / "o.pcd", pts, nrm, data=mode), repeats),
                size, "literal-run LZF (no compression)" if mode != "binary" else "")
        # the pure-Python LZF decoder on a real Kinect file, if the data are there
        kinect = HERE.parent.parent / "shared" / "data" / "kinect_scans" / "test0.pcd"
        if kinect.exists():
            from nurbskit.io.lzf import decompress

            data = kinect.read_bytes()
            pos = data.index(b"DATA binary_compressed\n") + 23
            csize, usize = (int(v) for v in np.frombuffer(data, "<u4", 2, pos))
            stream = data[pos + 8: pos + 8 + csize]
            add("LZF (Kinect test0.pcd)", "decode", "nurbskit pure Python",
                timed(lambda: decompress(stream, usize, use_c=False), repeats), usize, "MB/s of output")
            if _has_lzf():
                import lzf

                add("LZF (Kinect test0.pcd)", "decode", "python-lzf (C)",
                    timed(lambda: lzf.decompress(stream, usize + 1), repeats), usize, "MB/s of output")

        # ---- text --------------------------------------------------------------------
        xyz = tmp / "cloud.xyz"
        np.savetxt(xyz, pts, fmt="%.8g")
        size = xyz.stat().st_size
        add("XYZ text", "read", "nurbskit", timed(lambda: read_points(xyz), repeats), size)
        add("XYZ text", "read", "numpy loadtxt", timed(lambda: np.loadtxt(xyz), repeats), size)
        add("XYZ text", "write", "nurbskit (17 digits)", timed(lambda: write_points(tmp / "o.xyz", pts), repeats),
            (tmp / "o.xyz").stat().st_size)
        add("XYZ text", "write", "numpy savetxt (17 digits)",
            timed(lambda: np.savetxt(tmp / "s.xyz", pts, fmt="%.17g"), repeats), (tmp / "s.xyz").stat().st_size)

    peers = {}
    for r in rows:
        peers.setdefault((r["format"], r["operation"]), []).append(r)
    for group in peers.values():
        ours = next((r for r in group if r["tool"].startswith("nurbskit")), None)
        for r in group:
            r["ratio_vs_nurbskit"] = (r["seconds"] / ours["seconds"]) if ours else None

    result = {
        "question": "io_formats", "points": n, "repeats": repeats, "threads": 2,
        "machine": {"python": sys.version.split()[0], "platform": platform.platform(), "cpus": os.cpu_count(),
                    "numpy": np.__version__, "trimesh": trimesh.__version__},
        "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None,
        "rows": rows,
    }
    results = HERE / "results"
    results.mkdir(exist_ok=True)
    (results / "io_formats.json").write_text(json.dumps(result, indent=1))
    lines = [f"# io_formats: {n:,} points, median of {repeats} (after a warm-up), 2 threads",
             "", f"load average at the end: {result['load_average']}", "",
             "| format | operation | tool | seconds | MB/s | time / nurbskit's | note |",
             "| --- | --- | --- | ---: | ---: | ---: | --- |"]
    for r in rows:
        ratio = f"{r['ratio_vs_nurbskit']:.2f}" if r["ratio_vs_nurbskit"] else ""
        lines.append(f"| {r['format']} | {r['operation']} | {r['tool']} | {r['seconds']:.4f} | "
                     f"{r['mb_per_s']:.0f} | {ratio} | {r['note']} |")
    (results / "io_formats.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def _has_lzf() -> bool:
    try:
        import lzf  # noqa: F401

        return True
    except ImportError:
        return False


if __name__ == "__main__":
    raise SystemExit(main())
