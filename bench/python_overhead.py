#!/usr/bin/env python3
"""What the Python path costs over the C++ path on the same extraction, in the same run, with
scikit-image's measure.marching_cubes on the same array beside them (the module's overhead target: at most 10%).

The C++ path is timed in process by isotope_bench_api (bench/bench_api.cpp, Google Benchmark):
open_volume on a float array it borrows, or on the file, then Source::extract, exactly what
isotope.extract does for a float32 array or a path. The Python path is that call, timed with
time.perf_counter (median of --repeats, after one warm-up), mesh arrays included. Run it with the
interpreter isotope is installed in:

    build-ci/venv/bin/python bench/python_overhead.py --bench-api build-ci/bench/isotope_bench_api \\
        --volume ../shared/data/embryo_256x256x256_uint8.raw --iso 64.5 --eps 0,16
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time

import numpy as np

import isotope


def raw_array(path):
    m = re.search(r"_(\d+)x(\d+)x(\d+)_(uint8|uint16|int16|float32|float64)\.raw$", os.path.basename(path))
    if not m:
        sys.exit(f"{path}: expected NAME_XxYxZ_TYPE.raw")
    x, y, z = (int(v) for v in m.group(1, 2, 3))
    return np.fromfile(path, dtype=m.group(4)).reshape(z, y, x)


def median_seconds(f, repeats):
    f()  # warm-up: page cache, allocator, TBB's threads
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = f()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--bench-api", required=True, help="isotope_bench_api (bench/bench_api.cpp)")
    p.add_argument("--volume", required=True, help="NAME_XxYxZ_TYPE.raw")
    p.add_argument("--iso", type=float, required=True)
    p.add_argument("--eps", default="0,16", help="comma-separated eps values (data units)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json", help="also write the rows here")
    a = p.parse_args()
    eps_list = [float(e) for e in a.eps.split(",")]

    out = subprocess.run([a.bench_api, "--volume", a.volume, "--iso", repr(a.iso), "--eps", a.eps,
                          "--benchmark_format=json", f"--benchmark_repetitions={a.repeats}",
                          "--benchmark_report_aggregates_only=true"],
                         check=True, capture_output=True, text=True).stdout
    cpp = {b["run_name"]: b["real_time"] / 1e3 for b in json.loads(out)["benchmarks"]
           if b.get("aggregate_name") == "median"}

    values = raw_array(a.volume)
    floats = values.astype(np.float32)
    rows = []
    for eps in eps_list:
        name = f"eps:{eps:g}"
        for kind, given in (("array", floats), ("file", a.volume)):
            seconds, mesh = median_seconds(lambda: isotope.extract(given, iso=a.iso, eps=eps), a.repeats)
            rows.append({"path": kind, "eps": eps, "cpp_seconds": cpp[f"BM_ApiExtract/{kind}/{name}/real_time"],
                         "python_seconds": seconds, "triangles": int(mesh.stats["triangles"])})
    from skimage import measure
    sk_seconds, (_, sk_faces, _, _) = median_seconds(lambda: measure.marching_cubes(floats, level=a.iso), a.repeats)

    print(f"{os.path.basename(a.volume)}, iso {a.iso:g}, {os.cpu_count()} cores, median of {a.repeats}")
    print(f"{'path':6} {'eps':>6} {'C++ ms':>9} {'Python ms':>10} {'Python/C++':>11} {'target':>7} {'triangles':>10}")
    for r in rows:
        ratio = r["python_seconds"] / r["cpp_seconds"]
        r["ratio"] = ratio
        print(f"{r['path']:6} {r['eps']:6g} {1e3 * r['cpp_seconds']:9.1f} {1e3 * r['python_seconds']:10.1f} "
              f"{ratio:11.3f} {'met' if ratio <= 1.10 else 'MISSED':>7} {r['triangles']:10d}")
    print(f"scikit-image measure.marching_cubes on the same float32 array: {1e3 * sk_seconds:.1f} ms, "
          f"{len(sk_faces)} triangles (one thread; marching cubes, not tetrahedra)")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"volume": a.volume, "iso": a.iso, "rows": rows,
                       "skimage": {"seconds": sk_seconds, "triangles": len(sk_faces)}}, f, indent=2)


if __name__ == "__main__":
    main()
