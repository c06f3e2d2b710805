"""Per-stage timings of LAAV and Random Voting over Hopkins155, on one core.

Prints a table of medians and 90th percentiles (ms) per stage, the plain RV time, and
the time of a lambda-only ``Pipeline.update``; writes the same as markdown (``--out``).

    python benchmarks/speed.py --data /path/to/hopkins155 [--every 1] [--out bench-out/speed.md]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # one core: set before numpy is imported

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import laav  # noqa: E402
from laav.params import STAGES  # noqa: E402


def _data_dir(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    if os.environ.get("HOPKINS155"):
        return Path(os.environ["HOPKINS155"])
    return Path(__file__).resolve().parents[2] / "shared" / "data" / "hopkins155"


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", help="Hopkins155 folder (default $HOPKINS155 or ../shared/...)")
    ap.add_argument("--every", type=int, default=1, help="use every k-th sequence (default 1)")
    ap.add_argument("--out", default="bench-out/speed.md")
    args = ap.parse_args(argv)
    root = _data_dir(args.data)
    files = [f for f in laav.find_truth_files(root) if f.parent.name != "dancing"][:: args.every]
    if not files:
        print(f"no *_truth.mat files under {root}", file=sys.stderr)
        return 2
    stage = {s: [] for s in (*STAGES, "total")}
    rv, lam = [], []
    for f in files:
        seq = laav.load_sequence(f)
        t = time.perf_counter()
        pipe = laav.Pipeline(seq, seq.n_motions)
        stage["total"].append(time.perf_counter() - t)
        for s in STAGES:
            stage[s].append(pipe.result.timings[s])
        t = time.perf_counter()
        pipe.update(lam=pipe.params.lam * 1.5)
        lam.append(time.perf_counter() - t)
        t = time.perf_counter()
        laav.random_voting(seq, seq.n_motions, seed=0)
        rv.append(time.perf_counter() - t)

    def row(name, v):
        v = 1000 * np.asarray(v)
        return f"| {name} | {np.median(v):.1f} | {np.percentile(v, 90):.1f} |"

    lines = [
        f"# Speed, {time.strftime('%Y-%m-%d')}: {len(files)} Hopkins155 sequences, one core",
        "",
        f"Machine: {_cpu()}, {os.cpu_count()} cores, {platform.system()} {platform.machine()}, "
        f"Python {platform.python_version()}, numpy {np.__version__}, laav {laav.__version__}.",
        "",
        "| stage (LAAV, default parameters) | median ms | p90 ms |",
        "|---|---:|---:|",
        *[row(s, stage[s]) for s in (*STAGES, "total")],
        row("lambda-only Pipeline.update", lam),
        row("plain Random Voting (total)", rv),
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"written: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
