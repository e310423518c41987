#!/usr/bin/env python3
"""Strong scaling of `mpirun -n R isotope extract|convert` (docs/DISTRIBUTED.md) beside the single
process, threaded, in the same run: whole processes, the mesh or the store written, median wall
time of --runs. On a 2-core machine 4 ranks are oversubscribed and labelled so. Extraction is
timed with the store warm (in the page cache) and cold (evicted before every run); the report's
per-rank loads give the balance and the bytes each rank read.

    python3 bench/mpi_scaling.py --isotope build-ci/tools/isotope --data ../shared/data --work /tmp/mpi-bench
"""

import argparse
import json
import os
import pathlib
import statistics
import subprocess
import time

ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
CORES = os.cpu_count() or 1


def evict(path):
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)


def timed(cmd, cold=None):
    if cold:
        evict(cold)
    start = time.perf_counter()
    subprocess.run([str(c) for c in cmd], check=True, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    return time.perf_counter() - start


def layouts():
    """(label, ranks or None for no mpirun, threads per rank)."""
    return [("alone, 1 thread", None, 1), (f"alone, {CORES} threads", None, CORES), ("1 rank x 1", 1, 1),
            ("2 ranks x 1", 2, 1), ("2 ranks x 2" + (" (oversubscribed)" if 4 > CORES else ""), 2, 2),
            ("4 ranks x 1" + (" (oversubscribed)" if 4 > CORES else ""), 4, 1)]


def command(isotope, ranks, threads, args):
    # --bind-to none: Open MPI binds each of up to 2 ranks to one core, which would leave a rank's
    # threads on one core (docs/DISTRIBUTED.md, "Ranks and threads").
    launch = [] if ranks is None else ["mpirun", "--bind-to", "none", "--oversubscribe", "-n", str(ranks)]
    return launch + [isotope] + args + ["--threads", str(threads)]


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--isotope", required=True)
    p.add_argument("--data", required=True)
    p.add_argument("--work", required=True, help="a folder for the stores and meshes (on the disk to measure)")
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--smooth-size", type=int, default=513)
    a = p.parse_args()
    work = pathlib.Path(a.work)
    work.mkdir(parents=True, exist_ok=True)
    iso = a.isotope
    n = a.smooth_size
    raws = {"embryo": pathlib.Path(a.data) / "embryo_256x256x256_uint8.raw",
            f"smooth {n}^3": work / f"smooth_{n}x{n}x{n}_uint8.raw"}
    if not raws[f"smooth {n}^3"].exists():
        subprocess.run([iso, "generate", "noise", "--size", str(n), "--type", "uint8", "-o",
                        raws[f"smooth {n}^3"], "--quiet"], check=True)
    stores = {}
    for name, raw in raws.items():
        stores[name] = work / (name.split()[0] + ".isotope")
        subprocess.run([iso, "convert", raw, stores[name], "--quiet"], check=True)

    print(f"# isotope under mpirun: median of {a.runs} whole-process runs, seconds ({CORES} cores)\n")
    header = "| case | " + " | ".join(l for l, _, _ in layouts()) + " |"
    print(header)
    print("|" + "---|" * (len(layouts()) + 1))
    cases = []
    for name, (i, eps_list) in {"embryo": ("50", ["0", "4"]), f"smooth {n}^3": ("128", ["0", "2"])}.items():
        for eps in eps_list:
            for cold in (False, True):
                cases.append((f"extract {name} eps {eps}, {'cold' if cold else 'warm'}",
                              ["extract", stores[name], "--iso", i, "--eps", eps, "-o", work / "m.ply", "--quiet"],
                              stores[name] if cold else None))
    for name, raw in raws.items():
        cases.append((f"convert {name}", ["convert", raw, work / "c.isotope", "--quiet"], None))
    for label, args, cold in cases:
        row = []
        for _, ranks, threads in layouts():
            cmd = command(iso, ranks, threads, args)
            row.append(statistics.median(timed(cmd, cold) for _ in range(a.runs)))
        print(f"| {label} | " + " | ".join(f"{t:.2f}" for t in row) + " |", flush=True)

    print("\n# balance: the largest rank over the mean (work: tetrahedra visited, cells marched at eps 0),"
          " and compressed bytes each rank read, MB\n")
    print("| case | ranks | work max/mean | time max/mean | MB read per rank | MB read alone |")
    print("|---|---:|---:|---:|---|---:|")
    for name, (i, eps_list) in {"embryo": ("50", ["0", "4"]), f"smooth {n}^3": ("128", ["0", "2"])}.items():
        for eps in eps_list:
            base = ["extract", stores[name], "--iso", i, "--eps", eps, "-o", work / "m.ply", "--quiet",
                    "--report", work / "r.json"]
            subprocess.run([iso] + base, check=True, env=ENV)
            alone = json.loads((work / "r.json").read_text())["bytes_read"] / 1e6
            for ranks in (2, 4):
                subprocess.run(command(iso, ranks, 1, base), check=True, env=ENV)
                loads = json.loads((work / "r.json").read_text())["ranks"]
                b = json.loads((work / "r.json").read_text())["balance"]
                mb = ", ".join(f"{l['bytes_read'] / 1e6:.1f}" for l in loads)
                print(f"| {name} eps {eps} | {ranks} | {b['work_max_over_mean']:.2f} | "
                      f"{b['seconds_max_over_mean']:.2f} | {mb} | {alone:.1f} |", flush=True)


if __name__ == "__main__":
    main()
