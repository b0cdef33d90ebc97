#!/usr/bin/python3
"""The Python module's overhead over vdb2mesh on the paper's phantom (target: <= 5%).

    python_bench.py --bin build/bin --pythonpath build/python [--rounds 9] [--size 100] [--quick]

Writes the phantom (vdbphantom cube-cavity --noise 0.5 --seed 1), then runs, interleaved, ROUNDS times:
  cli    vdb2mesh p.vdb cli.ply -q --stats: its own total (the stats' summary.seconds: read, pipeline,
         topology, write), the process's wall time and peak memory (/usr/bin/time -f %M);
  path   a fresh /usr/bin/python3: riemesh.mesh('p.vdb') then .save(): the call's time (perf_counter),
         the process's wall time and peak memory;
  array  the same on the phantom as a C-ordered float32 numpy array (riemesh.mesh(array, 0.5)), the
         array read beforehand through pyopenvdb (not timed).
Every run must give the same mesh as vdb2mesh (the PLY's bytes after the header comment). Prints the
medians and the overheads of the calls over vdb2mesh's own total (the interpreter's start-up and
numpy's import are reported apart, in the wall times). --quick: a 48^3 phantom, 2 rounds (for ctest:
the pipeline runs; the figures mean little).
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile

PYTHON = "/usr/bin/python3"

CHILD = r"""
import sys, time, json
import numpy as np
import riemesh
mode, image, out = sys.argv[1:4]
if mode == "array":
    import pyopenvdb
    grid = pyopenvdb.read(image, "density")
    (lo, hi) = grid.evalActiveVoxelBoundingBox()
    volume = np.zeros([h - l + 1 for l, h in zip(lo, hi)], np.float32)
    grid.copyToArray(volume, ijk=lo)
    del grid
    start = time.perf_counter()
    result = riemesh.mesh(volume, 0.5)
else:
    start = time.perf_counter()
    result = riemesh.mesh(image)
result.save(out)
print(json.dumps({"seconds": time.perf_counter() - start, "vertices": len(result.vertices)}))
"""


def timed(cmd, env=None):
    """(stdout, wall seconds, peak KB) of cmd under /usr/bin/time."""
    p = subprocess.run(["/usr/bin/time", "-f", "@@ %e %M"] + cmd, capture_output=True, text=True, env=env)
    if p.returncode != 0:
        sys.exit("python_bench: %s failed: %s" % (" ".join(cmd), p.stderr.strip()[-500:]))
    last = [line for line in p.stderr.splitlines() if line.startswith("@@ ")][-1].split()
    return p.stdout, float(last[1]), int(last[2])


def mesh_bytes(path):
    """A PLY file's bytes without its header comment (which names the program)."""
    data = open(path, "rb").read()
    end = data.index(b"end_header\n")
    header = b"\n".join(line for line in data[:end].split(b"\n") if not line.startswith(b"comment"))
    return header + data[end:]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", required=True)
    ap.add_argument("--pythonpath", required=True)
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--size", type=int, default=100)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.quick:
        args.rounds, args.size = 2, 48
    env = dict(os.environ, PYTHONPATH=os.path.abspath(args.pythonpath))
    with tempfile.TemporaryDirectory(prefix="python_bench_") as work:
        image = os.path.join(work, "p.vdb")
        subprocess.run([os.path.join(args.bin, "vdbphantom"), "cube-cavity", image, "--size", str(args.size),
                        "--noise", "0.5", "--seed", "1"], check=True, capture_output=True)
        rows = {"cli": [], "path": [], "array": []}
        reference = None
        for _ in range(args.rounds):
            cli_ply, stats = os.path.join(work, "cli.ply"), os.path.join(work, "cli.json")
            _, wall, kb = timed([os.path.join(args.bin, "vdb2mesh"), image, cli_ply, "-q", "--stats", stats])
            summary = json.load(open(stats))["summary"]
            rows["cli"].append((summary["seconds"], wall, kb))
            if summary.get("malloc_huge_pages"):
                # vdb2mesh restarted itself with malloc on huge pages: the module gets the same
                # allocator (as a user sets it: GLIBC_TUNABLES before the interpreter starts), so the
                # overhead measured is the module's own.
                env["GLIBC_TUNABLES"] = "glibc.malloc.hugetlb=1"
            reference = mesh_bytes(cli_ply)
            for mode in ("path", "array"):
                out = os.path.join(work, mode + ".ply")
                stdout, wall, kb = timed([PYTHON, "-c", CHILD, mode, image, out], env)
                call = json.loads(stdout.strip().splitlines()[-1])
                if mesh_bytes(out) != reference:
                    sys.exit("python_bench: the %s run gave another mesh than vdb2mesh" % mode)
                rows[mode].append((call["seconds"], wall, kb))
        print("python_bench: cube-cavity %d^3 noise 0.5 seed 1, %d interleaved rounds, %d vertices (same mesh in "
              "every run)" % (args.size, args.rounds, summary["vertices"]))
        print("%-28s %10s %10s %10s %10s" % ("", "call s", "min s", "wall s", "peak MB"))
        med = {}
        for name, label in (("cli", "vdb2mesh (own total)"), ("path", "riemesh.mesh('p.vdb')"),
                            ("array", "riemesh.mesh(float32 array)")):
            calls = [r[0] for r in rows[name]]
            med[name] = statistics.median(calls)
            print("%-28s %10.3f %10.3f %10.3f %10.1f" % (label, med[name], min(calls),
                                                         statistics.median(r[1] for r in rows[name]),
                                                         max(r[2] for r in rows[name]) / 1024))
        for name in ("path", "array"):
            overhead = med[name] / med["cli"] - 1
            verdict = "meets" if overhead <= 0.05 else "misses"
            print("overhead of %-5s over vdb2mesh: %+.1f%% (median call), %+.1f%% (fastest call): %s the <= 5%% target"
                  % (name, 100 * overhead, 100 * (min(r[0] for r in rows[name]) / min(r[0] for r in rows["cli"]) - 1),
                     verdict))


if __name__ == "__main__":
    main()
