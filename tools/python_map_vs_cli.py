#!/usr/bin/env python3
"""Usage: tools/python_map_vs_cli.py PYTHON ZWIDTH SCENE RUNS

Issue 35's criterion, read literally: `import zwidth` and a draft map of
the seed device, timed inside the Python process, against the CLI's whole
run of the same map, alternately in one run; pairwise ratios."""
import statistics, subprocess, sys, time
py, cli, scene, n = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
code = ("import time; t0 = time.perf_counter(); import zwidth; "
        f"m = zwidth.map({scene!r}, accuracy='draft'); print(time.perf_counter() - t0, m.k_width)")
ratios, ins, clis, whole = [], [], [], []
for i in range(n + 1):
    t = time.perf_counter()
    out = subprocess.run([py, "-c", code], check=True, capture_output=True, text=True).stdout.split()
    w = time.perf_counter() - t
    t = time.perf_counter()
    subprocess.run([cli, "map", "--scene", scene, "--accuracy", "draft"], check=True, capture_output=True)
    c = time.perf_counter() - t
    if i == 0:
        continue  # warm-up
    ins.append(float(out[0])); clis.append(c); whole.append(w); ratios.append(float(out[0]) / c)
med = statistics.median
print(f"import+map in process {med(ins):.3f} s, python whole process {med(whole):.3f} s, CLI {med(clis):.3f} s")
print(f"pairwise in-process/CLI: median {med(ratios):.3f} (min {min(ratios):.3f}, max {max(ratios):.3f}); "
      f"whole/CLI median {med([a / b for a, b in zip(whole, clis)]):.3f}")
