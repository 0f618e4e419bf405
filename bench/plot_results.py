#!/usr/bin/python3
# SPDX-License-Identifier: MIT
"""Draws the benches' CSV files (bench_parallel --csv, bench_peers --csv) as PNG plots.

  /usr/bin/python3 bench/plot_results.py bench/results/*.csv        -> a .png beside each

A 'main' table gives one panel per distribution: speedup over pdt with 1 worker
(insertions and removals, one operation at a time), CGAL parallel's speedup over
its own 1-thread run, and the ideal line. A 'skewed' table gives one panel per
stream: speedup with stealing on and off. An 'interleaved' table (insertions and
removals mixed) gives pdt's speedup over its 1 worker and over CGAL sequential.
A bench_peers table gives seconds per peer against threads, one panel per
distribution. Needs Debian's python3-matplotlib (scripts/install-deps.sh
--extras). The PNG goes beside the CSV; a file of any other kind is an error.
"""
import csv
import sys
from collections import defaultdict

try:
    import matplotlib
except ImportError:
    sys.exit("plot_results: needs matplotlib: run scripts/install-deps.sh --extras "
             "(Debian's python3-matplotlib), then /usr/bin/python3 bench/plot_results.py FILE.csv")

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FormatStrFormatter  # noqa: E402


def load(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def seconds_by(rows, **match):
    out = {}
    for r in rows:
        if all(r[k] == v for k, v in match.items()):
            out[int(r["threads"])] = float(r["seconds"])
    return dict(sorted(out.items()))


def speedups(times):
    if 1 not in times:
        return [], []
    base = times[1]
    ts = list(times)
    return ts, [base / times[t] for t in ts]


def panel_axes(n):
    cols = min(n, 3)
    rows = (n + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.9 * rows), squeeze=False)
    return fig, [a for row in axes for a in row]


def finish(ax, threads, title):
    top = max(threads) if threads else 16
    ax.plot([1, top], [1, top], color="0.7", linestyle=":", label="ideal")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log", base=2)
    ax.set_xticks(threads)
    ax.set_xticklabels([str(t) for t in threads])
    ax.set_xlabel("workers (threads)")
    ax.set_ylabel("speedup over 1")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def save(fig, axes, used, title, out):
    """Blanks the panels past the first `used`, titles the figure and writes it."""
    for ax in axes[used:]:
        ax.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def plot_main(rows, out, machine):
    known = ["uniform", "normal", "line", "clusters", "kuzmin"]  # the benches' order; others after, as read
    dists = []
    for r in rows:
        if r["experiment"] == "main" and r["dist"] not in dists:
            dists.append(r["dist"])
    dists.sort(key=lambda d: known.index(d) if d in known else len(known))
    fig, axes = panel_axes(len(dists))
    for ax, d in zip(axes, dists):
        threads = []
        for impl, phase, style, label in [("pdt", "insert", "o-", "pdt insert"),
                                          ("pdt", "remove", "s-", "pdt remove"),
                                          ("pdt_batch", "insert", "^--", "pdt batch insert"),
                                          ("cgal_par", "insert", "v-.", "CGAL parallel insert"),
                                          ("cgal_par", "remove", "x-.", "CGAL parallel remove")]:
            ts, sp = speedups(seconds_by(rows, experiment="main", dist=d, impl=impl, phase=phase))
            if ts:
                ax.plot(ts, sp, style, label=label)
                threads = ts
        points = next(r["points"] for r in rows if r["dist"] == d)
        finish(ax, threads, f"{d}, {int(points):,} points")
    save(fig, axes, len(dists), f"bench_parallel: speedup over 1 worker ({machine})", out)


def plot_skewed(rows, out, machine):
    streams = []
    for r in rows:
        if r["experiment"] == "skewed" and r["dist"] not in streams:
            streams.append(r["dist"])
    fig, axes = panel_axes(len(streams))
    for ax, d in zip(axes, streams):
        threads = []
        for impl, style, label in [("pdt", "o-", "stealing + recuts"), ("pdt_norecut", "^-.", "stealing only"),
                                   ("pdt_nosteal", "s--", "static")]:
            ts, sp = speedups(seconds_by(rows, experiment="skewed", dist=d, impl=impl, phase="mixed"))
            if ts:
                ax.plot(ts, sp, style, label=label)
                threads = ts
        finish(ax, threads, d)
    save(fig, axes, len(streams), f"bench_parallel --skewed: speedup over 1 worker ({machine})", out)


def plot_interleaved(rows, out, machine):
    dists = []
    for r in rows:
        if r["experiment"] == "interleaved" and r["dist"] not in dists:
            dists.append(r["dist"])
    fig, axes = panel_axes(len(dists))
    for ax, d in zip(axes, dists):
        times = seconds_by(rows, experiment="interleaved", dist=d, impl="pdt", phase="mixed")
        ts, sp = speedups(times)
        if ts:
            ax.plot(ts, sp, "o-", label="pdt, over its 1 worker")
        cgal = seconds_by(rows, experiment="interleaved", dist=d, impl="cgal_seq", phase="mixed")
        if 1 in cgal and times:
            ts = list(times)
            ax.plot(ts, [cgal[1] / times[t] for t in ts], "s--", label="pdt, over CGAL sequential")
        points = next(r["points"] for r in rows if r["dist"] == d)
        finish(ax, ts, f"{d}, {int(points):,} points, interleaved")
    save(fig, axes, len(dists), f"bench_parallel, interleaved ({machine})", out)


def plot_peers(rows, out, machine):
    dists = []
    for r in rows:
        if r["dist"] not in dists:
            dists.append(r["dist"])
    fig, axes = panel_axes(len(dists))
    styles = {"pdt_batch": "o", "pdt_engine": "o-", "cgal_batch": "s", "cgal_parallel": "s--", "hxt": "^:"}
    for ax, d in zip(axes, dists):
        impls = []
        for r in rows:
            if r["dist"] == d and r["impl"] not in impls:
                impls.append(r["impl"])
        threads = set()
        for impl in impls:
            pts = sorted((int(r["threads"]), float(r["seconds"])) for r in rows if r["dist"] == d and r["impl"] == impl)
            threads.update(t for t, _ in pts)
            ax.plot([t for t, _ in pts], [sec for _, sec in pts], styles.get(impl, "x-"), label=impl)
        ts = sorted(threads)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
        ax.yaxis.set_minor_formatter(FormatStrFormatter("%g"))
        ax.set_xticks(ts)
        ax.set_xticklabels([str(t) for t in ts])
        ax.set_xlabel("threads")
        ax.set_ylabel("seconds (lower is better)")
        points = next(r["points"] for r in rows if r["dist"] == d)
        ax.set_title(f"{d}, {int(points):,} points")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    save(fig, axes, len(dists), f"bench_peers: batch triangulation time ({machine})", out)


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    for path in sys.argv[1:]:
        try:
            rows = load(path)
        except OSError as e:
            sys.exit(f"plot_results: cannot read {path}: {e.strerror}")
        if not rows:
            sys.exit(f"plot_results: {path} has no rows")
        machine = "16 cores" if "16cores" in path else "2 cores" if "2cores" in path else path
        out = path.rsplit(".", 1)[0] + ".png"
        if "experiment" not in rows[0]:
            if not {"dist", "impl", "threads", "seconds", "points"} <= rows[0].keys():
                sys.exit(f"plot_results: {path}: neither a bench_parallel nor a bench_peers table")
            plot_peers(rows, out, machine)
            print(f"plot_results: {out}")
            continue
        kinds = defaultdict(int)
        for r in rows:
            kinds[r["experiment"]] += 1
        if kinds.get("skewed"):
            plot_skewed(rows, out, machine)
        elif kinds.get("main"):
            plot_main(rows, out, machine)
        elif kinds.get("interleaved"):
            plot_interleaved(rows, out, machine)
        else:
            sys.exit(f"plot_results: {path}: no 'main', 'skewed' or 'interleaved' rows")
        print(f"plot_results: {out}")


if __name__ == "__main__":
    main()
