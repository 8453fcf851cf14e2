#!/usr/bin/env python3
"""The scaling plot of the README and BENCHMARKS.md: the CSV written by
`cargo run --release -p sfs-geometry --example scaling -- target/scaling.csv` drawn as two
log-log panels (update time against surface vertices, against network curves), one line per
timing column (cold, warm, and any added later), and a third (issue 35, point 3): the two
phases of a live update against the network's curves (E to the curves: the network; its
surface; E to the surface: the whole update), as an SVG with no dependency.

    python3 benches/scaling_plot.py target/scaling.csv docs/scaling.svg
"""
import csv
import math
import sys

COLOURS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd"]

# What each column of the CSV is, for a reader of the README (BENCHMARKS.md has the details).
LABELS = {
    "cold": "a surface from scratch",
    "warm": "the same, factorisation patterns kept",
    "exact": "one more curve, surfaced exactly",
    "provisional": "one more curve, faces it did not touch kept",
    "again": "the same network again (a monitored epoch)",
    "curves": "E to the new curves shown (the network)",
    "surface": "then its surface",
    "update": "E to the new surface shown (the whole update)",
    "settle": "the exact update that follows while idle",
}


def panel(rows, series, x0, y0, w, h, title, xlabel):
    """One log-log panel of the rows of `series`, its origin at (x0, y0), as SVG elements."""
    pts = [r for r in rows if r["series"] == series]
    if not pts:
        return []
    cols = [k for k in pts[0] if k.endswith("_ms") and any(r[k] for r in pts)]
    xs = [float(r["x"]) for r in pts]
    ys = [float(r[c]) for r in pts for c in cols if r[c]]
    lx0, lx1 = math.log10(min(xs)), math.log10(max(xs))
    ly0, ly1 = math.floor(math.log10(min(ys))), math.ceil(math.log10(max(ys)))
    if lx1 == lx0:
        lx1 = lx0 + 1
    sx = lambda x: x0 + (math.log10(x) - lx0) / (lx1 - lx0) * w
    sy = lambda y: y0 + h - (math.log10(y) - ly0) / (ly1 - ly0) * h
    out = [
        f'<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="#888"/>',
        f'<text x="{x0 + w / 2}" y="{y0 - 10}" text-anchor="middle" font-size="14">{title}</text>',
        f'<text x="{x0 + w / 2}" y="{y0 + h + 36}" text-anchor="middle" font-size="12">{xlabel}</text>',
        f'<text x="{x0 - 48}" y="{y0 + h / 2}" font-size="12" transform="rotate(-90 {x0 - 48} {y0 + h / 2})" text-anchor="middle">ms</text>',
    ]
    for d in range(ly0, ly1 + 1):
        y = sy(10 ** d)
        out.append(f'<line x1="{x0}" y1="{y:.1f}" x2="{x0 + w}" y2="{y:.1f}" stroke="#eee"/>')
        out.append(f'<text x="{x0 - 6}" y="{y + 4:.1f}" text-anchor="end" font-size="11">{10 ** d:g}</text>')
    for x in xs:
        out.append(f'<text x="{sx(x):.1f}" y="{y0 + h + 16}" text-anchor="middle" font-size="11">{x:g}</text>')
    for k, c in enumerate(cols):
        line = [(sx(float(r["x"])), sy(float(r[c]))) for r in pts if r[c]]
        colour = COLOURS[k % len(COLOURS)]
        path = " ".join(f"{x:.1f},{y:.1f}" for x, y in line)
        out.append(f'<polyline points="{path}" fill="none" stroke="{colour}" stroke-width="2"/>')
        for x, y in line:
            out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="3" fill="{colour}"/>')
        label = LABELS.get(c[:-3], c[:-3])
        out.append(f'<text x="{x0 + 10}" y="{y0 + 18 + 16 * k}" font-size="12" fill="{colour}">{label}</text>')
    return out


def main():
    src, dst = sys.argv[1], sys.argv[2]
    with open(src, newline="") as f:
        rows = list(csv.DictReader(f))
    body = panel(rows, "vertices", 70, 40, 380, 300, "time (ms) against the surface's size", "surface vertices")
    body += panel(rows, "curves", 560, 40, 380, 300, "time (ms) against the network's curves (20 k vertices)", "curves in the network")
    body += panel(rows, "session", 1050, 40, 380, 300, "after E: what the operator waits for (ms)", "curves in the network")
    svg = (
        '<svg xmlns="http://www.w3.org/2000/svg" width="1470" height="400" font-family="sans-serif">'
        '<rect width="100%" height="100%" fill="white"/>' + "".join(body) + "</svg>\n"
    )
    with open(dst, "w") as f:
        f.write(svg)


if __name__ == "__main__":
    main()
