#!/usr/bin/python3
"""The paper's experiments (Taton & Lachaud 2003, section 5), reproduced against peers, as one report.

    report.py --bin BUILD/bin --out DIR [--quick] [--docs DOCS_DIR] [--sections a,b,...]

Runs vdbphantom, vdb2mesh, vdb_bench, render_mesh and, where it was built (CGAL installed), cgal_bench
(every run with its own timeout; a failed or
timed-out run becomes a row that says so, never an abort), writes CSV tables, gnuplot PNGs and
DIR/benchmarks.md; with --docs also DOCS_DIR/benchmarks.md with the PNGs and CSVs under
DOCS_DIR/benchmarks/. Verdicts on the targets are computed from the numbers of this run.

--quick: a small phantom and few settings (seconds; for CI): exits non-zero when any run or plot
fails, so the pipeline cannot rot. The full run exits non-zero only when the report itself fails.
Standard library only (Debian's /usr/bin/python3); plots need gnuplot (Debian gnuplot-nox).
"""
import argparse
import datetime
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time

SECTIONS = ["phantom", "plate", "peers", "sharp", "noise", "resolution", "head", "guarantee", "metric", "core",
            "growth"]
HEAD = "/usr/share/mricron/templates/ch2.nii.gz"


class Bench:
    def __init__(self, args):
        self.bin = os.path.abspath(args.bin)
        self.out = os.path.abspath(args.out)
        self.quick = args.quick
        self.failures = []  # (what, why) of every run that did not succeed
        self.work = os.path.join(self.out, "tmp")  # large intermediates (volumes, meshes): not committed
        shutil.rmtree(self.work, ignore_errors=True)  # nothing from an earlier run is reused
        os.makedirs(self.work)
        self.pngs = []
        self.csvs = []

    # ---- running programs ---------------------------------------------------------------------
    def run(self, what, cmd, timeout):
        """Runs cmd; returns (ok, stdout, seconds, why). Never raises for a failing program."""
        start = time.monotonic()
        try:
            p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            why = "timeout after %d s" % timeout
            self.failures.append((what, why))
            return False, "", time.monotonic() - start, why
        except OSError as e:
            why = "cannot run: %s" % e
            self.failures.append((what, why))
            return False, "", time.monotonic() - start, why
        secs = time.monotonic() - start
        if p.returncode != 0:
            last = (p.stderr.strip().splitlines() or ["(no message)"])[-1]
            why = "exit %d: %s" % (p.returncode, last[:160])
            self.failures.append((what, why))
            return False, p.stdout, secs, why
        return True, p.stdout, secs, ""

    def tool(self, name):
        return os.path.join(self.bin, name)

    def phantom(self, size, noise, seed=1, shape="cube-cavity"):
        tag = "" if shape == "cube-cavity" else shape + "_"
        seeded = "" if seed == 1 else "_seed%d" % seed  # seed 1 keeps the names the sections always used
        path = os.path.join(self.work, "phantom_%ss%d_n%g%s.vdb" % (tag, size, noise, seeded))
        if not os.path.exists(path):
            ok, _, _, why = self.run("vdbphantom %s %d %g seed %d" % (shape, size, noise, seed),
                                     [self.tool("vdbphantom"), shape, path, "--size", str(size),
                                      "--noise", str(noise), "--seed", str(seed)], 120)
            if not ok:
                return None
        return path

    def vdb2mesh(self, name, image, extra, timeout, reference=True):
        """One riemesh run; returns a dict of its summary (status 'ok' or why it failed)."""
        mesh = os.path.join(self.work, name + ".obj")
        stats = os.path.join(self.work, name + ".json")
        cmd = [self.tool("vdb2mesh"), image, mesh, "--stats", stats, "-q"] + extra
        if reference and image.endswith(".vdb"):
            cmd += ["--reference", image + ":sdf"]
        for f in (mesh, stats):
            if os.path.exists(f):
                os.remove(f)
        ok, _, secs, why = self.run("vdb2mesh " + name, cmd, timeout)
        row = {"name": name, "status": "ok" if ok else why, "mesh": mesh, "stats": stats, "wall": secs}
        if ok:
            with open(stats) as f:
                j = json.load(f)
            s = j["summary"]
            row.update(vertices=s["vertices"], components=s["components"], genus=s["genus"],
                       iterations=s["iterations"], stop=s["stop"], seconds=s["seconds"],
                       metric_seconds=s["metric_seconds"], evolve_seconds=s["evolve_seconds"],
                       read_seconds=s.get("read_seconds", 0.0), write_seconds=s.get("write_seconds", 0.0),
                       delta=j["parameters"]["delta_voxels"],
                       energy=[(it["iteration"], it["mean_kinetic_energy"]) for it in j["iterations"]])
            if "reference" in j:
                ref = j["reference"]
                row.update(mean=ref["mean_voxels"], hausdorff=ref["hausdorff_voxels"],
                           surface_mean=ref.get("mean_surface_to_mesh_voxels"))
        return row

    def peers(self, image, label, extra, timeout, obj_dir=None):
        cmd = [self.tool("vdb_bench"), "mesh", image, "--label", label] + extra
        if image.endswith(".vdb"):
            cmd += ["--reference", image + ":sdf"]
        if obj_dir:
            os.makedirs(obj_dir, exist_ok=True)
            cmd += ["--obj-dir", obj_dir]
        ok, out, _, why = self.run("vdb_bench mesh " + label, cmd, timeout)
        rows = parse_csv(out)
        for r in rows:
            r["status"] = "ok"
        if not ok:
            rows.append({"image": label, "tool": "openvdb/marching-cubes", "setting": " ".join(extra),
                         "status": why})
        return rows

    def render(self, mesh, png, title, extra=()):
        ok, _, _, _ = self.run("render_mesh " + os.path.basename(png),
                               [self.tool("render_mesh"), mesh, png, "--size", "800x640", "--color", "edge-length",
                                "--title", title] + list(extra), 120)
        if ok:
            self.pngs.append(png)
        return ok

    def write_csv(self, name, rows, columns):
        path = os.path.join(self.out, name)
        tmp = path + ".tmp"
        with open(tmp, "w") as f:
            f.write(",".join(columns) + "\n")
            for r in rows:
                f.write(",".join(csv_cell(r.get(c, "")) for c in columns) + "\n")
        os.replace(tmp, path)
        self.csvs.append(path)

    def plot(self, name, script, data):
        """Runs a gnuplot script; `data` maps data file names (in the work dir) to their text."""
        for fname, text in data.items():
            with open(os.path.join(self.work, fname), "w") as f:
                f.write(text)
        png = os.path.join(self.out, name)
        header = ('set terminal pngcairo size 900,600 font "DejaVu Sans,12" noenhanced\n'
                  'set output "%s.tmp"\nset grid\nset key top right\ncd "%s"\n' % (png, self.work))
        if not shutil.which("gnuplot"):
            self.failures.append(("plot " + name, "gnuplot not installed (scripts/setup installs gnuplot-nox)"))
            return False
        script_path = os.path.join(self.work, name + ".gp")
        with open(script_path, "w") as f:
            f.write(header + script + "\nunset output\n")
        ok, _, _, _ = self.run("plot " + name, ["gnuplot", script_path], 60)
        if ok and os.path.exists(png + ".tmp"):
            os.replace(png + ".tmp", png)
            self.pngs.append(png)
            return True
        return False


# ---- small helpers -------------------------------------------------------------------------------
# Issue 16's side by side: riemesh without its sharpening (on by default) and with its option that is
# off by default (name, flags, file suffix), and every method of its tables in order.
SHARP_VARIANTS = [("riemesh --no-sharpen", ["--no-sharpen"], "N"),
                  ("riemesh --face-samples", ["--face-samples"], "F")]
SHARP_METHODS = ("riemesh",) + tuple(v[0] for v in SHARP_VARIANTS) + ("volumeToMesh", "CGAL Mesh_3")

def parse_csv(text):
    lines = [l for l in text.splitlines() if l.strip()]
    rows, header = [], None
    for line in lines:
        cells = split_csv(line)
        if header is None or cells == header:
            header = cells
            continue
        rows.append(dict(zip(header, cells)))
    for r in rows:
        for k, v in list(r.items()):
            r[k] = number(v)
    return rows


def split_csv(line):
    cells, cur, quoted = [], "", False
    for ch in line:
        if ch == '"':
            quoted = not quoted
        elif ch == "," and not quoted:
            cells.append(cur)
            cur = ""
        else:
            cur += ch
    cells.append(cur)
    return cells


def number(v):
    try:
        return int(v)
    except (TypeError, ValueError):
        pass
    try:
        return float(v)
    except (TypeError, ValueError):
        return v


def csv_cell(v):
    if isinstance(v, float):
        v = "%.5g" % v
    v = str(v)
    return '"%s"' % v if "," in v else v


def fmt(v, digits=3):
    if v is None or v == "":
        return "–"
    if isinstance(v, float):
        if abs(v) >= 100:
            return "{:,.0f}".format(v)
        return ("%%.%dg" % digits) % v
    if isinstance(v, int):
        return "{:,}".format(v)
    return str(v)


def fmt_hausdorff(v):
    """surfaceError reads distances from a 16-voxel band: 16 means 'at least 16', a missed part."""
    if isinstance(v, (int, float)) and v >= 15.99:
        return ">= 16 (cap: a part of the surface is missed)"
    return fmt(v)


def obj_edge_lengths(path):
    verts, edges = [], set()
    with open(path) as f:
        for line in f:
            if line.startswith("v "):
                _, x, y, z = line.split()[:4]
                verts.append((float(x), float(y), float(z)))
            elif line.startswith("f "):
                idx = [int(t.split("/")[0]) - 1 for t in line.split()[1:]]
                for a, b in zip(idx, idx[1:] + idx[:1]):
                    edges.add((min(a, b), max(a, b)))
    return [math.dist(verts[a], verts[b]) for a, b in edges]


def percentile(values, q):
    s = sorted(values)
    if not s:
        return float("nan")
    pos = q / 100.0 * (len(s) - 1)
    lo = int(math.floor(pos))
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


def ok(row):
    return row.get("status") == "ok"


def topology_ok(row):
    """One closed surface of genus 0 (the phantom's true topology)."""
    return ok(row) and row.get("components") == 1 and row.get("genus") == 0 and row.get("closed_manifold", 1) == 1


def topo_text(row):
    if not ok(row):
        return "–"
    text = "%s comp., genus %s" % (fmt(row.get("components")), fmt(row.get("genus")))
    if row.get("closed_manifold", 1) != 1:
        text += " (not a closed manifold: %s open, %s bad edges)" % (row.get("boundary_edges"), row.get("bad_edges"))
    return text


def table(columns, rows):
    """Markdown table: columns are (header, function of row)."""
    out = ["| " + " | ".join(h for h, _ in columns) + " |", "|" + "---|" * len(columns)]
    for r in rows:
        out.append("| " + " | ".join(str(f(r)) for _, f in columns) + " |")
    return "\n".join(out)


def verdict(value, limit, better="lower"):
    """'met' or 'missed by X' for a ratio against its limit."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "not measured"
    met = value <= limit if better == "lower" else value >= limit
    if met:
        return "**met** (%.2f vs limit %.2f)" % (value, limit)
    return "**missed** by %.0f%% (%.2f vs limit %.2f)" % (100.0 * (value / limit - 1.0), value, limit)


# ---- the experiments -----------------------------------------------------------------------------
class Report:
    def __init__(self, bench, args):
        self.b = bench
        self.q = args.quick
        self.size = 40 if self.q else 100
        self.scale = self.size / 100.0  # physical lengths scale with the box (the phantom scales with N)
        self.md = []
        self.results = {}
        self.timeout = 60 if self.q else 600

    def section(self, title, text=""):
        self.md.append("\n## " + title + "\n")
        if text:
            self.md.append(text + "\n")

    def image(self, png, alt):
        if os.path.exists(png):
            self.md.append("\n![%s](%s)\n" % (alt, os.path.basename(png)))

    @staticmethod
    def deltas(r, scale):
        """The Euclidean models' deltas, as in the paper (section 5: "the mesh resolutions of the
        Euclidean models are chosen so as to correspond to the minimal and maximal edge lengths achieved
        by our Riemannian model"): the shortest and the longest Euclidean edge of the Riemannian model's
        result as the evolution leaves it (a --no-sharpen run: the sharpening's moves shorten edges at
        corners), plus its 5th and 95th percentiles for a sensitivity check. Nominal 1.5 and 6 voxels (x scale)
        when that run failed or left no surface."""
        lengths = obj_edge_lengths(r["mesh"]) if ok(r) else []
        if not lengths:
            return dict(fine=1.5 * scale, coarse=6.0 * scale, p5=1.5 * scale, p95=6.0 * scale, nominal=True)
        return dict(fine=min(lengths), coarse=max(lengths), p5=percentile(lengths, 5),
                    p95=percentile(lengths, 95), nominal=False)

    def delta_text(self, d, unit):
        if d["nominal"]:
            return ("Deltas: nominal fine %s and coarse %s %s, because the Riemannian run failed or left no "
                    "surface to take edge lengths from.\n" % (fmt(d["fine"]), fmt(d["coarse"]), unit))
        return ("Deltas, as in the paper (\"the mesh resolutions of the Euclidean models are chosen so as to "
                "correspond to the minimal and maximal edge lengths achieved by our Riemannian model\"): the "
                "fine Euclidean model's delta is the Riemannian result's shortest Euclidean edge before sharpening "
                "(%s %s), the "
                "coarse one's its longest (%s %s). The Riemannian edges' 5th and 95th percentiles are %s and "
                "%s %s.\n" % (fmt(d["fine"]), unit, fmt(d["coarse"]), unit, fmt(d["p5"]), fmt(d["p95"]), unit))

    # 1. Table 2 and Fig. 5 --------------------------------------------------------------------
    def phantom(self):
        b = self.b
        img = b.phantom(self.size, 0.5)
        self.section("Table 2 and Fig. 5: the paper's phantom",
                     "`vdbphantom cube-cavity --size %d --noise 0.5 --seed 1` (a cube with a spherical cavity "
                     "opening through a hole in its top face; the true surface is one component of genus 0). "
                     "Errors are distances to the exact surface in voxels, measured by `vdb2mesh --reference` "
                     "both ways from dense samples of both surfaces: mean err = mesh -> true surface (about 4 "
                     "samples per square voxel over the triangles, area-weighted), true->mesh mean = from samples "
                     "of the exact surface, its edges and corners included (the phantom's analytic distance), and "
                     "Hausdorff = the larger of the two maxima (vdb/src/level_set.cpp)." % self.size)
        if img is None:
            self.md.append("The phantom could not be made: %s\n" % b.failures[-1][1])
            return
        r = b.vdb2mesh("phantom_R", img, ["--delta", "%g" % (3 * self.scale)], self.timeout)
        d = self.deltas(b.vdb2mesh("phantom_R_unsharpened", img, ["--delta", "%g" % (3 * self.scale), "--no-sharpen"],
                                   self.timeout), self.scale)
        self.results["deltas"] = d
        fe = b.vdb2mesh("phantom_FE", img, ["--metric", "euclidean", "--delta", "%.4g" % d["fine"]], self.timeout)
        ce = b.vdb2mesh("phantom_CE", img, ["--metric", "euclidean", "--delta", "%.4g" % d["coarse"]], self.timeout)
        rows = [dict(ce, model="coarse Euclidean"), dict(r, model="Riemannian"), dict(fe, model="fine Euclidean")]
        # Sensitivity: a fine model at the 5th percentile instead of the shortest edge.
        fe5 = b.vdb2mesh("phantom_FE5", img, ["--metric", "euclidean", "--delta", "%.4g" % d["p5"]], self.timeout)
        self.results["table2"] = rows
        self.results["table2_fe5"] = fe5
        b.write_csv("table2_phantom.csv", rows, ["model", "status", "delta", "seconds", "metric_seconds",
                                                   "evolve_seconds", "iterations", "stop", "vertices", "mean",
                                                   "hausdorff", "components", "genus"])
        self.md.append(self.delta_text(d, "voxels"))
        self.md.append("The Riemannian model runs at vdb2mesh's default delta (3 voxels of metric length, scaled "
                       "with the box).\n")
        if ok(fe5):
            self.md.append("Sensitivity: a fine Euclidean model at the 5th percentile (delta %s) has %s vertices, "
                           "mean error %s, Hausdorff %s, %s component(s) of genus %s.\n" % (
                               fmt(fe5.get("delta")), fmt(fe5.get("vertices")), fmt(fe5.get("mean")),
                               fmt_hausdorff(fe5.get("hausdorff")), fmt(fe5.get("components")), fmt(fe5.get("genus"))))
        else:
            self.md.append("Sensitivity run (fine Euclidean at the 5th percentile): %s.\n" % fe5["status"])
        self.md.append(table([
            ("model", lambda x: x["model"]), ("delta (vox)", lambda x: fmt(x.get("delta"))),
            ("seconds", lambda x: fmt(x.get("seconds"))), ("of which metric", lambda x: fmt(x.get("metric_seconds"))),
            ("iterations", lambda x: "%s (%s)" % (fmt(x.get("iterations")), x.get("stop", "–"))),
            ("vertices", lambda x: fmt(x.get("vertices"))), ("mean err (vox)", lambda x: fmt(x.get("mean"))),
            ("true->mesh mean (vox)", lambda x: fmt(x.get("surface_mean"))),
            ("Hausdorff (vox)", lambda x: fmt_hausdorff(x.get("hausdorff"))),
            ("components", lambda x: fmt(x.get("components"))), ("genus", lambda x: fmt(x.get("genus"))),
            ("status", lambda x: x["status"])], rows))
        self.md.append("\nThe paper (Table 2; 100^3, its own machine in 2003): coarse 27 s / 1,751 vertices, "
                       "Riemannian 3 min 20 s / 4,829, fine 8 min 04 s / 8,499; structure tensor and metric 19 s.\n")
        # Cut through the middle (y = centre) to show the cavity and the hole.
        self.fig5(rows, "phantom", "Fig. 5", ["--clip", "y:%g" % (0.5 * (self.size - 1))])

    # 1b. Thin plate: topology kept where the coarse model breaks it -----------------------------
    def plate(self):
        b = self.b
        img = b.phantom(self.size, 0.5, shape="thin-plate")
        self.section("Topology: the thin plate",
                     "`vdbphantom thin-plate --size %d --noise 0.5 --seed 1`: a plate %s x %s x 3 voxels (one "
                     "component of genus 0). The paper (4.2, 5): along flat contours the metric overestimates "
                     "lengths across the contour, so the Riemannian model keeps thin structures that a Euclidean "
                     "model of the same resolution punches through. Euclidean models at the phantom's coarse and "
                     "fine deltas (Table 2) and at the Riemannian model's delta. Right topology = one component of "
                     "genus 0 that covers the whole plate (Hausdorff distance below the 16-voxel cap)." % (
                         self.size, fmt(0.7 * self.size), fmt(0.7 * self.size)))
        if img is None:
            self.md.append("The plate could not be made: %s\n" % b.failures[-1][1])
            return
        d = self.results.get("deltas") or self.deltas({"status": "none"}, self.scale)
        runs = [("Riemannian", []),
                ("coarse Euclidean", ["--metric", "euclidean", "--delta", "%.4g" % d["coarse"]]),
                ("Euclidean at the Riemannian delta", ["--metric", "euclidean", "--delta", "%g" % (3 * self.scale)]),
                ("fine Euclidean", ["--metric", "euclidean", "--delta", "%.4g" % d["fine"]])]
        rows = []
        for i, (model, extra) in enumerate(runs):
            args = extra if extra else ["--delta", "%g" % (3 * self.scale)]
            x = b.vdb2mesh("plate_%d" % i, img, args, self.timeout)
            if not ok(x) and "no surface left" in x["status"]:
                # A model that lost the whole plate is this experiment's outcome, not a failed run:
                # vdb2mesh refuses to write an empty mesh (exit 1).
                b.failures = [f for f in b.failures if f[0] != "vdb2mesh plate_%d" % i]
                m = re.search(r"after (\d+) iterations", x["status"])
                x.update(status="ok", vertices=0, components=0, genus=0, stop="no surface left",
                         delta=float(args[args.index("--delta") + 1]), iterations=int(m.group(1)) if m else None)
            x["model"] = model
            x["kept"] = ok(x) and x.get("components") == 1 and x.get("genus") == 0 and x.get("hausdorff", 99) < 16
            rows.append(x)
        self.results["plate"] = rows
        b.write_csv("thin_plate.csv", rows, ["model", "status", "delta", "seconds", "iterations", "stop", "vertices",
                                             "mean", "hausdorff", "components", "genus", "kept"])
        self.md.append(table([
            ("model", lambda x: x["model"]), ("delta (vox)", lambda x: fmt(x.get("delta"))),
            ("vertices", lambda x: fmt(x.get("vertices"))),
            ("iterations", lambda x: "%s (%s)" % (fmt(x.get("iterations")), x.get("stop", "–"))),
            ("mean err (vox)", lambda x: fmt(x.get("mean"))),
            ("true->mesh mean (vox)", lambda x: fmt(x.get("surface_mean"))),
            ("Hausdorff (vox)", lambda x: fmt_hausdorff(x.get("hausdorff"))),
            ("components", lambda x: fmt(x.get("components"))), ("genus", lambda x: fmt(x.get("genus"))),
            ("plate kept", lambda x: ("yes" if x["kept"] else "**no**") if ok(x) else "–"),
            ("status", lambda x: x["status"])], rows))
        shots = []
        for x in rows:
            if ok(x) and x.get("vertices", 0) > 0:
                png = os.path.join(b.out, "plate_%s.png" % x["name"].split("_")[1])
                if b.render(x["mesh"], png, "%s: %s vertices" % (x["model"], fmt(x["vertices"])), ["--wire"]):
                    shots.append((x["model"], png))
        if shots:
            self.md.append("\n| %s |\n|%s\n| %s |\n" % (" | ".join(m for m, _ in shots), "---|" * len(shots),
                                                        " | ".join("![%s](%s)" % (m, os.path.basename(p))
                                                                   for m, p in shots)))

    def fig5(self, rows, tag, figure, render_extra=()):
        b = self.b
        good = [x for x in rows if ok(x) and x.get("vertices")]
        if not good:
            return
        # Kinetic energy against iteration (log y), as in the paper.
        data, plots = {}, []
        for i, x in enumerate(good):
            fname = "%s_energy_%d.dat" % (tag, i)
            data[fname] = "".join("%d %.6g\n" % (it, e) for it, e in x["energy"] if e > 0)
            plots.append('"%s" using 1:2 with lines lw 2 title "%s (%s vertices)"' % (fname, x["model"], fmt(x["vertices"])))
        b.plot("%s_kinetic_energy.png" % tag,
               'set logscale y\nset format y "1e%%T"\nset xlabel "iteration"\n'
               'set ylabel "mean kinetic energy per vertex"\nset title "%s: mean kinetic energy"\n'
               'plot %s' % (figure, ", ".join(plots)), data)
        self.image(os.path.join(b.out, "%s_kinetic_energy.png" % tag), "kinetic energy")
        # Edge-length histograms (fraction of edges per bin, Euclidean lengths in voxels).
        data, plots = {}, []
        all_lengths = {x["model"]: obj_edge_lengths(x["mesh"]) for x in good}
        top = max(percentile(v, 99.5) for v in all_lengths.values())
        width = max(top / 40.0, 1e-3)
        for i, (model, lengths) in enumerate(all_lengths.items()):
            bins = {}
            for l in lengths:
                bins[int(l / width)] = bins.get(int(l / width), 0) + 1
            fname = "%s_hist_%d.dat" % (tag, i)
            data[fname] = "".join("%.5g %.5g\n" % ((k + 0.5) * width, bins.get(k, 0) / len(lengths))
                                  for k in range(0, int(top / width) + 2))
            plots.append('"%s" using 1:2 with histeps lw 2 title "%s"' % (fname, model))
        b.plot("%s_edge_lengths.png" % tag,
               'set xlabel "edge length (world units)"\nset ylabel "fraction of edges"\n'
               'set title "%s: edge lengths"\nset xrange [0:%g]\nplot %s' % (figure, top * 1.05, ", ".join(plots)), data)
        self.image(os.path.join(b.out, "%s_edge_lengths.png" % tag), "edge length histograms")
        # Pictures of each mesh, coloured by edge length.
        cells = []
        for x in good:
            png = os.path.join(b.out, "%s_%s.png" % (tag, x["name"].split("_")[-1]))
            if b.render(x["mesh"], png, "%s: %s vertices" % (x["model"], fmt(x["vertices"])), ["--wire"] + list(render_extra)):
                cells.append("![%s](%s)" % (x["model"], os.path.basename(png)))
        if cells:
            self.md.append("\n| " + " | ".join(x["model"] for x in good) + " |\n|" + "---|" * len(good) + "\n| " +
                           " | ".join(cells) + " |\n")

    # 4. Peers -------------------------------------------------------------------------------------
    def peers(self):
        b = self.b
        img = b.phantom(self.size, 0.5)
        self.section("Peers on the same image: OpenVDB volumeToMesh and marching cubes",
                     "`vdb_bench mesh`: the image is smoothed with OpenVDB `tools::Filter::gaussian(width 1, 1 "
                     "iteration)` (4 passes of a 3-voxel box filter, a Gaussian of sigma ~1.6 voxels), then "
                     "meshed by `tools::volumeToMesh` at each adaptivity (quads split in two triangles) and by a "
                     "plain marching cubes (bench/vdb_bench.cpp). Same error code as `vdb2mesh --reference`.")
        if img is None:
            return
        adapt = [0, 0.5, 1] if self.q else [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
        rows = b.peers(img, "phantom", ["--adaptivity", ",".join("%g" % a for a in adapt), "--mc"], self.timeout,
                       obj_dir=os.path.join(b.work, "peers"))
        self.results["peers"] = rows
        for x in rows:  # the peer marching cubes promises a closed, oriented 2-manifold: hold it to that
            if ok(x) and x["tool"] == "marching-cubes" and x.get("closed_manifold") != 1:
                b.failures.append(("marching cubes " + x["setting"], "not a closed oriented manifold: %s open, %s bad "
                                   "edges" % (x.get("boundary_edges"), x.get("bad_edges"))))
        riemesh = self.results.get("table2", [])
        r = next((x for x in riemesh if x["model"] == "Riemannian"), None)
        vdb_rows = [x for x in rows if ok(x) and x["tool"] == "openvdb"]
        # The best adaptivity: the fewest vertices among settings at most as far from the surface as
        # the Riemannian model (the equal-error comparison); without one, the most accurate setting.
        best = None
        if vdb_rows:
            if r is not None and ok(r):
                within = [x for x in vdb_rows if x["mean_voxels"] <= r["mean"]]
                best = min(within, key=lambda x: x["vertices"]) if within else None
            if best is None:
                best = min(vdb_rows, key=lambda x: x["mean_voxels"])
        self.results["vdb_best"] = best
        allrows = rows + [dict(image="phantom", tool="riemesh", setting=x["model"], vertices=x.get("vertices"),
                               mean_voxels=x.get("mean"), hausdorff_voxels=x.get("hausdorff"),
                               surface_mean_voxels=x.get("surface_mean"),
                               components=x.get("components"), genus=x.get("genus"), closed_manifold=1,
                               seconds=x.get("seconds"), status=x["status"]) for x in riemesh]
        b.write_csv("peers_phantom.csv", allrows, ["tool", "setting", "status", "vertices", "triangles", "mean_voxels",
                                                    "surface_mean_voxels", "hausdorff_voxels", "components", "genus",
                                                    "closed_manifold", "seconds", "smooth_seconds"])
        self.md.append(table([
            ("tool", lambda x: x["tool"]), ("setting", lambda x: x.get("setting", "")),
            ("vertices", lambda x: fmt(x.get("vertices"))), ("mean err (vox)", lambda x: fmt(x.get("mean_voxels"))),
            ("true->mesh mean (vox)", lambda x: fmt(x.get("surface_mean_voxels"))),
            ("Hausdorff (vox)", lambda x: fmt_hausdorff(x.get("hausdorff_voxels"))), ("topology", topo_text),
            ("seconds", lambda x: fmt(x.get("seconds"))), ("status", lambda x: x["status"])], allrows))
        if best is not None:
            self.md.append("\nBest volumeToMesh setting for this image: %s (%s vertices, mean error %s): the fewest "
                           "vertices among settings at most as far from the surface as the Riemannian model, or the "
                           "most accurate setting when none is.\n" % (best["setting"], fmt(best["vertices"]),
                                                                     fmt(best["mean_voxels"])))
        # Pareto plot: vertices (log x) against mean error.
        def vdb_label(x):  # a few labels only: neighbouring adaptivities overlap
            a = x["setting"].split("a=")[-1]
            return a if a in ("0.00", "0.10", "0.50", "0.90", "1.00") else '""'
        short = {"coarse Euclidean": "CE", "Riemannian": "R", "fine Euclidean": "FE"}
        data = {"pareto_vdb.dat": "".join("%d %.5g %s\n" % (x["vertices"], x["mean_voxels"], vdb_label(x))
                                          for x in vdb_rows),
                "pareto_mc.dat": "".join("%d %.5g\n" % (x["vertices"], x["mean_voxels"])
                                         for x in rows if ok(x) and x["tool"] == "marching-cubes"),
                "pareto_riemesh.dat": "".join('%d %.5g "%s"\n' % (x["vertices"], x["mean"], short.get(x["model"], x["model"]))
                                              for x in riemesh if ok(x) and "mean" in x)}
        b.plot("pareto_phantom.png",
               'set logscale x\nset xlabel "vertices"\nset ylabel "mean distance to the true surface (voxels)"\n'
               'set title "Phantom (noise 0.5): vertices against error (lower left is better)"\n'
               "set key bottom right\nset yrange [0:*]\n"
               'plot "pareto_vdb.dat" using 1:2 with linespoints pt 7 lw 2 title "OpenVDB volumeToMesh (labels: adaptivity)", '
               '"pareto_vdb.dat" using 1:2:3 with labels offset 0,1 notitle, '
               '"pareto_mc.dat" using 1:2 with points pt 5 ps 2 title "marching cubes", '
               '"pareto_riemesh.dat" using 1:2 with points pt 9 ps 2.5 lc rgb "red" title "riemesh (CE coarse Euclidean, R Riemannian, FE fine Euclidean)", '
               '"pareto_riemesh.dat" using 1:2:3 with labels left offset 1.2,0 tc rgb "red" notitle', data)
        self.image(os.path.join(b.out, "pareto_phantom.png"), "Pareto plot")
        pics = []
        for x in ([best] if best else []) + [x for x in rows if ok(x) and x["tool"] == "marching-cubes"]:
            name = "%s_%s" % (x["tool"], x["setting"])
            name = "".join(c if c.isalnum() or c in ".-" else "_" for c in name)
            obj = os.path.join(b.work, "peers", name + ".obj")
            png = os.path.join(b.out, "peer_%s.png" % x["tool"])
            if os.path.exists(obj) and b.render(obj, png, "%s %s: %s vertices" % (x["tool"], x["setting"], fmt(x["vertices"])),
                                                ["--wire", "--clip", "y:%g" % (0.5 * (self.size - 1))]):
                pics.append(("%s %s" % (x["tool"], x["setting"]), os.path.basename(png)))
        if pics:
            self.md.append("\n| " + " | ".join(p[0] for p in pics) + " |\n|" + "---|" * len(pics) + "\n| " +
                           " | ".join("![%s](%s)" % p for p in pics) + " |\n")

    # 4b. Sharp features: riemesh, volumeToMesh and CGAL Mesh_3 side by side (issue 16) -------------
    def cgal_run(self, img, tag, gaussian, d, runs):
        """One cgal_bench run at facet distance d (voxels), cached in `runs` by d; returns its row."""
        key = round(d, 4)
        if key not in runs:
            b = self.b
            ply = os.path.join(b.work, "sharp_%s_cgal_d%g.ply" % (tag, key))
            okr, out, _, why = b.run("cgal_bench %s d=%g" % (tag, key),
                                     [b.tool("cgal_bench"), img, "--grid", "density", "--gaussian", gaussian,
                                      "--facet-distance", "%g" % key, "--reference", img + ":sdf", "--out", ply,
                                      "--label", tag], self.timeout)
            rows = parse_csv(out) if okr else []
            row = rows[0] if rows else {"setting": "d=%g" % key, "status": why or "no output"}
            row.update(status="ok" if rows else row["status"], d=key, mesh=ply)
            runs[key] = row
        return runs[key]

    def cgal_match(self, img, tag, gaussian, target, runs):
        """CGAL's facet distance whose vertex count is within 10% of `target`: a secant search on
        log(vertices) against log(distance), kept inside the bracket found so far (at most 7 runs).
        Returns the closest run (its status says why when none succeeded)."""
        d, slope, prev = 0.5, 1.0, None
        lo = hi = None  # distances known to give too many / too few vertices
        for _ in range(4 if self.q else 7):
            x = self.cgal_run(img, tag, gaussian, d, runs)
            if not ok(x) or not x.get("vertices"):
                break
            v = x["vertices"]
            if abs(v / target - 1) <= 0.1:
                break
            if v > target:
                lo = d if lo is None else max(lo, d)
            else:
                hi = d if hi is None else min(hi, d)
            if prev and prev[0] != d and prev[1] != v:
                slope = min(3.0, max(0.3, -math.log(v / prev[1]) / math.log(d / prev[0])))
            prev = (d, v)
            nd = min(8.0, max(0.02, d * (v / target) ** (1.0 / slope)))
            if lo is not None and hi is not None and not lo < nd < hi:
                nd = math.sqrt(lo * hi)
            if round(nd, 4) == round(d, 4):
                break
            d = nd
        good = [x for x in runs.values() if ok(x) and x.get("vertices")]
        if not good:
            return next(iter(runs.values()), {"status": "no run"})
        return min(good, key=lambda x: abs(x["vertices"] / target - 1))

    def sharp(self):
        b = self.b
        images = [("cube-cavity", 0.5, 1)] if self.q else (
            [("cube-cavity", 0.5, s) for s in (1, 2, 3)] + [("thin-plate", 0.5, s) for s in (1, 2, 3)] +
            [("cube-cavity", 0.8, 1)])
        smoothings = ["1:1"] if self.q else ["1:1", "2:1"]
        adapt = [0, 0.5, 1] if self.q else [0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]
        fine = [0.2] if self.q else [0.2, 0.1, 0.05]
        have_cgal = os.access(b.tool("cgal_bench"), os.X_OK)
        self.section("Sharp features: riemesh, volumeToMesh and CGAL Mesh_3 on the same images",
                     "Issue 16's side by side: the same images (`vdbphantom SHAPE --size %d --noise N --seed S`), every "
                     "mesh measured by the same code (vdb/level_set.h `surfaceError`, as `vdb2mesh --reference`: "
                     "mesh->true mean over ~4 samples per square voxel of the mesh, true->mesh mean from samples of the "
                     "true surface, its edges and corners included, Hausdorff = the larger of the two maxima; voxels). "
                     "**riemesh**: `vdb2mesh` defaults (creases and corners put back on the converged surface where "
                     "the filtered face normals and the image both show one); **riemesh --no-sharpen**: the same "
                     "without that; **riemesh --face-samples**: with `--face-samples` (the image force sampled at the "
                     "faces' centres as well as at the vertices, off by default). **volumeToMesh**: `vdb_bench mesh` after OpenVDB's "
                     "`tools::Filter::gaussian` (width:iterations) %s, adaptivities %s; its best setting over all of them by the peers "
                     "section's rule (the fewest vertices among settings at most as far from the surface, mesh->true, "
                     "as riemesh; else the most accurate). **CGAL Mesh_3**: `cgal_bench` (CGAL %s, "
                     "`Labeled_mesh_domain_3::create_implicit_mesh_domain` on iso - trilinear(image), facet_angle 30, "
                     "no facet_size bound, no perturbation or exudation, manifold output) on the image smoothed by the "
                     "same Gaussian as volumeToMesh's best setting (on the raw noisy image an implicit mesher makes "
                     "garbage), its facet_distance searched (secant on log vertices, at most %d runs) for a vertex "
                     "count within 10%% of riemesh's. Seconds: riemesh without its read and write (metric + evolution, "
                     "2 threads); volumeToMesh smoothing + meshing (2 threads); CGAL smoothing + meshing (the mesher "
                     "runs on one thread, CGAL's Sequential_tag); none counts reading the image. The Gaussian alone "
                     "is the smooth_seconds column of sharp_features.csv." % (
                         self.size, " and ".join(smoothings),
                         ", ".join("%g" % a for a in adapt), "5.5 (Debian libcgal-dev)", 4 if self.q else 7))
        if not have_cgal:
            self.md.append("**CGAL Mesh_3 not measured**: `cgal_bench` is not in %s (it is built only where CGAL is "
                           "installed: Debian libcgal-dev, which scripts/setup installs).\n" % b.bin)
        rows, extra, corner = [], [], {}  # corner: label -> method -> row, for the pictured images
        analytic = set()
        for shape, noise, seed in images:
            tag = "%s_n%g_s%d" % ("cube" if shape == "cube-cavity" else "plate", noise, seed)
            label = "%s, noise %g, seed %d" % (shape, noise, seed)
            img = b.phantom(self.size, noise, seed=seed, shape=shape)
            if img is None:
                rows.append(dict(image=label, method="(phantom)", status=b.failures[-1][1]))
                continue
            r = b.vdb2mesh("sharp_%s_R" % tag, img, [], self.timeout)
            if ok(r):
                with open(r["stats"]) as f:
                    analytic.add(bool(json.load(f).get("reference", {}).get("analytic")))
            rrow = dict(image=label, method="riemesh", setting="vdb2mesh defaults", vertices=r.get("vertices"),
                        mean_voxels=r.get("mean"), surface_mean_voxels=r.get("surface_mean"),
                        hausdorff_voxels=r.get("hausdorff"), components=r.get("components"), genus=r.get("genus"),
                        closed_manifold=1, status=r["status"], mesh=r["mesh"],
                        seconds=(r["seconds"] - r.get("read_seconds", 0.0) - r.get("write_seconds", 0.0))
                        if ok(r) else None)
            rows.append(rrow)
            # The same without the sharpening (--no-sharpen), and with the option that is off by default
            # (--face-samples: the image force sampled at the faces' centres too).
            for method, flags, suffix in SHARP_VARIANTS:
                rs = b.vdb2mesh("sharp_%s_%s" % (tag, suffix), img, flags, self.timeout)
                rows.append(dict(image=label, method=method, setting="vdb2mesh " + " ".join(flags),
                                 vertices=rs.get("vertices"), mean_voxels=rs.get("mean"),
                                 surface_mean_voxels=rs.get("surface_mean"), hausdorff_voxels=rs.get("hausdorff"),
                                 components=rs.get("components"), genus=rs.get("genus"), closed_manifold=1,
                                 status=rs["status"], mesh=rs["mesh"],
                                 seconds=(rs["seconds"] - rs.get("read_seconds", 0.0) - rs.get("write_seconds", 0.0))
                                 if ok(rs) else None))
            # Mesh files only for the image pictured (vdb_bench writes no file for an empty mesh, and the thin
            # plate smoothed at width 2 has no voxel left above the iso value).
            pictured = (shape, noise, seed) in (images[0], ("thin-plate", 0.5, 1))
            obj_dir = os.path.join(b.work, "sharp_" + tag)
            peers = []
            for g in smoothings:
                peers += b.peers(img, tag, ["--gaussian", g, "--adaptivity", ",".join("%g" % a for a in adapt)],
                                 self.timeout, obj_dir=obj_dir if pictured else None)
            # An empty mesh (the smoothing erased the object) measures 0 one way: not a candidate.
            vdb_rows = [x for x in peers if ok(x) and x.get("tool") == "openvdb" and x.get("vertices")]
            best = None
            if vdb_rows:
                within = [x for x in vdb_rows if ok(r) and x["mean_voxels"] <= r["mean"]]
                best = (min(within, key=lambda x: x["vertices"]) if within
                        else min(vdb_rows, key=lambda x: x["mean_voxels"]))
                name = "".join(c if c.isalnum() or c in ".-" else "_" for c in "openvdb_" + best["setting"])
                rows.append(dict(best, image=label, method="volumeToMesh", mesh=os.path.join(obj_dir, name + ".obj")))
                if ok(r):
                    near = min(vdb_rows, key=lambda x: abs(x["vertices"] / r["vertices"] - 1))
                    extra.append(dict(near, image=label, method="volumeToMesh, nearest vertex count"))
            else:
                rows.append(dict(image=label, method="volumeToMesh", status=next(
                    (x["status"] for x in peers if not ok(x)), "no run")))
            if have_cgal:
                gaussian = best["setting"].split()[1] if best and best["setting"].startswith("gauss ") else "1:1"
                runs = {}
                if ok(r) and r.get("vertices"):
                    m = self.cgal_match(img, tag, gaussian, r["vertices"], runs)
                    within = ok(m) and abs(m["vertices"] / r["vertices"] - 1) <= 0.1
                    rows.append(dict(m, image=label, method="CGAL Mesh_3" if within or not ok(m) else
                                     "CGAL Mesh_3 (closest count: not within 10%)"))
                else:
                    rows.append(dict(image=label, method="CGAL Mesh_3", status="no riemesh count to match"))
                for d in fine:
                    self.cgal_run(img, tag, gaussian, d, runs)
                good = [x for x in runs.values() if ok(x) and "mean_voxels" in x]
                if good:
                    acc = min(good, key=lambda x: x["mean_voxels"] + x["surface_mean_voxels"])
                    extra.append(dict(acc, image=label, method="CGAL Mesh_3, most accurate of %d runs" % len(runs)))
            if pictured:
                corner[label] = {x["method"]: x for x in rows if x.get("image") == label}
        self.results["sharp"] = rows
        cols = ["image", "method", "setting", "status", "vertices", "mean_voxels", "surface_mean_voxels",
                "hausdorff_voxels", "components", "genus", "closed_manifold", "seconds", "smooth_seconds"]
        b.write_csv("sharp_features.csv", rows + extra, cols)
        if analytic == {False}:
            self.md.append("Reference distance in this run: the phantom's sdf **grid**, interpolated trilinearly, not "
                           "its analytic distance (`vdb2mesh --stats` says analytic: false: the grid's phantom metadata "
                           "did not reach the measure), so the true surface's corners are rounded by ~0.5 voxel in the "
                           "measure; the three methods are measured the same way.\n")
        elif analytic == {True}:
            self.md.append("Reference distance: the phantoms' analytic distance, exact at edges and corners.\n")
        columns = [("image", lambda x: x["image"]), ("method", lambda x: x["method"]),
                   ("setting", lambda x: x.get("setting", "")), ("vertices", lambda x: fmt(x.get("vertices"))),
                   ("mesh->true mean", lambda x: fmt(x.get("mean_voxels"))),
                   ("true->mesh mean", lambda x: fmt(x.get("surface_mean_voxels"))),
                   ("Hausdorff", lambda x: fmt_hausdorff(x.get("hausdorff_voxels"))), ("topology", topo_text),
                   ("seconds", lambda x: fmt(x.get("seconds"))), ("status", lambda x: x.get("status", ""))]
        self.md.append(table(columns, rows))
        if extra:
            self.md.append("\nOther settings of the peers on the same images: volumeToMesh at the adaptivity whose vertex "
                           "count is nearest riemesh's, and CGAL at its most accurate facet distance (lowest sum of the "
                           "two means) among the matching runs and d = %s:\n" % ", ".join("%g" % d for d in fine))
            self.md.append(table(columns, extra))
        # Means over the seeds, per shape and noise.
        groups = []
        for shape, noise, _ in images:
            if (shape, noise) not in groups:
                groups.append((shape, noise))
        summary = []
        for shape, noise in groups:
            for method in SHARP_METHODS:
                xs = [x for x in rows if ok(x) and x["image"].startswith("%s, noise %g," % (shape, noise))
                      and x["method"].split(" (")[0] == method and x.get("hausdorff_voxels") is not None]
                if not xs:
                    continue
                avg = lambda k: sum(x[k] for x in xs) / len(xs)
                summary.append(dict(image="%s, noise %g (%d seed%s)" % (shape, noise, len(xs), "" if len(xs) == 1 else "s"),
                                    method=method, vertices=avg("vertices"), mean=avg("mean_voxels"),
                                    surface=avg("surface_mean_voxels"), hmax=max(x["hausdorff_voxels"] for x in xs),
                                    topo=sum(topology_ok(x) for x in xs), n=len(xs), seconds=avg("seconds")))
        if summary:
            self.md.append("\nMeans over the seeds (Hausdorff: the worst seed):\n")
            self.md.append(table([
                ("images", lambda x: x["image"]), ("method", lambda x: x["method"]),
                ("vertices", lambda x: fmt(x["vertices"])), ("mesh->true mean", lambda x: fmt(x["mean"])),
                ("true->mesh mean", lambda x: fmt(x["surface"])), ("worst Hausdorff", lambda x: fmt_hausdorff(x["hmax"])),
                ("one comp., genus 0", lambda x: "%d of %d" % (x["topo"], x["n"])),
                ("seconds", lambda x: fmt(x["seconds"]))], summary))
        # The issue's targets, from these numbers.
        lines = ["\nIssue 16's targets on these images (riemesh's targets, at its defaults; its options and the peers' "
                 "numbers beside them):\n"]
        def target_line(what, pick, key, limit):
            per = {}
            for x in rows:
                if pick(x) and ok(x) and x.get(key) is not None:
                    per.setdefault(x["method"].split(" (")[0], []).append(x[key])
            if not per:
                return "- %s: **not measured**." % what
            parts = []
            for method in SHARP_METHODS:
                v = per.get(method)
                if v:
                    met = sum(1 for y in v if y <= limit)
                    parts.append("%s %d of %d (worst %s)" % (method, met, len(v), fmt(max(v))))
            rv = per.get("riemesh")
            verdict_text = ("**not measured**" if not rv else "**met**" if max(rv) <= limit else
                            "**missed** on %d of %d images" % (sum(1 for y in rv if y > limit), len(rv)))
            return "- %s: riemesh %s. Images within it: %s." % (what, verdict_text, "; ".join(parts))
        lines.append(target_line("Hausdorff <= 1.5 voxels at noise 0.5", lambda x: ", noise 0.5," in x["image"],
                                 "hausdorff_voxels", 1.5))
        if any(n == 0.8 for _, n, _ in images):
            lines.append(target_line("Hausdorff <= 2.5 voxels at noise 0.8", lambda x: ", noise 0.8," in x["image"],
                                     "hausdorff_voxels", 2.5))
        lines.append(target_line("true->mesh mean <= 0.2 voxel", lambda x: True, "surface_mean_voxels", 0.2))
        self.md.append("\n".join(lines) + "\n")
        if not self.q:
            self.sharp_held_out()
        # One picture of each method on the first cube and the first plate (seen from a corner).
        for k, (label, methods) in enumerate(corner.items()):
            pics = []
            for method in SHARP_METHODS:
                x = next((y for m, y in methods.items() if m.split(" (")[0] == method), None)
                if not x or not ok(x) or not os.path.exists(x.get("mesh", "")):
                    continue
                png = os.path.join(b.out, "sharp_%s%s.png" % ("" if k == 0 else "plate_",
                                                              method.replace(" --", "_").split()[0].lower()))
                if b.render(x["mesh"], png, "%s: %s vertices" % (method, fmt(x["vertices"])), ["--wire", "--view", "iso"]):
                    pics.append((method, os.path.basename(png)))
            if pics:
                self.md.append("\n%s, seen from a corner (edges coloured by length):\n\n| %s |\n|%s\n| %s |\n" % (
                    label, " | ".join(p[0] for p in pics), "---|" * len(pics),
                    " | ".join("![%s](%s)" % p for p in pics)))

    def sharp_held_out(self):
        """riemesh with and without its sharpening on seeds (4-9) and a shape (notched-block: concave
        edges) the sharpening was not tuned on."""
        b = self.b
        rows = []
        for shape, seeds in (("cube-cavity", range(4, 10)), ("thin-plate", range(4, 10)), ("notched-block", range(1, 4))):
            for seed in seeds:
                tag = "%s_n0.5_s%d" % (shape.split("-")[0], seed)
                img = b.phantom(self.size, 0.5, seed=seed, shape=shape)
                if img is None:
                    continue
                for method, flags, suffix in (("riemesh", [], "R"), ("riemesh --no-sharpen", ["--no-sharpen"], "N")):
                    r = b.vdb2mesh("held_%s_%s" % (tag, suffix), img, flags, self.timeout)
                    rows.append(dict(image="%s, noise 0.5, seed %d" % (shape, seed), method=method,
                                     vertices=r.get("vertices"), mean_voxels=r.get("mean"),
                                     surface_mean_voxels=r.get("surface_mean"), hausdorff_voxels=r.get("hausdorff"),
                                     components=r.get("components"), genus=r.get("genus"), closed_manifold=1,
                                     status=r["status"]))
        b.write_csv("sharp_held_out.csv", rows, ["image", "method", "status", "vertices", "mean_voxels",
                                                 "surface_mean_voxels", "hausdorff_voxels", "components", "genus"])
        good = [x for x in rows if ok(x) and x["method"] == "riemesh" and x.get("hausdorff_voxels") is not None]
        within = sum(1 for x in good if x["hausdorff_voxels"] <= 1.5)
        self.md.append("\nThe same measure on seeds 4-9 and on a shape with concave edges (`vdbphantom notched-block`, "
                       "seeds 1-3): the sharpening's settings were chosen on seeds 1-3 of the images above. riemesh's "
                       "Hausdorff <= 1.5 voxels on %d of %d images (worst %s), true->mesh mean <= 0.2 on %d of %d.\n" % (
                           within, len(good), fmt(max((x["hausdorff_voxels"] for x in good), default=None)),
                           sum(1 for x in good if x["surface_mean_voxels"] <= 0.2), len(good)))
        self.md.append(table([
            ("image", lambda x: x["image"]), ("method", lambda x: x["method"]),
            ("vertices", lambda x: fmt(x.get("vertices"))), ("mesh->true mean", lambda x: fmt(x.get("mean_voxels"))),
            ("true->mesh mean", lambda x: fmt(x.get("surface_mean_voxels"))),
            ("Hausdorff", lambda x: fmt_hausdorff(x.get("hausdorff_voxels"))), ("topology", topo_text),
            ("status", lambda x: x.get("status", ""))], rows))

    # 5. Noise sweep -------------------------------------------------------------------------------
    def noise(self):
        b = self.b
        levels = [0, 1.0] if self.q else [0, 0.25, 0.5, 0.75, 1.0]
        self.section("Noise sweep: who keeps the topology",
                     "The phantom (%d^3) at each noise level (seed 1). Right topology = one closed 2-manifold "
                     "component of genus 0. riemesh at its defaults; OpenVDB and marching cubes after the same "
                     "Gaussian smoothing as above (width 1, and width 2 = sigma ~2.8 voxels)." % self.size)
        rows = []
        for n in levels:
            img = b.phantom(self.size, n)
            if img is None:
                rows.append({"noise": n, "tool": "phantom", "setting": "", "status": b.failures[-1][1]})
                continue
            r = b.vdb2mesh("noise_%g_R" % n, img, ["--delta", "%g" % (3 * self.scale)], self.timeout)
            rows.append(dict(noise=n, tool="riemesh", setting="Riemannian", vertices=r.get("vertices"),
                             mean_voxels=r.get("mean"), hausdorff_voxels=r.get("hausdorff"),
                             surface_mean_voxels=r.get("surface_mean"),
                             components=r.get("components"), genus=r.get("genus"), closed_manifold=1,
                             seconds=r.get("seconds"), status=r["status"]))
            for g in (["1:1"] if self.q else ["1:1", "2:1"]):
                for x in b.peers(img, "noise %g" % n, ["--gaussian", g, "--adaptivity", "0,0.5", "--mc"], self.timeout):
                    x["noise"] = n
                    rows.append(x)
        self.results["noise"] = rows
        b.write_csv("noise_sweep.csv", rows, ["noise", "tool", "setting", "status", "vertices", "mean_voxels",
                                               "hausdorff_voxels", "components", "genus", "closed_manifold", "seconds"])
        tools = []
        for x in rows:
            key = (x["tool"], x.get("setting", ""))
            if key not in tools and x["tool"] != "phantom":
                tools.append(key)
        lines = ["| tool | " + " | ".join("noise %g" % n for n in levels) + " |", "|---|" + "---|" * len(levels)]
        for t in tools:
            cells = []
            for n in levels:
                x = next((y for y in rows if y.get("noise") == n and (y["tool"], y.get("setting", "")) == t), None)
                if x is None or not ok(x):
                    cells.append("failed" if x else "–")
                else:
                    mark = "yes" if topology_ok(x) else "**no**"
                    cells.append("%s: %s comp., g %s; %s vert., err %s" % (
                        mark, fmt(x.get("components")), fmt(x.get("genus")), fmt(x.get("vertices")),
                        fmt(x.get("mean_voxels"))))
            lines.append("| %s %s | %s |" % (t[0], t[1], " | ".join(cells)))
        self.md.append("\n".join(lines) + "\n")

    # 3. Resolution sweep --------------------------------------------------------------------------
    def resolution(self):
        b = self.b
        sizes = [40, 48] if self.q else [100, 200, 300]
        p5 = self.results.get("deltas", {"fine": 1.5 * self.scale})["fine"] / self.scale  # at 100^3
        self.section("Resolution sweep",
                     "The phantom (noise 0.5, seed 1) at several box sizes. vdbphantom keeps voxels of one world "
                     "unit and scales the object with the box (cube half-size 0.3 N), so the same physical "
                     "target is delta x N/100 voxels: Riemannian 3 x N/100, fine Euclidean %s x N/100 (the "
                     "shortest Riemannian edge above). Errors are given in voxels of this size and in voxels of the 100^3 box "
                     "(divided by N/100)." % fmt(p5))
        rows = []
        for s in sizes:
            img = b.phantom(s, 0.5)
            k = s / 100.0
            for model, extra in (("Riemannian", ["--delta", "%.4g" % (3 * k)]),
                                 ("fine Euclidean", ["--metric", "euclidean", "--delta", "%.4g" % (p5 * k)])):
                if img is None:
                    rows.append(dict(size=s, model=model, status="no phantom"))
                    continue
                same = [y for y in self.results.get("table2", []) if y["model"] == model and ok(y)]
                if s == self.size and same:  # the run of Table 2: same image, same delta
                    x = dict(same[0])
                else:
                    x = b.vdb2mesh("res_%d_%s" % (s, model[0]), img, extra, self.timeout * (2 if s >= 300 else 1))
                x.update(size=s, model=model)
                if "mean" in x:
                    x["mean100"] = x["mean"] / k
                rows.append(x)
        self.results["resolution"] = rows
        b.write_csv("resolution_sweep.csv", rows, ["size", "model", "status", "delta", "vertices", "iterations", "stop",
                                                    "seconds", "metric_seconds", "evolve_seconds", "mean", "mean100",
                                                    "hausdorff", "components", "genus"])
        self.md.append(table([
            ("size", lambda x: "%d^3" % x["size"]), ("model", lambda x: x["model"]),
            ("delta (vox)", lambda x: fmt(x.get("delta"))), ("vertices", lambda x: fmt(x.get("vertices"))),
            ("iterations", lambda x: "%s (%s)" % (fmt(x.get("iterations")), x.get("stop", "–"))),
            ("seconds", lambda x: fmt(x.get("seconds"))), ("of which metric", lambda x: fmt(x.get("metric_seconds"))),
            ("mean err (vox)", lambda x: fmt(x.get("mean"))), ("mean err (100^3 vox)", lambda x: fmt(x.get("mean100"))),
            ("topology", topo_text), ("status", lambda x: x["status"])], rows))

    # 2. Head ----------------------------------------------------------------------------------------
    def head(self):
        b = self.b
        self.section("Table 3 and Fig. 9: the Colin27 head MRI",
                     "`%s` (Debian mricron-data, 181x217x181, 1 mm) at `--iso 40`, vdb2mesh's defaults "
                     "otherwise (closed borders). Every run is capped (--max-iterations, and a wall-clock timeout) "
                     "and reported as it ends (see the iterations and status columns). No reference surface exists: no error columns." % HEAD)
        if not os.path.exists(HEAD):
            self.md.append("Skipped: %s is missing (Debian package mricron-data).\n" % HEAD)
            b.failures.append(("head", "missing " + HEAD))
            return
        cap, timeout = "400", 480
        r = b.vdb2mesh("head_R", HEAD, ["--iso", "40", "--max-iterations", cap], timeout, reference=False)
        d = self.deltas(b.vdb2mesh("head_R_unsharpened", HEAD, ["--iso", "40", "--max-iterations", cap, "--no-sharpen"],
                                   timeout, reference=False), 1.0)
        fe = b.vdb2mesh("head_FE", HEAD, ["--iso", "40", "--metric", "euclidean", "--delta", "%.4g" % d["fine"],
                                          "--max-iterations", cap], timeout, reference=False)
        ce = b.vdb2mesh("head_CE", HEAD, ["--iso", "40", "--metric", "euclidean", "--delta", "%.4g" % d["coarse"],
                                          "--max-iterations", cap], timeout, reference=False)
        rows = [dict(ce, model="coarse Euclidean"), dict(r, model="Riemannian"), dict(fe, model="fine Euclidean")]
        peers = b.peers(HEAD, "head", ["--iso", "40", "--adaptivity", "0,0.5", "--mc"], self.timeout)
        self.results["head"] = rows
        self.results["head_peers"] = peers
        b.write_csv("table3_head.csv", rows, ["model", "status", "delta", "seconds", "metric_seconds", "evolve_seconds",
                                               "iterations", "stop", "vertices", "components", "genus"])
        b.write_csv("peers_head.csv", peers, ["tool", "setting", "status", "vertices", "triangles", "components",
                                               "genus", "closed_manifold", "seconds"])
        self.md.append(self.delta_text(d, "mm"))
        self.md.append("Iteration cap %s, timeout %d s per run.\n" % (cap, timeout))
        self.md.append(table([
            ("model", lambda x: x["model"]), ("delta (vox)", lambda x: fmt(x.get("delta"))),
            ("seconds", lambda x: fmt(x.get("seconds"))), ("of which metric", lambda x: fmt(x.get("metric_seconds"))),
            ("iterations", lambda x: "%s (%s)" % (fmt(x.get("iterations")), x.get("stop", "–"))),
            ("vertices", lambda x: fmt(x.get("vertices"))), ("components", lambda x: fmt(x.get("components"))),
            ("genus", lambda x: fmt(x.get("genus"))), ("status", lambda x: x["status"])], rows))
        self.md.append("\nPeers on the same image (same smoothing as above): \n")
        self.md.append(table([
            ("tool", lambda x: x["tool"]), ("setting", lambda x: x.get("setting", "")),
            ("vertices", lambda x: fmt(x.get("vertices"))), ("topology", topo_text),
            ("seconds", lambda x: fmt(x.get("seconds"))), ("status", lambda x: x["status"])], peers))
        self.md.append("\nThe paper (Table 3; a 148^3 head CT): coarse 13 min 23 s / 10,876 vertices, Riemannian "
                       "32 min 38 s / 19,438, fine 151 min 26 s / 68,949; metric 59 s.\n")
        self.fig5(rows, "head", "Fig. 9")

    # Intersection-free evolution ------------------------------------------------------------------------
    def guarantee(self):
        b = self.b
        # 7 rounds: with 3, one run's ratios moved by up to a tenth from the next (on 9ac7128, phantom
        # 1.17x in one and 1.34x in another, its unguarded fastest 0.140 s and 0.125 s).
        rounds = 1 if self.q else 7
        self.section("The intersection-free evolution: what the guarantee costs",
                     "`vdb2mesh --intersection-free` (continuous collision detection of every step, edits refused "
                     "where faces would cross or come within 1e-6 delta) against the same run without it, vdb2mesh's "
                     "defaults otherwise (all cores), alternating, %d round%s each: the fastest evolution of each. "
                     "The soak of random cases (`scripts/soak`) is run apart: its figures are in the closing notes."
                     % (rounds, "" if rounds == 1 else "s"))
        images = [("phantom %d^3" % self.size, b.phantom(self.size, 0.5), [])]
        if not self.q and os.path.exists(HEAD):
            images.append(("head MRI", HEAD, ["--iso", "40"]))
        rows = []
        for label, img, extra in images:
            if img is None:
                continue
            best = {}
            offRuns = []  # every unguarded evolve time (the issue 15 evolve figure takes the fastest)
            for r in range(rounds):
                for guard in (False, True):
                    name = "guard_%s_%s_%d" % (label.split()[0], "on" if guard else "off", r)
                    x = b.vdb2mesh(name, img, extra + (["--intersection-free"] if guard else []), self.timeout,
                                   reference=False)
                    if not ok(x):
                        continue
                    with open(x["stats"]) as f:
                        x["self_intersections"] = json.load(f)["summary"].get("self_intersections")
                    if not guard:
                        offRuns.append(x["evolve_seconds"])
                    if guard not in best or x["evolve_seconds"] < best[guard]["evolve_seconds"]:
                        best[guard] = x
            if False in best and True in best:
                off, on = best[False], best[True]
                row = dict(image=label, off=off["evolve_seconds"], on=on["evolve_seconds"], off_runs=offRuns,
                           ratio=on["evolve_seconds"] / max(off["evolve_seconds"], 1e-9),
                           vertices="%s / %s" % (fmt(off["vertices"]), fmt(on["vertices"])),
                           iterations="%s / %s" % (fmt(off["iterations"]), fmt(on["iterations"])),
                           crossings="%s / %s" % (fmt(off["self_intersections"]), fmt(on["self_intersections"])))
                # The phantom's evolution in instructions too (one thread, under callgrind: the machine's
                # load does not move them; the head would take minutes).
                if label.startswith("phantom") and shutil.which("valgrind"):
                    counts = [self.step_instructions(img, extra + (["--intersection-free"] if guard else []))
                              for guard in (False, True)]
                    if None not in counts:
                        row.update(ins_off=counts[0], ins_on=counts[1], ins_ratio=counts[1] / max(counts[0], 1))
                rows.append(row)
        self.results["guarantee"] = rows
        b.write_csv("guarantee.csv", rows, ["image", "off", "on", "ratio", "vertices", "iterations", "crossings",
                                            "ins_off", "ins_on", "ins_ratio"])
        self.md.append(table([
            ("image", lambda x: x["image"]), ("evolve without (s)", lambda x: fmt(x["off"])),
            ("evolve with (s)", lambda x: fmt(x["on"])), ("ratio", lambda x: "%.2fx" % x["ratio"]),
            ("instructions without / with (one thread)", lambda x: "%s / %s = %.2fx" % (
                fmt(x["ins_off"]), fmt(x["ins_on"]), x["ins_ratio"]) if "ins_ratio" in x else "not measured"),
            ("vertices without / with", lambda x: x["vertices"]), ("iterations", lambda x: x["iterations"]),
            ("crossing face pairs", lambda x: x["crossings"])], rows))

    def step_instructions(self, image, extra):
        """Instructions of vdb2mesh's evolution steps (riemesh::Evolution::step) on one thread, under
        callgrind, sharpening off; None if the run fails."""
        b = self.b
        out = os.path.join(b.work, "guard_callgrind.out")
        cmd = ["valgrind", "--tool=callgrind", "--toggle-collect=riemesh::Evolution::step()",
               "--callgrind-out-file=" + out, b.tool("vdb2mesh"), image, os.path.join(b.work, "guard_callgrind.obj"),
               "-q", "--threads", "1", "--no-sharpen"] + extra
        okr, _, _, _ = b.run("callgrind vdb2mesh " + " ".join(extra), cmd, self.timeout)
        if not okr or not os.path.exists(out):
            return None
        with open(out) as f:
            for line in f:
                if line.startswith("totals:") or line.startswith("summary:"):
                    return int(line.split()[1])
        return None

    # Metric cost --------------------------------------------------------------------------------------
    def metric(self):
        b = self.b
        sizes = [40, 64] if self.q else [100, 200, 300]
        self.section("Structure tensor and metric: cost against image size, 1 and 2 threads",
                     "`vdb_bench metric`: `riemesh::vdb::computeMetric` (vdb2mesh's defaults: sigma 1, rho 2, "
                     "mu_max 9) on the phantom's density grid, fastest of %d runs." % (1 if self.q else 2))
        rows = []
        for s in sizes:
            img = b.phantom(s, 0.5)
            row = {"size": s}
            for t in (1, 2):
                if img is None:
                    continue
                okr, out, _, why = b.run("metric %d threads %d" % (s, t),
                                         [b.tool("vdb_bench"), "metric", img, "--grid", "density", "--threads", str(t),
                                          "--repeat", "1" if self.q else "2"], self.timeout)
                parsed = parse_csv(out) if okr else []
                if parsed:
                    row["voxels"] = parsed[0]["voxels"]
                    row["t%d" % t] = parsed[0]["seconds"]
                    row["cpu%d" % t] = parsed[0]["cpu_seconds"]
                else:
                    row["status"] = why
            if "t1" in row and "t2" in row:
                row["speedup"] = row["t1"] / row["t2"]
                row["cores2"] = row["cpu2"] / row["t2"]  # cores the 2-thread run actually got
                row["ns_per_voxel"] = 1e9 * row["t1"] / row["voxels"]
            rows.append(row)
        b.write_csv("metric_cost.csv", rows, ["size", "voxels", "t1", "cpu1", "t2", "cpu2", "speedup", "cores2",
                                               "ns_per_voxel", "status"])
        self.md.append(table([
            ("image", lambda x: "%d^3" % x["size"]), ("voxels", lambda x: fmt(x.get("voxels"))),
            ("1 thread (s)", lambda x: fmt(x.get("t1"))), ("2 threads (s)", lambda x: fmt(x.get("t2"))),
            ("speed-up", lambda x: fmt(x.get("speedup"))),
            ("cores used by 2 threads (CPU s / s)", lambda x: fmt(x.get("cores2"))),
            ("ns/voxel (1 thread)", lambda x: fmt(x.get("ns_per_voxel"))),
            ("status", lambda x: x.get("status", "ok"))], rows))
        starved = [x for x in rows if "cores2" in x and x["cores2"] < 1.5]
        if starved:
            self.md.append("\nIn this run the 2-thread runs got %s cores on average (processor seconds per second): "
                           "the machine was busy, so the speed-up says little about the code.\n" % fmt(
                               sum(x["cores2"] for x in starved) / len(starved)))
        data = {"metric.dat": "".join("%d %s %s\n" % (x["voxels"], x["t1"], x["t2"]) for x in rows if "speedup" in x)}
        if data["metric.dat"]:
            b.plot("metric_cost.png", 'set logscale xy\nset xlabel "voxels"\nset ylabel "seconds"\nset key top left\n'
                   'set title "Structure tensor + metric"\n'
                   'plot "metric.dat" using 1:2 with linespoints pt 7 lw 2 title "1 thread", '
                   '"metric.dat" using 1:3 with linespoints pt 5 lw 2 title "2 threads"', data)
            self.image(os.path.join(b.out, "metric_cost.png"), "metric cost")

    # Scale: riemesh and the OpenVDB user's pipeline on growing dense and sparse inputs ---------------
    def timed(self, what, cmd):
        """Runs cmd under /usr/bin/time; returns (ok, stdout, wall seconds, peak KB, why)."""
        b = self.b
        out = os.path.join(b.work, "time.txt")
        if os.path.exists(out):
            os.remove(out)
        okr, stdout, secs, why = b.run(what, ["/usr/bin/time", "-f", "%e %M", "-o", out] + cmd, self.timeout)
        peak = None
        if os.path.exists(out):
            last = open(out).read().strip().splitlines()
            if last:
                try:
                    peak = int(last[-1].split()[-1])
                except ValueError:
                    pass
        return okr, stdout, secs, peak, why

    def growth(self):
        b = self.b
        here = os.path.dirname(os.path.abspath(__file__))
        peer = os.path.join(here, "peer_pipeline.py")
        tools = os.path.join(here, "sphere_tools.py")
        phantoms = [40, 64] if self.q else [100, 200, 300, 400]
        radii = [20, 30] if self.q else [60, 125, 250, 500]
        self.section("Scale: time and peak memory against the input's size, riemesh and the peer",
                     "Each input meshed by `vdb2mesh` with its defaults, and by the pipeline an OpenVDB user runs "
                     "today in one Python process (`bench/peer_pipeline.py`: pyopenvdb read, for fog volumes scipy "
                     "Gaussian smoothing sigma 1.5 over the active box, volumeToMesh adaptivity 0.5, PLY write). Wall "
                     "time and peak memory of the whole process (`/usr/bin/time -f %M`), one run each, in this same run "
                     "(ratios = riemesh / peer). Inputs: the paper's phantom (`vdbphantom cube-cavity --noise 0.5`, a "
                     "dense fog volume of N^3 voxels) and level-set spheres (`pyopenvdb.createLevelSetSphere(radius=r, "
                     "voxelSize=1, halfWidth=3)`: sparse, a narrow band in a (2r+5)^3 box). Sphere error: two-sided, "
                     "in voxels (`bench/sphere_tools.py error`: mesh to sphere over 45 samples per triangle, sphere to "
                     "mesh over 20,000 rays).")
        inputs = []
        for n in phantoms:
            img = b.phantom(n, 0.5)
            inputs.append({"kind": "phantom", "size": n, "label": "phantom %d^3" % n, "image": img,
                           "voxels": n ** 3, "box_voxels": n ** 3, "grid": "density"})
        for r in radii:
            path = os.path.join(b.work, "sphere_r%d.vdb" % r)
            okr, out, _, why = b.run("sphere r=%d" % r, ["/usr/bin/python3", tools, "make", str(r), path], self.timeout)
            row = {"kind": "sphere", "size": r, "label": "sphere r=%d" % r, "image": path if okr else None,
                   "grid": "ls"}
            if okr:
                row.update(json.loads(out.strip().splitlines()[-1]))
                row["voxels"] = row["active_voxels"]
            inputs.append(row)
        rows = []
        for x in inputs:
            row = {k: x.get(k) for k in ("kind", "size", "label", "voxels", "box_voxels")}
            rows.append(row)
            if not x.get("image"):
                row["status"] = "input not made"
                continue
            ext = ".obj" if x["kind"] == "sphere" else ".ply"
            mesh = os.path.join(b.work, "scale_%s_%d%s" % (x["kind"], x["size"], ext))
            stats = os.path.join(b.work, "scale_%s_%d.json" % (x["kind"], x["size"]))
            okr, _, secs, peak, why = self.timed("scale riemesh " + x["label"],
                                                 [b.tool("vdb2mesh"), x["image"], mesh, "--grid", x["grid"], "-q",
                                                  "--stats", stats])
            if okr:
                with open(stats) as f:
                    j = json.load(f)
                sm = j["summary"]
                row.update(wall=secs, peak_mb=peak / 1024.0 if peak else None, vertices=sm["vertices"],
                           components=sm["components"], genus=sm["genus"], iterations=sm["iterations"],
                           levels=j["parameters"].get("levels"), read=sm.get("read_seconds"),
                           volume=sm.get("metric_seconds"), evolve=sm.get("evolve_seconds"))
                if x["kind"] == "sphere":
                    oke, out, _, whye = b.run("sphere error r=%d" % x["size"],
                                              ["/usr/bin/python3", tools, "error", mesh, str(x["size"])], self.timeout)
                    if oke:
                        e = json.loads(out.strip().splitlines()[-1])
                        row.update(error_mean=e["mean"], error_max=e["max"])
            else:
                row["status"] = why
            pmesh = os.path.join(b.work, "scale_peer_%s_%d.ply" % (x["kind"], x["size"]))
            okp, out, psecs, ppeak, whyp = self.timed("scale peer " + x["label"],
                                                      ["/usr/bin/python3", peer, x["image"], pmesh, "--grid", x["grid"]])
            if okp:
                pj = json.loads(out.strip().splitlines()[-1])
                row.update(peer_wall=psecs, peer_peak_mb=ppeak / 1024.0 if ppeak else None,
                           peer_vertices=pj.get("vertices"))
            else:
                row.setdefault("status", "peer: " + whyp)
            if row.get("wall") and row.get("peer_wall"):
                row["time_ratio"] = row["wall"] / row["peer_wall"]
            if row.get("peak_mb") and row.get("peer_peak_mb"):
                row["memory_ratio"] = row["peak_mb"] / row["peer_peak_mb"]
        self.results["scale"] = rows
        b.write_csv("scale.csv", rows, ["kind", "size", "voxels", "box_voxels", "wall", "peak_mb", "vertices",
                                        "components", "genus", "iterations", "levels", "read", "volume", "evolve",
                                        "error_mean", "error_max", "peer_wall", "peer_peak_mb", "peer_vertices",
                                        "time_ratio", "memory_ratio", "status"])
        self.md.append(table([
            ("input", lambda x: x["label"]), ("active voxels", lambda x: fmt(x.get("voxels"))),
            ("box voxels", lambda x: fmt(x.get("box_voxels"))),
            ("riemesh s (read / volume / evolve)", lambda x: "%s (%s / %s / %s)" % (
                fmt(x.get("wall")), fmt(x.get("read")), fmt(x.get("volume")), fmt(x.get("evolve")))
                if x.get("wall") else "-"),
            ("riemesh MB", lambda x: fmt(x.get("peak_mb"))),
            ("peer s", lambda x: fmt(x.get("peer_wall"))), ("peer MB", lambda x: fmt(x.get("peer_peak_mb"))),
            ("time ratio", lambda x: fmt(x.get("time_ratio"))), ("memory ratio", lambda x: fmt(x.get("memory_ratio"))),
            ("vertices (peer)", lambda x: "%s (%s)" % (fmt(x.get("vertices")), fmt(x.get("peer_vertices")))),
            ("components, genus", lambda x: "%s, %s" % (fmt(x.get("components")), fmt(x.get("genus")))),
            ("levels, iterations", lambda x: "%s, %s" % (fmt(x.get("levels")), fmt(x.get("iterations")))),
            ("sphere error mean / max (voxels)", lambda x: "%s / %s" % (fmt(x.get("error_mean")), fmt(x.get("error_max")))
                if "error_mean" in x else "-"),
            ("status", lambda x: x.get("status", "ok"))], rows))
        for kind in ("phantom", "sphere"):
            got = [x for x in rows if x["kind"] == kind and x.get("wall") and x.get("peer_wall")]
            if len(got) >= 2:
                f, l = got[0], got[-1]
                grow = l["voxels"] / f["voxels"]
                self.md.append("\n%s, from %s to %s (%.1fx the active voxels): riemesh time %.1fx, memory %.1fx; "
                               "the peer's time %.1fx, memory %.1fx.\n" % (
                                   kind.capitalize() + "s", f["label"], l["label"], grow, l["wall"] / f["wall"],
                                   l["peak_mb"] / f["peak_mb"], l["peer_wall"] / f["peer_wall"],
                                   l["peer_peak_mb"] / f["peer_peak_mb"]))
        # Issue 15's iterations at 400^3 over 100^3 on more than one image: the same phantom with other
        # noise seeds (the count moves with where a coarse level happens to end).
        seedRows = []
        if not self.q:
            first = {x["size"]: x.get("iterations") for x in rows if x["kind"] == "phantom"}
            for seed in range(1, 10):
                row = {"seed": seed}
                for n in (100, 400):
                    if seed == 1:
                        row["it%d" % n] = first.get(n)
                        continue
                    img = b.phantom(n, 0.5, seed)
                    x = b.vdb2mesh("iterations_s%d_seed%d" % (n, seed), img, [], self.timeout, reference=False) if img else None
                    row["it%d" % n] = x.get("iterations") if x and ok(x) else None
                if row.get("it100") and row.get("it400"):
                    row["ratio"] = row["it400"] / row["it100"]
                seedRows.append(row)
            self.results["iteration_seeds"] = seedRows
            b.write_csv("iteration_seeds.csv", seedRows, ["seed", "it100", "it400", "ratio"])
            self.md.append("\nIterations with the defaults, `vdbphantom cube-cavity --noise 0.5` with seeds 1-9 (seed 1 "
                           "is the table's):\n")
            self.md.append(table([("seed", lambda x: str(x["seed"])), ("100^3", lambda x: fmt(x.get("it100"))),
                                  ("400^3", lambda x: fmt(x.get("it400"))),
                                  ("ratio", lambda x: "%.2fx" % x["ratio"] if x.get("ratio") else "-")], seedRows))
        data = {}
        for kind in ("phantom", "sphere"):
            data["scale_%s.dat" % kind] = "".join(
                "%d %s %s %s %s\n" % (x["voxels"], x["wall"], x["peer_wall"], x["peak_mb"], x["peer_peak_mb"])
                for x in rows if x["kind"] == kind and x.get("wall") and x.get("peer_wall") and x.get("peak_mb")
                and x.get("peer_peak_mb"))
        if all(data.values()):
            for col, png, ylabel, title in ((2, "scale_time.png", "wall seconds", "Wall time"),
                                            (4, "scale_memory.png", "peak MB", "Peak memory")):
                b.plot(png, 'set logscale xy\nset xlabel "active voxels"\nset ylabel "%s"\nset key top left\n'
                       'set title "%s against the input size"\n'
                       'plot "scale_phantom.dat" using 1:%d with linespoints pt 7 lw 2 title "riemesh, phantoms", '
                       '"scale_phantom.dat" using 1:%d with linespoints pt 6 lw 2 dt 2 title "peer, phantoms", '
                       '"scale_sphere.dat" using 1:%d with linespoints pt 5 lw 2 title "riemesh, level-set spheres", '
                       '"scale_sphere.dat" using 1:%d with linespoints pt 4 lw 2 dt 2 title "peer, level-set spheres"' % (
                           ylabel, title, col, col + 1, col, col + 1), data)
                self.image(os.path.join(b.out, png), png[:-4].replace("_", " "))

    # The core's cost per iteration against the vertex count -------------------------------------
    def core(self):
        b = self.b
        self.section("The core: cost per iteration against the vertex count",
                     "`core_bench --scaling-only`: a sphere settled at about 1k, 5k, 20k and 80k vertices (ball "
                     "image, Euclidean metric) that keeps evolving; one iteration is forces, integration, "
                     "regularity, collisions and topology, on one thread. The sizes take turns (9 rounds) so that "
                     "all of them meet the same machine; each row is the median iteration. The peer is OpenMesh's "
                     "own `update_normals()` (face normals, then every vertex's one ring: a plain linear pass) on "
                     "a copy of the same mesh, timed in the same turns. `core_bench --instructions` counts the "
                     "instructions of 5 iterations of each size under callgrind (Debian valgrind), which neither "
                     "the machine's load nor its caches move.")
        okr, out, _, why = b.run("core_bench scaling", [b.tool("core_bench")] + (["--quick"] if self.q else []) +
                                 ["--scaling-only"], self.timeout)
        rows = []
        for line in out.splitlines() if okr else []:
            f = line.split()
            # target vertices ms us/vertex [growth] forces integr. regul. collis. topol. peer; "80000 as-is" too
            if len(f) >= 9 and f[0].isdigit():
                asis = f[1] == "as-is"
                f = f[2:] if asis else f[1:]
                if len(f) == 9:  # the growth column is empty on the first and the as-is rows
                    f = f[:3] + [""] + f[3:]
                if len(f) != 10:
                    continue
                rows.append({"target": int(line.split()[0]), "renumbered": 0 if asis else 1,
                             "vertices": int(f[0]), "ms": float(f[1]), "us_per_vertex": float(f[2]),
                             "growth": number(f[3]) if f[3] else "", "forces": float(f[4]), "integration": float(f[5]),
                             "regularity": float(f[6]), "collisions": float(f[7]), "topology": float(f[8]),
                             "peer_us_per_vertex": float(f[9])})
        if not rows:
            b.failures.append(("core_bench scaling", why or "no table in its output"))
        counted = {}
        if not self.q and rows:
            if shutil.which("valgrind"):
                okc, cout, _, why = b.run("core_bench instructions", [b.tool("core_bench"), "--instructions"], 1800)
                # By target: under valgrind libm may take other code paths (no FMA), and the sphere
                # settles at a slightly different count.
                for line in cout.splitlines() if okc else []:
                    f = line.split()
                    if len(f) >= 4 and f[0].isdigit() and f[1] != "as-is":
                        counted[int(f[0])] = (float(f[2]), float(f[3]))
            else:
                b.failures.append(("core_bench instructions", "valgrind not installed (scripts/setup installs it)"))
        for x in rows:
            if x["renumbered"] and x["target"] in counted:
                x["instructions"], x["instructions_per_vertex"] = counted[x["target"]]
        b.write_csv("core_scaling.csv", rows, ["target", "renumbered", "vertices", "ms", "us_per_vertex", "growth",
                                               "forces", "integration", "regularity", "collisions", "topology",
                                               "peer_us_per_vertex", "instructions", "instructions_per_vertex"])
        self.md.append(table([
            ("vertices", lambda x: fmt(x["vertices"]) + ("" if x["renumbered"] else " (not renumbered)")),
            ("ms / iteration", lambda x: fmt(x["ms"])), ("us / vertex", lambda x: fmt(x["us_per_vertex"])),
            ("growth exponent", lambda x: fmt(x["growth"]) if x["growth"] != "" else ""),
            ("forces / integration / regularity / collisions / topology (ms)",
             lambda x: " / ".join(fmt(x[k]) for k in ("forces", "integration", "regularity", "collisions", "topology"))),
            ("instructions / vertex", lambda x: fmt(x.get("instructions_per_vertex", ""))),
            ("peer: update_normals us / vertex", lambda x: fmt(x["peer_us_per_vertex"]))], rows))
        self.md.append("\nThe growth exponent is k in ms ~ vertices^k from the row above (1: linear).%s\n" % (
            " The last row is the largest mesh again without renumbering it along a space-filling curve "
            "(`EvolutionOptions::renumber`): what the renumbering buys." if any(not x["renumbered"] for x in rows) else ""))
        self.results["core"] = rows
        # Issue 15: the evolve step on 1 and on 2 threads (core_bench --parallel-only).
        okp, pout, _, pwhy = b.run("core_bench parallel", [b.tool("core_bench")] + (["--quick"] if self.q else []) +
                                   ["--parallel-only"], self.timeout)
        par = []
        for line in pout.splitlines() if okp else []:
            f = line.split()
            # target metric vertices ms1 ms2 speedup cores ...
            if len(f) >= 7 and f[0].isdigit() and f[1] in ("euclidean", "riemannian") and f[5].endswith("x"):
                row = {"target": int(f[0]), "metric": f[1], "vertices": int(f[2]), "ms1": float(f[3]),
                       "ms2": float(f[4]), "speedup": float(f[5][:-1]), "cores": float(f[6])}
                if len(f) >= 20 and f[-1].endswith("x") and float(f[-1][:-1]) > 0:
                    # each processor's 1-thread median, and 1 + fast/slow: what 2 threads could give
                    row.update({"ms1cpu0": float(f[-3]), "ms1cpu1": float(f[-2]), "ceiling": float(f[-1][:-1])})
                par.append(row)
        if not par:
            b.failures.append(("core_bench parallel", pwhy or "no table in its output"))
        else:
            b.write_csv("core_parallel.csv", par, ["target", "metric", "vertices", "ms1", "ms2", "speedup", "cores",
                                                   "ms1cpu0", "ms1cpu1", "ceiling"])
            self.md.append("\n`core_bench --parallel-only`: the evolve step of a converged sphere on 1 and on 2 threads, "
                           "taking turns step by step on the same mesh (pairs in alternating order). The 1-thread steps "
                           "run pinned to each processor in turn and the faster processor's median is the 1-thread "
                           "figure: this virtual machine's processors are not equally fast (one 1-thread step took 9 ms "
                           "in one run and 18 ms in the next), and unpinned rounds gave speed-ups above 2 on 2 cores. "
                           "Medians; cores = processor seconds per second of the 2-thread steps: near 1 on a busy "
                           "machine, where the speed-up says little. Ceiling = 1 + (faster processor's 1-thread median) / "
                           "(slower one's): the most 2 threads could give on these two processors, perfectly balanced "
                           "(2 on equal ones):\n")
            self.md.append(table([("vertices", lambda x: fmt(x["vertices"])), ("metric", lambda x: x["metric"]),
                                  ("ms, 1 thread", lambda x: fmt(x["ms1"])), ("ms, 2 threads", lambda x: fmt(x["ms2"])),
                                  ("speed-up", lambda x: fmt(x["speedup"]) + "x"), ("cores", lambda x: fmt(x["cores"])),
                                  ("ms, 1 thread on processor 0 / 1", lambda x: "%s / %s" % (fmt(x["ms1cpu0"]), fmt(x["ms1cpu1"]))
                                   if "ceiling" in x else "-"),
                                  ("ceiling", lambda x: fmt(x["ceiling"]) + "x" if "ceiling" in x else "-")],
                                 par))
        self.results["parallel"] = par
        main_rows = [x for x in rows if x["renumbered"]]
        if len(main_rows) >= 2:
            f0 = main_rows[0]
            top = 1.15 * max(max(x["us_per_vertex"] / f0["us_per_vertex"], x["peer_us_per_vertex"] / f0["peer_us_per_vertex"])
                             for x in main_rows)
            data = {"core.dat": "".join("%d %s %s\n" % (x["vertices"], x["us_per_vertex"] / f0["us_per_vertex"],
                                                        x["peer_us_per_vertex"] / f0["peer_us_per_vertex"])
                                        for x in main_rows)}
            b.plot("core_scaling.png", 'set logscale x\nset xrange [700:150000]\nset xlabel "vertices"\n'
                   'set ylabel "time per vertex / time per vertex at %s vertices"\nset yrange [0:%.2f]\n'
                   'set key bottom right\nset title "Cost per vertex against mesh size (flat = linear)"\n'
                   'plot "core.dat" using 1:2 with linespoints pt 7 lw 2 title "riemesh iteration (%s us at %s)", '
                   '"core.dat" using 1:3 with linespoints pt 5 lw 2 title "OpenMesh update_normals, the peer (%s us)", '
                   '1 with lines dt 2 lc "gray" title "linear"' % (
                       fmt(f0["vertices"]), top, fmt(f0["us_per_vertex"]), fmt(f0["vertices"]),
                       fmt(f0["peer_us_per_vertex"])), data)
            self.image(os.path.join(b.out, "core_scaling.png"), "core scaling")

    # Targets -------------------------------------------------------------------------------------
    def targets(self):
        lines = []
        for g in self.results.get("guarantee", []):
            lines.append("- Intersection-free evolution, %s: evolve %s s with the guarantee, %s s without = %.2fx, "
                         "target <= 1.3x: %s%s." % (g["image"], fmt(g["on"]), fmt(g["off"]), g["ratio"],
                                                    verdict(g["ratio"], 1.3),
                                                    " (instructions, one thread: %.2fx, which the machine's load does "
                                                    "not move)" % g["ins_ratio"] if "ins_ratio" in g else ""))
        t2 = {x["model"]: x for x in self.results.get("table2", [])}
        r, fe = t2.get("Riemannian"), t2.get("fine Euclidean")
        if r and fe and ok(r) and ok(fe):
            vr, er = r["vertices"] / fe["vertices"], r["mean"] / fe["mean"]
            lines.append("- Riemannian vs fine Euclidean (phantom): vertices %s / %s = %.2fx, target <= 0.5x: %s; "
                         "mean error %s / %s = %.2fx, target <= 1.3x: %s." % (
                             fmt(r["vertices"]), fmt(fe["vertices"]), vr, verdict(vr, 0.5), fmt(r["mean"]),
                             fmt(fe["mean"]), er, verdict(er, 1.3)))
            fe5 = self.results.get("table2_fe5")
            if fe5 and ok(fe5):
                lines.append("  Sensitivity: with the fine model at the 5th percentile of the Riemannian edges instead "
                             "of the shortest, vertices %s / %s = %.2fx (%s), mean error %.2fx." % (
                                 fmt(r["vertices"]), fmt(fe5["vertices"]), r["vertices"] / fe5["vertices"],
                                 "under 0.5x" if r["vertices"] / fe5["vertices"] <= 0.5 else "over 0.5x",
                                 r["mean"] / fe5["mean"]))
        else:
            lines.append("- Riemannian vs fine Euclidean: **not measured** (a run failed; see Table 2).")
        plate = {x["model"]: x for x in self.results.get("plate", [])}
        if plate:
            rp = plate.get("Riemannian")
            broken = [m for m, x in plate.items() if m != "Riemannian" and ok(x) and not x["kept"]]
            if rp is None or not ok(rp):
                v = "**not measured** (the Riemannian run failed)"
            elif not rp["kept"]:
                v = "**missed**: the Riemannian model lost the plate's topology"
            elif broken:
                v = "**met**: the Riemannian model keeps it; broken by %s" % ", ".join(broken)
            else:
                v = "**not shown**: every Euclidean model kept the plate too"
            lines.append("- Topology kept where a coarse model punches holes (thin plate, 3 voxels): %s." % v)
        if r and ok(r):
            lines.append("- Phantom, total time (read, metric, evolve, write) %s s, target < 1.5 s: %s." % (
                fmt(r["seconds"]), verdict(r["seconds"], 1.5)))
        best = self.results.get("vdb_best")
        if r and ok(r) and best and "seconds" in best:
            pipe = r.get("read_seconds", 0.0) + best["seconds"]
            ratio = r["seconds"] / pipe
            lines.append("- Phantom, riemesh total time vs the OpenVDB pipeline (the same read, %s s, plus Gaussian "
                         "smoothing and volumeToMesh at %s, %s s; its write not counted): %s / %s s = %.2fx, target "
                         "<= 3x: %s." % (fmt(r.get("read_seconds")), best["setting"], fmt(best["seconds"]),
                                         fmt(r["seconds"]), fmt(pipe), ratio, verdict(ratio, 3.0)))
        head = {x["model"]: x for x in self.results.get("head", [])}
        hr = head.get("Riemannian")
        if hr and ok(hr):
            lines.append("- Head MRI: %s component(s) of genus %s (target 1, <= 2), %s vertices (target <= 40,000), "
                         "%s s (target < 20 s): %s." % (
                             fmt(hr["components"]), fmt(hr["genus"]), fmt(hr["vertices"]), fmt(hr["seconds"]),
                             "**met**" if hr["components"] == 1 and hr["genus"] <= 2 and hr["vertices"] <= 40000
                             and hr["seconds"] < 20 else "**missed**"))
            hp = [x for x in self.results.get("head_peers", []) if x.get("tool") == "openvdb" and "seconds" in x]
            if hp:
                p0 = hp[0]
                pipe = hr.get("read_seconds", 0.0) + p0["seconds"]
                ratio = hr["seconds"] / pipe
                lines.append("- Head, riemesh total time vs the OpenVDB pipeline (same read plus smoothing and "
                             "volumeToMesh at %s): %s / %s s = %.2fx, target <= 3x: %s." % (
                                 p0["setting"], fmt(hr["seconds"]), fmt(pipe), ratio, verdict(ratio, 3.0)))
        best = self.results.get("vdb_best")
        if r and ok(r) and best:
            ratio = r["vertices"] / best["vertices"]
            equal = best["mean_voxels"] <= r["mean"]
            lines.append("- Riemannian vs OpenVDB at equal mean error: %s / %s vertices (%s, error %s %s riemesh's %s) "
                         "= %.2fx, target <= 0.7x: %s%s" % (
                             fmt(r["vertices"]), fmt(best["vertices"]), best["setting"], fmt(best["mean_voxels"]),
                             "<=" if equal else ">", fmt(r["mean"]), ratio, verdict(ratio, 0.7),
                             "" if equal else " (no volumeToMesh setting gets as close to the surface as riemesh: "
                             "compared with its most accurate setting, riemesh is closer with %s vertices)" % (
                                 "fewer" if ratio < 1 else "more")))
        else:
            lines.append("- Riemannian vs OpenVDB at equal error: **not measured**.")
        noise = self.results.get("noise", [])
        if noise:
            levels = sorted({x["noise"] for x in noise if "noise" in x})
            def at(n, pred):
                return [x for x in noise if x.get("noise") == n and pred(x)]
            vdb_broken = [n for n in levels if any(not topology_ok(x) for x in at(n, lambda y: y["tool"] == "openvdb"))]
            r_ok = [n for n in levels if all(topology_ok(x) for x in at(n, lambda y: y["tool"] == "riemesh"))
                    and at(n, lambda y: y["tool"] == "riemesh")]
            wins = [n for n in vdb_broken if n in r_ok]
            if not vdb_broken:
                v = "**not shown**: smoothing + volumeToMesh kept the right topology at every noise level tested"
            elif len(wins) == len(vdb_broken):
                v = "**met** at noise %s" % ", ".join("%g" % n for n in wins)
            else:
                v = "**missed** at noise %s (riemesh wrong too)" % ", ".join("%g" % n for n in vdb_broken if n not in wins)
            lines.append("- Right topology where smoothing + volumeToMesh breaks it: volumeToMesh (some setting) wrong at "
                         "noise %s; riemesh right at noise %s: %s." % (
                             ", ".join("%g" % n for n in vdb_broken) or "none", ", ".join("%g" % n for n in r_ok) or "none", v))
        core = [x for x in self.results.get("core", []) if x["renumbered"]]
        five = [x for x in core if x["target"] == 5000]
        if five:
            lines.append("- Core, one iteration of a %s-vertex mesh (one thread): %s ms, target < 2 ms: %s." % (
                fmt(five[0]["vertices"]), fmt(five[0]["ms"]), verdict(five[0]["ms"], 2.0)))
        if len(core) >= 2:
            first, last = core[0], core[-1]
            ours = last["us_per_vertex"] / first["us_per_vertex"]
            peer = last["peer_us_per_vertex"] / first["peer_us_per_vertex"]
            ipv = [x["instructions_per_vertex"] for x in core if "instructions_per_vertex" in x]
            spread = max(ipv) / min(ipv) if len(ipv) == len(core) else None
            lines.append("- Core, cost per iteration linear in the vertex count (%s to %s vertices): instructions per "
                         "vertex %s, max/min = %s, target <= 1.1x: %s; time per vertex grows %.2fx, the peer's plain "
                         "linear pass on the same meshes (OpenMesh update_normals) %.2fx: %s." % (
                             fmt(first["vertices"]), fmt(last["vertices"]),
                             ", ".join(fmt(v) for v in ipv) if spread else "not counted",
                             "%.2fx" % spread if spread else "-", verdict(spread, 1.1) if spread else "**not measured**",
                             ours, peer, "**met** (no more than the peer's: the memory hierarchy, not the algorithm)"
                             if ours <= peer else "**missed** (more than the peer's)"))
        res = [x for x in self.results.get("resolution", []) if x["model"] == "Riemannian"]
        if res and all(ok(x) for x in res):
            vs = [x["vertices"] for x in res]
            ratio = max(vs) / min(vs)
            lines.append("- Riemannian vertex count across sizes %s: %s, max/min = %.2fx, target <= 1.3x: %s." % (
                ", ".join("%d^3" % x["size"] for x in res), ", ".join(fmt(v) for v in vs), ratio, verdict(ratio, 1.3)))
        else:
            lines.append("- Riemannian vertex count across sizes: **not measured** (a run failed).")
        sc = {(x["kind"], x["size"]): x for x in self.results.get("scale", [])}
        s250, s500 = sc.get(("sphere", 250)), sc.get(("sphere", 500))
        if s250:
            if s250.get("time_ratio") and s250.get("error_mean") is not None:
                good = (s250["components"] == 1 and s250["genus"] == 0 and s250["error_mean"] <= 0.1
                        and s250["peak_mb"] <= 1024 and s250["time_ratio"] <= 3)
                lines.append("- Level-set sphere r = 250: %s component(s), genus %s, two-sided mean error %s voxels "
                             "(target <= 0.1), peak %s MB (target <= 1024), wall time %s / %s s = %.2fx the peer's "
                             "(target <= 3x): %s." % (
                                 fmt(s250["components"]), fmt(s250["genus"]), fmt(s250["error_mean"]),
                                 fmt(s250["peak_mb"]), fmt(s250["wall"]), fmt(s250["peer_wall"]), s250["time_ratio"],
                                 "**met**" if good else "**missed**"))
            else:
                lines.append("- Level-set sphere r = 250: **not measured** (%s)." % s250.get("status", "a run failed"))
        if s250 and s500 and s250.get("peak_mb") and s500.get("peak_mb"):
            m = s500["peak_mb"] / s250["peak_mb"]
            lines.append("- Level-set sphere r = 500 (%s box voxels): peak %s MB = %.2fx r = 250's, target <= 4x: %s." % (
                fmt(s500.get("box_voxels")), fmt(s500["peak_mb"]), m, verdict(m, 4.0)))
        # Issue 15: the same iterations at any size; the evolve time; 2 threads over 1.
        p100, p400 = sc.get(("phantom", 100)), sc.get(("phantom", 400))
        if p100 and p400 and p100.get("iterations") and p400.get("iterations"):
            r = p400["iterations"] / p100["iterations"]
            seeds = [x for x in self.results.get("iteration_seeds", []) if x.get("ratio")]
            line = "- Phantom iterations at 400^3 over 100^3 (defaults): %s / %s = %.2fx" % (
                fmt(p400["iterations"]), fmt(p100["iterations"]), r)
            if len(seeds) > 1:  # the verdict on the worst seed: one image can be lucky
                r = max(x["ratio"] for x in seeds)
                line += "; noise seeds %s: %s; worst %.2fx" % (
                    ", ".join(str(x["seed"]) for x in seeds),
                    ", ".join("%s / %s" % (fmt(x["it400"]), fmt(x["it100"])) for x in seeds), r)
            lines.append(line + ", target <= 1.3x: %s." % verdict(r, 1.3))
        for n, limit in ((100, 0.12), (400, 3.0)):
            x = sc.get(("phantom", n))
            if x and x.get("evolve") is not None:
                # The same image with the same defaults also runs unguarded in the guarantee section (its
                # rounds): a time is the fastest of all those runs, as timings are there (this machine's
                # speed drifts by tens of percent; the fastest run is the least disturbed).
                others = [t for g in self.results.get("guarantee", []) if g["image"] == "phantom %d^3" % n
                          for t in g.get("off_runs", [])]
                runs = [x["evolve"]] + others
                best = min(runs)
                how = " (fastest of %d runs: the scale table's and the intersection-free section's unguarded ones; " \
                      "the scale table's alone %s s)" % (len(runs), fmt(x["evolve"])) if others else ""
                lines.append("- Phantom %d^3, evolve %s s%s, target <= %g s: %s." % (n, fmt(best), how, limit,
                                                                                  verdict(best, limit)))
        big = [x for x in self.results.get("parallel", []) if x["vertices"] >= 20000]
        if big:
            worst = min(big, key=lambda x: x["speedup"])
            ceil = [x["ceiling"] for x in big if "ceiling" in x]
            lines.append("- Evolve step on 2 threads over 1 at 20k+ vertices: %s; target >= 1.7x: %s.%s" % (
                ", ".join("%s %s %.2fx" % (fmt(x["vertices"]), x["metric"], x["speedup"]) for x in big),
                "**met**" if worst["speedup"] >= 1.7 else "**missed** (%.2fx)" % worst["speedup"],
                (" The two processors' own 1-thread speeds allowed at most %.2f-%.2fx in this run (2x on equal "
                 "processors)." % (min(ceil), max(ceil))) if ceil else ""))
        for n, tl, ml in ((100, 1.5, None), (400, 2.0, 1.5)):
            x = sc.get(("phantom", n))
            if not x:
                continue
            if x.get("time_ratio"):
                line = "- Phantom %d^3, wall time %s / %s s = %.2fx the peer's, target <= %gx: %s" % (
                    n, fmt(x["wall"]), fmt(x["peer_wall"]), x["time_ratio"], tl, verdict(x["time_ratio"], tl))
                if ml and x.get("memory_ratio"):
                    line += "; peak memory %s / %s MB = %.2fx, target <= %gx: %s" % (
                        fmt(x["peak_mb"]), fmt(x["peer_peak_mb"]), x["memory_ratio"], ml, verdict(x["memory_ratio"], ml))
                lines.append(line + ".")
            else:
                lines.append("- Phantom %d^3 against the peer: **not measured** (%s)." % (n, x.get("status", "a run failed")))
        return "\n".join(lines)


def machine_text(load_start):
    cpu = "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    here = os.path.dirname(os.path.abspath(__file__))
    try:
        commit = subprocess.run(["git", "-C", here, "describe", "--always", "--dirty"], capture_output=True,
                                text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.TimeoutExpired):
        commit = "unknown"
    load_end = os.getloadavg()
    return ("Machine: %d processors (nproc), %s; load average %.2f / %.2f / %.2f at the start, %.2f / %.2f / %.2f "
            "at the end (the machine is shared: timings are noisy). Commit %s." % (
                os.cpu_count() or 0, cpu, *load_start, *load_end, commit or "unknown"))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", required=True, help="folder with vdbphantom, vdb2mesh, vdb_bench, render_mesh, core_bench "
                    "(and cgal_bench, optional)")
    ap.add_argument("--out", required=True, help="results folder (CSV, PNG, benchmarks.md)")
    ap.add_argument("--docs", help="also write DOCS/benchmarks.md and DOCS/benchmarks/ (PNG, CSV)")
    ap.add_argument("--quick", action="store_true", help="small sizes, seconds; non-zero exit on any failure")
    ap.add_argument("--sections", default=",".join(SECTIONS), help="comma list of " + ",".join(SECTIONS))
    args = ap.parse_args()
    for t in ("vdbphantom", "vdb2mesh", "vdb_bench", "render_mesh", "core_bench"):
        if not os.access(os.path.join(args.bin, t), os.X_OK):
            print("report.py: error: %s not found in %s (build first: scripts/build)" % (t, args.bin), file=sys.stderr)
            return 1
    wanted = [s for s in args.sections.split(",") if s]
    bad = [s for s in wanted if s not in SECTIONS]
    if bad:
        print("report.py: error: unknown section %s (sections: %s)" % (",".join(bad), ",".join(SECTIONS)), file=sys.stderr)
        return 1
    if args.quick and "head" in wanted and args.sections == ",".join(SECTIONS):
        wanted.remove("head")  # the head is 7 M voxels: not a few seconds
    os.makedirs(args.out, exist_ok=True)
    bench = Bench(args)
    rep = Report(bench, args)
    started = time.monotonic()
    load_start = os.getloadavg()
    date = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    # Order matters: peers and the resolution sweep use the phantom's Riemannian result.
    for s in SECTIONS:
        if s in wanted:
            print("report.py: %s ..." % s, file=sys.stderr, flush=True)
            try:
                getattr(rep, s)()
            except Exception as e:  # a bug in one section must not lose the others' results
                bench.failures.append(("section " + s, "report.py crashed: %s: %s" % (type(e).__name__, e)))
                rep.md.append("\n**This section crashed:** %s: %s\n" % (type(e).__name__, e))
    head = ["# riemesh benchmarks: the paper's experiments, reproduced against peers", "",
            "Generated by `scripts/bench%s` on %s in %.0f s. %s" % (" --quick" if args.quick else "", date,
                                                                   time.monotonic() - started, machine_text(load_start)),
            "", "Every number below comes from this one run; the verdicts are computed from them.", "",
            "## Targets", "", rep.targets(), ""]
    if bench.failures:
        head += ["## Runs that failed", ""] + ["- %s: %s" % f for f in bench.failures] + [""]
    text = "\n".join(head + rep.md) + "\n"
    write_text(os.path.join(args.out, "benchmarks.md"), text)
    if args.docs:
        dest = os.path.join(args.docs, "benchmarks")
        os.makedirs(dest, exist_ok=True)
        for f in bench.pngs + bench.csvs:
            shutil.copy(f, os.path.join(dest, os.path.basename(f)))
        linked = text
        for f in bench.pngs:
            name = os.path.basename(f)
            linked = linked.replace("](%s)" % name, "](benchmarks/%s)" % name)
        write_text(os.path.join(args.docs, "benchmarks.md"), linked)
    print("report.py: %s written (%d failed runs)" % (os.path.join(args.out, "benchmarks.md"), len(bench.failures)),
          file=sys.stderr)
    if args.quick and bench.failures:
        for what, why in bench.failures:
            print("report.py: failed: %s: %s" % (what, why), file=sys.stderr)
        return 1
    return 0


def write_text(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w") as f:
        f.write(text)
    os.replace(tmp, path)


if __name__ == "__main__":
    sys.exit(main())
