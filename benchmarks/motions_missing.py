"""The number of motions on incomplete tracks: :func:`laav.estimate_motions` on Hopkins155
with the seeded occlusion of ``laav bench --missing`` (tracks start late, end early, one gap;
:func:`laav.synthetic.occlude`), against the same estimate on the complete tracks.

With no track seen in every frame the estimate runs on the stretch of frames and the tracks
seen throughout it that hold the most entries (:func:`laav.motions.complete_window`). The
constants of the test were fitted on complete tracks (``benchmarks/motions.py``); nothing is
tuned here. Prints one JSON line per sequence and writes a Markdown table with machine, date
and git commit.

    python benchmarks/motions_missing.py --data DIR [--missing 0.2,0.4] [--every 1]
        [--out docs/bench/motions_missing.md]
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import cpu_model, git_commit, laav_version  # noqa: E402

import laav  # noqa: E402
from laav.io import find_truth_files, load_sequence  # noqa: E402
from laav.motions import complete_window  # noqa: E402
from laav.synthetic import occlude  # noqa: E402


def _estimate(seq) -> tuple[int, str]:
    """(estimated C or -1 when the estimate refuses, the window or the refusal)."""
    try:
        c = laav.estimate_motions(seq, random_state=0).n_motions
    except ValueError as e:
        return -1, str(e).split(": ", 1)[-1][:90]
    if seq.is_complete:
        return c, "all"
    a, b, idx = complete_window(seq.visible)
    return c, f"frames {a}-{b - 1} of {seq.n_frames}, {idx.size} of {seq.n_points} tracks"


def run(data: str, shares: list[float], every: int) -> list[dict]:
    rows = []
    for path in find_truth_files(data)[::every]:
        seq = load_sequence(path)
        row = {"sequence": path.parent.name, "true": seq.n_motions}
        row["complete"], _ = _estimate(seq)
        for m in shares:
            row[f"missing {m:.0%}"], row[f"window {m:.0%}"] = _estimate(occlude(seq, m, rng=0))
        print(json.dumps(row), flush=True)
        rows.append(row)
    return rows


def report(rows: list[dict], shares: list[float], out: str, argv: list[str], seconds: float) -> None:
    n = len(rows)

    def right(key, C=None):
        sel = [r for r in rows if C is None or r["true"] == C]
        k = sum(r[key] == r["true"] for r in sel)
        return f"{k} / {len(sel)} ({100 * k / max(len(sel), 1):.1f} %)"

    keys = ["complete"] + [f"missing {m:.0%}" for m in shares]
    when = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    lines = [
        f"# The number of motions on incomplete tracks ({when})",
        "",
        f"- Machine: {cpu_model()}, 2 logical cores (shared with other jobs), {platform.system()} "
        f"{platform.release()}",
        f"- Software: Python {platform.python_version()}, laav {laav_version()} (git {git_commit()})",
        f"- Command: `python benchmarks/motions_missing.py {' '.join(argv)}` ({seconds:.0f} s)",
        f"- Data: {n} Hopkins155 sequences; `laav.synthetic.occlude(seq, share, rng=0)`; "
        "`laav.estimate_motions(seq, random_state=0)` (constants fitted on complete tracks, "
        "`docs/bench/motions.md`; nothing tuned here). A refusal (no stretch of >= 10 frames "
        "seen whole by 16 tracks) counts as wrong.",
        "",
        "| tracks | C right | 2 motions | 3 motions | refused |",
        "|---|---|---|---|---|",
    ]
    for key in keys:
        refused = sum(r[key] == -1 for r in rows)
        lines.append(f"| {key} | {right(key)} | {right(key, 2)} | {right(key, 3)} | {refused} |")
    lines += ["", "Per sequence (true C, estimate on complete tracks, on each share, the stretch used):", "",
              "```"] + [json.dumps(r) for r in rows] + ["```", ""]
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text("\n".join(lines))
    print(f"wrote {out}")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", required=True)
    ap.add_argument("--missing", default="0.2,0.4")
    ap.add_argument("--every", type=int, default=1, help="every k-th sequence (default: all)")
    ap.add_argument("--out", default="docs/bench/motions_missing.md")
    a = ap.parse_args(argv)
    shares = [float(s) for s in a.missing.split(",")]
    t = time.perf_counter()
    rows = run(a.data, shares, a.every)
    report(rows, shares, a.out, argv, time.perf_counter() - t)


if __name__ == "__main__":
    main()
