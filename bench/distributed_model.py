#!/usr/bin/env python3
"""The time model of docs/DISTRIBUTED.md: `isotope convert` and `isotope extract` of an N^3 volume
on P nodes of C cores (one rank per node, C threads each), from constants measured on this
machine (--measure runs the single-process commands that give them) and stated assumptions about
the cluster (the flags). Prints one Markdown table per operation.

    python3 bench/distributed_model.py --isotope build-ci/tools/isotope --work /tmp/model --measure
"""

import argparse
import json
import os
import pathlib
import subprocess


def measure(isotope, work, size):
    """Constants from single-process runs on the smooth field (`isotope generate noise`), 1 thread:
    convert's core-ns per node, and per band-0 brick an extraction reads: core-seconds, compressed
    bytes, triangles; the fraction of band-0 bricks read; the PLY's bytes per triangle; and rank 0's
    gather and weld per triangle, from a 2-rank run's report (its wall time past its own share)."""
    work.mkdir(parents=True, exist_ok=True)
    raw = work / f"smooth_{size}x{size}x{size}_uint8.raw"
    store = work / "smooth.isotope"
    if not raw.exists():
        subprocess.run([isotope, "generate", "noise", "--size", str(size), "--type", "uint8", "-o", raw, "--quiet"],
                       check=True)
    out = subprocess.run([isotope, "convert", raw, store, "--threads", "1"], check=True, capture_output=True,
                         text=True).stdout
    seconds = float(out.split(";")[1].split(" s")[0])
    info = json.loads(subprocess.run([isotope, "info", store, "--json"], check=True, capture_output=True,
                                     text=True).stdout)
    c = {"convert_core_ns_per_node": seconds * 1e9 / size ** 3,
         "store_bytes_per_node": info["file_bytes"] / size ** 3,
         "band0_bricks": info["band_detail"][0]["bricks"]}
    for eps in ("0", "2"):
        report = work / "r.json"
        subprocess.run([isotope, "extract", store, "--iso", "128", "--eps", eps, "--threads", "1", "-o",
                        work / "m.ply", "--report", report, "--quiet"], check=True)
        r = json.loads(report.read_text())
        bricks = r["bricks_read"]
        c[f"eps{eps}"] = {"core_s_per_brick": r["extract_seconds"] / bricks,
                          "bytes_per_brick": r["bytes_read"] / bricks,
                          "fraction_of_bricks": bricks / c["band0_bricks"],  # bricks read (all bands) per band-0 brick
                          "triangles_per_brick": r["triangles"] / bricks,
                          "ply_bytes_per_triangle": (work / "m.ply").stat().st_size / max(1, r["triangles"])}
        env = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
        subprocess.run(["mpirun", "--bind-to", "none", "-n", "2", isotope, "extract", store, "--iso", "128", "--eps",
                        eps, "--threads", "1", "-o", work / "m.ply", "--report", report, "--quiet"], check=True,
                       env=dict(os.environ, **env))
        r = json.loads(report.read_text())
        past = r["extract_seconds"] - max(l["seconds"] for l in r["ranks"])
        c[f"eps{eps}"]["rank0_s_per_triangle"] = max(0.0, past) / max(1, r["triangles"])
    return c


def table(c, a):
    bw = lambda p: min(p * a.node_gbs, a.fs_gbs) * 1e9
    cores = lambda p: p * a.cores * a.thread_efficiency
    print(f"### convert (input {a.input_bytes} bytes a node; the store's bytes a node scaled from the measured "
          f"uint8 store by the same factor)\n")
    print("| volume | nodes | read input | build | hand-over I/O | bricks I/O | total |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for n in a.sizes:
        nodes = n ** 3
        for p in a.nodes:
            read = nodes * a.input_bytes / bw(p)
            build = nodes * c["convert_core_ns_per_node"] * 1e-9 / cores(p)  # measured over all bands
            # Two bands a pass: only the hand-overs to bands 2, 4, ... exist (nodes/64 + nodes/64^2 + ...).
            handover = 2 * nodes / 63 * a.handover_bytes / bw(p)
            store = 3 * nodes * c["store_bytes_per_node"] * a.input_bytes / bw(p)
            total = read + build + handover + store + a.launch_s
            print(f"| {n}^3 | {p} | {read:.0f} s | {build:.0f} s | {handover:.0f} s | {store:.0f} s | "
                  f"**{total / 60:.1f} min** |")
    for eps in ("0", "2"):
        e = c[f"eps{eps}"]
        print(f"\n### extract, eps {eps} (as the smooth field at eps {eps}: {e['fraction_of_bricks']:.0%} of band 0's "
              f"bricks read, {e['triangles_per_brick']:.0f} triangles a brick)\n")
        print("| volume | nodes | triangles | read | extract (x1.3 balance) | gather + weld on rank 0 | "
              "write one PLY | total, one file | total, --parts | rank 0 holds |")
        print("|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
        for n in a.sizes:
            bricks = e["fraction_of_bricks"] * (n / 16) ** 3
            tris = bricks * e["triangles_per_brick"]
            for p in a.nodes:
                read = bricks * e["bytes_per_brick"] / bw(p)
                work = bricks * e["core_s_per_brick"] / cores(p) * 1.3
                gather = tris * (a.wire_bytes_per_triangle / (a.network_gbs * 1e9) + e["rank0_s_per_triangle"])
                write = tris * e["ply_bytes_per_triangle"] / (a.rank0_write_gbs * 1e9)
                parts = tris * e["ply_bytes_per_triangle"] / bw(p)
                held = tris * (a.wire_bytes_per_triangle + e["ply_bytes_per_triangle"]) / 2 ** 30
                one = read + work + gather + write + a.launch_s
                many = read + work + parts + a.launch_s
                note = f"{held:,.0f} GiB" + (" (over a node's memory)" if held > a.node_memory_gib else "")
                print(f"| {n}^3 | {p} | {tris / 1e9:.1f} G | {read:.0f} s | {work:.0f} s | {gather:.0f} s | "
                      f"{write:.0f} s | **{one / 60:.1f} min** | **{many / 60:.1f} min** | {note} |")


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--isotope", default="build-ci/tools/isotope")
    p.add_argument("--work", default="/tmp/isotope-model")
    p.add_argument("--measure", action="store_true", help="measure the constants here (else read WORK/constants.json)")
    p.add_argument("--size", type=int, default=513, help="the smooth field measured")
    p.add_argument("--sizes", type=int, nargs="+", default=[4096, 8192])
    p.add_argument("--nodes", type=int, nargs="+", default=[16, 64, 256])
    p.add_argument("--cores", type=int, default=32)
    p.add_argument("--thread-efficiency", type=float, default=0.85, help="of C threads against one (measured: 2 threads)")
    p.add_argument("--input-bytes", type=int, default=2, help="per node of the input (uint16)")
    p.add_argument("--node-gbs", type=float, default=5.0, help="a node's share of the file system, GB/s")
    p.add_argument("--fs-gbs", type=float, default=100.0, help="the file system's aggregate bandwidth, GB/s")
    p.add_argument("--network-gbs", type=float, default=12.5, help="into rank 0 (100 Gb/s InfiniBand), GB/s")
    p.add_argument("--rank0-write-gbs", type=float, default=2.0, help="one process writing one file, GB/s")
    p.add_argument("--handover-bytes", type=int, default=48,
                   help="per node of a hand-over: a float and a Record (44 bytes in this x86-64 build)")
    p.add_argument("--wire-bytes-per-triangle", type=float, default=22.0,
                   help="a part's vertices (12 + 8 bytes, half a vertex a triangle) and triangles (12 bytes)")
    p.add_argument("--node-memory-gib", type=float, default=256.0)
    p.add_argument("--launch-s", type=float, default=0.5, help="mpirun and MPI_Init (measured here: 0.35 to 0.5 s)")
    a = p.parse_args()
    work = pathlib.Path(a.work)
    if a.measure:
        c = measure(a.isotope, work, a.size)
        (work / "constants.json").write_text(json.dumps(c, indent=2))
    else:
        c = json.loads((work / "constants.json").read_text())
    print("constants measured here:\n\n```\n" + json.dumps(c, indent=2) + "\n```\n")
    table(c, a)


if __name__ == "__main__":
    main()
