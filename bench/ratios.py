#!/usr/bin/env python3
"""Every extraction time of an isotope_bench run as a ratio to the full-resolution baseline.

Google Benchmark cannot put one benchmark's time into another's counters, so the ratio the
issue asks for ("every extraction figure also a ratio against the baseline, from the same run")
is computed here from the JSON output:

    ./build-bench/bench/isotope_bench --benchmark_filter='BM_Extract|BM_FullResolutionBaseline' \\
        --benchmark_out=bench.json --benchmark_out_format=json
    python3 bench/ratios.py bench.json

For every BM_Extract and BM_ExtractPaged row it prints its wall time, the wall time of
BM_FullResolutionBaseline of the same dataset and thread count, time / baseline (below 1: faster
than marching every cell of the raw array) and the triangles over the baseline's. With
--benchmark_repetitions, the aggregate named by --aggregate (median by default) is used, or the
median of the repetitions if the file holds no aggregates. Standard library only.
"""

import argparse
import json
import statistics
import sys

TO_MS = {"ns": 1e-6, "us": 1e-3, "ms": 1.0, "s": 1e3}
# Name parts Google Benchmark appends on its own: not part of what a row measures.
HARNESS_PARTS = ("min_time:", "min_warmup_time:", "iterations:", "repeats:", "real_time", "process_time",
                 "manual_time")
EXTRACTIONS = ("BM_Extract", "BM_ExtractPaged")
BASELINE = "BM_FullResolutionBaseline"


def load(path):
    text = sys.stdin.read() if path == "-" else open(path, encoding="utf-8").read()
    # Console text before the JSON (a redirected stderr, say) is skipped.
    return json.loads(text[text.index("{"):])


def clean_name(run_name):
    """BM_Extract/bolt/eps:8/mode:none/threads:2/min_time:0.300/real_time -> ...threads:2"""
    return "/".join(p for p in run_name.split("/") if not p.startswith(HARNESS_PARTS))


def parse(name):
    """(family, dataset, {key: value}) of a name like BM_Extract/bolt/eps:8/mode:none/threads:2."""
    parts = name.split("/")
    params = dict(p.split(":", 1) for p in parts[2:] if ":" in p)
    return parts[0], parts[1] if len(parts) > 1 else "", params


def pick_rows(benchmarks, aggregate):
    """One (time in ms, triangles) per benchmark name, in the file's order."""
    chosen, repetitions, order = {}, {}, []
    for b in benchmarks:
        if b.get("error_occurred"):
            continue
        name = clean_name(b.get("run_name", b["name"]))
        if name not in order:
            order.append(name)
        row = (b["real_time"] * TO_MS[b.get("time_unit", "ns")], b.get("triangles"))
        if b.get("run_type") == "aggregate":
            if b.get("aggregate_name") == aggregate:
                chosen[name] = row
        else:
            repetitions.setdefault(name, []).append(row)
    for name, rows in repetitions.items():
        if name not in chosen:
            chosen[name] = (statistics.median(r[0] for r in rows), rows[0][1])
    return [(name, *chosen[name]) for name in order if name in chosen]


def format_ms(ms):
    return f"{ms:.4g}"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("json", help="isotope_bench JSON output (--benchmark_out or --benchmark_format=json), - for stdin")
    parser.add_argument("--aggregate", default="median", help="aggregate to use with repetitions (default: median)")
    args = parser.parse_args()

    rows = pick_rows(load(args.json)["benchmarks"], args.aggregate)
    baselines = {}
    for name, ms, triangles in rows:
        family, dataset, params = parse(name)
        if family == BASELINE:
            baselines[(dataset, params.get("threads"))] = (ms, triangles)

    table = [("benchmark", "time ms", "baseline ms", "time/baseline", "triangles/baseline's")]
    missing = 0
    for name, ms, triangles in rows:
        family, dataset, params = parse(name)
        if family not in EXTRACTIONS:
            continue
        base = baselines.get((dataset, params.get("threads")))
        if base is None:
            missing += 1
            table.append((name, format_ms(ms), "-", "-", "-"))
            continue
        tri = f"{triangles / base[1]:.4g}" if triangles is not None and base[1] else "-"
        table.append((name, format_ms(ms), format_ms(base[0]), f"{ms / base[0]:.4g}", tri))
    if len(table) == 1:
        sys.exit("no BM_Extract or BM_ExtractPaged rows in " + args.json)

    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]))]
    for row in table:
        print("  ".join(cell.ljust(w) if i == 0 else cell.rjust(w) for i, (cell, w) in enumerate(zip(row, widths))))
    if missing:
        print(f"\n{missing} rows have no BM_FullResolutionBaseline of the same dataset and threads in this file: "
              "include it in --benchmark_filter.", file=sys.stderr)


if __name__ == "__main__":
    main()
