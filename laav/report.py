"""The benchmark report: ``report.md`` and its figures, computed from ``runs.csv`` only.

:func:`report_from_csv` turns a ``runs.csv`` (see :mod:`laav.bench`) into Markdown;
:func:`write_report` writes it next to the CSV with three PNG figures. Apart from the
published reference rows of Table 1 (clearly labelled), every number comes from the CSV.

Aggregation: for each method and noise level the error of a sequence is first averaged
over its seeds; means and medians are then taken over sequences, so a sequence counts
once whatever the number of seeds. Errors are misclassification rates in percent.

Missing data (``laav bench --missing``): the sections of the complete-data report (Table 1,
noise, convergence, repetitions, time; Figs. 2-4) use the runs at missing share 0, or at
the smallest share when there is none; when the CSV holds more than one share, a table
and a figure of the error against the missing share (at the smallest noise level) follow.

matplotlib is imported only inside :func:`write_figures` and draws on Agg canvases
without pyplot (no global backend state is touched).
"""

from __future__ import annotations

import os
from collections import Counter
from pathlib import Path

import numpy as np

from .bench import RUNS_CSV, format_noise, read_runs

__all__ = ["PUBLISHED", "FIGURES", "MISSING_FIGURE", "report_from_csv", "write_report",
           "write_figures", "table1", "per_sequence_errors", "method_label", "missing_table"]

#: Mean misclassification (%) reported in Table 1 of the LAAV paper: two, three motions, all.
PUBLISHED = {
    "laav": (0.37, 1.12, 0.55),
    "rv": (0.44, 1.88, 0.77),
}
#: File names of the figures, by role.
FIGURES = {
    "noise": "fig2_error_vs_noise.png",
    "convergence": "fig3_convergence.png",
    "repetitions": "fig4_repetitions.png",
}
#: File name of the error-vs-missing-share figure (only when runs.csv holds several shares).
MISSING_FIGURE = "fig5_error_vs_missing.png"
_LABELS = {"laav": "LAAV", "rv": "RV"}
_COLORS = {"laav": "#1f77b4", "rv": "#d62728"}


def method_label(method: str) -> str:
    """Display name of a method (``laav`` -> ``LAAV``)."""
    return _LABELS.get(method, method)


def _methods(rows) -> list[str]:
    present = {r["method"] for r in rows}
    return [m for m in _LABELS if m in present] + sorted(present - set(_LABELS))


def _levels(rows) -> list[float]:
    return sorted({r["noise"] for r in rows})


def _select(rows, method=None, sigma=None):
    return [r for r in rows if (method is None or r["method"] == method)
            and (sigma is None or r["noise"] == sigma)]


def per_sequence_errors(rows, method: str, sigma: float) -> dict:
    """``{sequence: (motions, category, mean error over seeds, std over seeds, n seeds)}``."""
    groups: dict = {}
    for r in _select(rows, method, sigma):
        groups.setdefault(r["sequence"], []).append(r)
    out = {}
    for name, rs in sorted(groups.items()):
        e = np.array([r["error"] for r in rs])
        std = float(e.std(ddof=1)) if e.size > 1 else float("nan")
        out[name] = (rs[0]["motions"], rs[0]["category"], float(e.mean()), std, int(e.size))
    return out


def _stats(values) -> tuple[float, float, int]:
    v = np.asarray(list(values), dtype=float)
    if v.size == 0:
        return float("nan"), float("nan"), 0
    return float(v.mean()), float(np.median(v)), int(v.size)


def table1(rows, sigma: float = 0.0) -> dict:
    """Mean and median error per method over two-motion, three-motion and all sequences.

    Returns
    -------
    dict
        ``{method: {"two": (mean, median, n), "three": (...), "all": (...)}}``.
    """
    out = {}
    for m in _methods(rows):
        seqs = per_sequence_errors(rows, m, sigma)
        if not seqs:
            continue
        out[m] = {
            "two": _stats(v[2] for v in seqs.values() if v[0] == 2),
            "three": _stats(v[2] for v in seqs.values() if v[0] == 3),
            "all": _stats(v[2] for v in seqs.values()),
        }
    return out


def _shares(rows) -> list[float]:
    return sorted({r.get("missing", 0.0) for r in rows})


def _base(rows) -> tuple[list, float]:
    """The runs of the complete-data sections: missing share 0 (else the smallest); the share."""
    shares = _shares(rows)
    share = 0.0 if not shares or 0.0 in shares else shares[0]
    return [r for r in rows if r.get("missing", 0.0) == share], share


def _pct(share: float) -> str:
    return f"{100 * share:.4g} %"


def missing_table(rows) -> tuple[float, dict]:
    """Error against the missing share, at the smallest noise level of ``rows``.

    Returns
    -------
    (sigma, dict)
        ``{method: {share: {"two": (mean, median, n), "three": ..., "all": ...,
        "unlabelled": mean unlabelled % over runs (NaN when not recorded)}}}``; errors
        averaged over seeds per sequence first, as in :func:`table1`.
    """
    sigma = min(r["noise"] for r in rows)
    at = [r for r in rows if r["noise"] == sigma]
    out = {}
    for share in _shares(at):
        rs = [r for r in at if r.get("missing", 0.0) == share]
        for m, t in table1(rs, sigma).items():
            unl = [r.get("unlabelled", float("nan")) for r in rs if r["method"] == m]
            known = [u for u in unl if np.isfinite(u)]
            t["unlabelled"] = float(np.mean(known)) if known else float("nan")
            out.setdefault(m, {})[share] = t
    return sigma, out


def _f(v: float, nd: int = 2) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.{nd}f}"


def _sigma(s: float) -> str:
    return format_noise(s)


def _noise_means(rows) -> dict:
    """``{method: {sigma: (mean, median, n sequences)}}`` of per-sequence mean errors."""
    return {m: {s: _stats(v[2] for v in per_sequence_errors(rows, m, s).values())
                for s in _levels(rows) if _select(rows, m, s)}
            for m in _methods(rows)}


def _convergence(rows) -> dict:
    """``{method: {sigma: (median iterations, p90 iterations, non-converged %, n runs)}}``."""
    out = {}
    for m in _methods(rows):
        out[m] = {}
        for s in _levels(rows):
            rs = _select(rows, m, s)
            if not rs:
                continue
            it = np.array([r["iterations"] for r in rs], dtype=float)
            nc = 100.0 * float(np.mean([not r["converged"] for r in rs]))
            out[m][s] = (float(np.median(it)), float(np.percentile(it, 90)), nc, len(rs))
    return out


def _repetitions(rows) -> dict:
    """``{method: {sigma: (mean std, median std, max std, n sequences with >= 2 seeds)}}``."""
    out = {}
    for m in _methods(rows):
        out[m] = {}
        for s in _levels(rows):
            stds = [v[3] for v in per_sequence_errors(rows, m, s).values() if v[4] > 1]
            if stds:
                a = np.array(stds)
                out[m][s] = (float(a.mean()), float(np.median(a)), float(a.max()), a.size)
    return out


def _balance(rows, seqs, methods, levels) -> list[str]:
    """Seeds per noise level, and a warning when some sequence/method lacks runs."""
    seeds: dict = {}
    for r in rows:
        seeds.setdefault((r["noise"], r["method"], r["sequence"]), set()).add(r["seed"])
    per_level, uneven = [], []
    for s in levels:
        sets = [seeds.get((s, m, q), set()) for m in methods for q in seqs]
        union = set().union(*sets)
        per_level.append(f"σ = {_sigma(s)}: {len(union)}")
        missing = sum(len(union - x) for x in sets)
        if missing:
            uneven.append(f"σ = {_sigma(s)}: {missing} of {len(union) * len(sets)} runs missing")
    out = ["Seeds per sequence and method: " + "; ".join(per_level) + ".", ""]
    if uneven:
        out += ["**Note:** not every sequence has every method and seed (" + "; ".join(uneven)
                + "): an interrupted or partial bench? Rerun it with the same options to "
                "complete it.", ""]
    return out


def _code_line(rows) -> str:
    """Which package version and git commit made the runs (the rows' provenance columns)."""
    made = Counter((r["version"] or "?", r["commit"] or "unrecorded") for r in rows)
    parts = [f"laav {v} at git `{c}`" for v, c in sorted(made)]
    if len(made) == 1:
        return f"Code: {parts[0]} (every run)."
    counts = [f"{p}: {made[k]} runs" for p, k in zip(parts, sorted(made))]
    return "Code: **mixed** (resumed with `--allow-mixed`): " + "; ".join(counts) + "."


def report_from_csv(path: str | os.PathLike) -> str:
    """The Markdown report of a ``runs.csv`` (every number computed from the CSV)."""
    path = Path(path)
    all_rows = read_runs(path)
    lines = ["# LAAV benchmark report", ""]
    if not all_rows:
        return "\n".join(lines + [f"`{path.name}` holds no runs yet.", ""])
    shares = _shares(all_rows)
    rows, base_share = _base(all_rows)
    methods = _methods(rows)
    levels = _levels(rows)
    seqs = sorted({r["sequence"] for r in rows})
    motions = {r["sequence"]: r["motions"] for r in rows}
    seeds = sorted({r["seed"] for r in rows})
    n2 = sum(1 for s in seqs if motions[s] == 2)
    n3 = sum(1 for s in seqs if motions[s] == 3)
    if shares == [0.0]:
        where = ""
    elif len(shares) == 1:
        where = (f" All runs at {_pct(base_share)} of the entries missing (seeded occlusion "
                 "model: tracks start late, end early and have one gap).")
    else:
        where = (f" Missing shares {', '.join(_pct(s) for s in shares)} (seeded occlusion "
                 "model: tracks start late, end early and have one gap); the sections up to "
                 f"*Run time* use the {_pct(base_share)} runs ({len(rows)} of {len(all_rows)}),"
                 " the last section all of them.")
    lines += [
        f"Computed from `{path.name}`: {len(all_rows)} runs of {len(seqs)} sequences "
        f"({n2} with two motions, {n3} with three, {len(seqs) - n2 - n3} other), "
        f"methods {', '.join(method_label(m) for m in _methods(all_rows))}, "
        f"seeds {', '.join(map(str, seeds))}, noise σ = {', '.join(map(_sigma, levels))} px. "
        "Parameters: `bench.json`." + where,
        "",
        _code_line(all_rows),
        "",
        "Errors are misclassification rates in percent (a point left unlabelled counts as "
        "wrong). Each sequence's error is first averaged over its seeds; means and medians "
        "are over sequences.",
        "",
    ]
    lines += _balance(rows, seqs, methods, levels)

    # Table 1
    title = "## Table 1: misclassification rate (%) without added noise"
    if base_share:
        title += f", {_pct(base_share)} of the entries missing"
    lines += [title, ""]
    t1 = table1(rows, 0.0)
    head = ("| Method | 2 motions mean | 2 motions median | 3 motions mean | 3 motions median "
            "| All mean | All median | Sequences |")
    lines += [head, "|---|---:|---:|---:|---:|---:|---:|---:|"]
    if not t1:
        lines.append("| (no runs at σ = 0) | | | | | | | |")
    for m, t in t1.items():
        lines.append(
            f"| {method_label(m)} | {_f(t['two'][0])} | {_f(t['two'][1])} | {_f(t['three'][0])} "
            f"| {_f(t['three'][1])} | {_f(t['all'][0])} | {_f(t['all'][1])} | {t['all'][2]} |"
        )
    for m, (two, three, all_) in PUBLISHED.items():
        lines.append(f"| {method_label(m)} (published) | {two:.2f} | – | {three:.2f} | – "
                     f"| {all_:.2f} | – | 155 |")
    lines += ["", "Rows marked *published* are the means reported in the LAAV paper "
              "(Table 1, Hopkins155) for reference; they are not computed from this run.", ""]

    # per category
    cats = sorted({r["category"] for r in rows if r["category"]})
    if cats and t1:
        lines += ["### By category (σ = 0, mean %)", "",
                  "| Category | Motions | Sequences | "
                  + " | ".join(method_label(m) for m in t1) + " |",
                  "|---|---:|---:|" + "---:|" * len(t1)]
        per = {m: per_sequence_errors(rows, m, 0.0) for m in t1}
        category = {r["sequence"]: r["category"] for r in rows}
        for c in cats:
            for k in sorted({motions[s] for s in seqs}):
                names = [s for s in seqs if motions[s] == k and category[s] == c
                         and any(s in per[m] for m in t1)]
                if not names:
                    continue
                vals = [_f(_stats(per[m][s][2] for s in names if s in per[m])[0]) for m in t1]
                lines.append(f"| {c} | {k} | {len(names)} | " + " | ".join(vals) + " |")
        lines.append("")

    # noise
    nm = _noise_means(rows)
    lines += ["## Error vs. noise (Fig. 2)", "",
              "Mean (median) misclassification (%) over sequences at each noise level σ (px).",
              "",
              "| Method | " + " | ".join(f"σ = {_sigma(s)}" for s in levels) + " |",
              "|---|" + "---:|" * len(levels)]
    for m in methods:
        cells = [f"{_f(nm[m][s][0])} ({_f(nm[m][s][1])})" if s in nm[m] else "–" for s in levels]
        lines.append(f"| {method_label(m)} | " + " | ".join(cells) + " |")
    lines += ["", f"![error vs noise]({FIGURES['noise']})", ""]

    # convergence
    cv = _convergence(rows)
    lines += ["## Convergence of Random Voting (Fig. 3)", "",
              "Iterations of the voting stage per run, summed over every trial it ran "
              "(LAAV: its trials from the coarse labels, the informed one and, by default, "
              "those from missing-motion starts; with `LaavParams.with_plain_rv()` also the "
              "plain RV trials it is compared with; RV: all trials from random starts), and "
              "the share of runs whose returned labelling did not come from a converged "
              "trial.", "",
              "| Method | σ (px) | Runs | Median iterations | p90 iterations | Not converged (%) |",
              "|---|---:|---:|---:|---:|---:|"]
    for m in methods:
        for s, (med, p90, nc, n) in cv[m].items():
            lines.append(f"| {method_label(m)} | {_sigma(s)} | {n} | {med:.0f} | {p90:.0f} "
                         f"| {_f(nc, 1)} |")
    lines += ["", f"![convergence]({FIGURES['convergence']})", ""]

    # repetitions
    rep = _repetitions(rows)
    lines += ["## Variation over repetitions (Fig. 4)", ""]
    if any(rep[m] for m in methods):
        lines += ["Standard deviation over seeds of a sequence's error (percentage points), "
                  "summarised over sequences.", "",
                  "| Method | σ (px) | Sequences | Mean std | Median std | Max std |",
                  "|---|---:|---:|---:|---:|---:|"]
        for m in methods:
            for s, (mean, med, mx, n) in rep[m].items():
                lines.append(f"| {method_label(m)} | {_sigma(s)} | {n} | {_f(mean)} "
                             f"| {_f(med)} | {_f(mx)} |")
    else:
        lines.append("Only one seed per sequence: run with `--seeds 2` or more to measure the "
                     "variation over repetitions. The figure shows the spread over sequences.")
    lines += ["", f"![repetitions]({FIGURES['repetitions']})", ""]

    # time
    lines += ["## Run time", "", "Wall time of one segmentation call (s), per run.", "",
              "| Method | Runs | Mean | Median | Max |", "|---|---:|---:|---:|---:|"]
    for m in methods:
        t = np.array([r["seconds"] for r in _select(rows, m)])
        lines.append(f"| {method_label(m)} | {t.size} | {t.mean():.3f} | {np.median(t):.3f} "
                     f"| {t.max():.3f} |")
    lines.append("")
    if len(shares) > 1:
        lines += _missing_section(all_rows)
    return "\n".join(lines)


def _missing_section(rows) -> list[str]:
    sigma, mt = missing_table(rows)
    shares = _shares([r for r in rows if r["noise"] == sigma])
    out = ["## Error vs. missing share (Fig. 5)", "",
           f"Misclassification (%) with a share of the F x P entries hidden by the seeded "
           f"occlusion model (`laav.synthetic.occlude`, spread 0.5, generator "
           f"`occlusion_rng(seed, sequence, share)` as in `benchmarks/missing.py`), at noise "
           f"σ = {_sigma(sigma)} px. A point left unlabelled counts as wrong; *Unlabelled* is "
           "the mean share of such points per run.", "",
           "| Method | Missing | 2 motions mean | 2 motions median | 3 motions mean "
           "| 3 motions median | All mean | All median | Sequences | Unlabelled (%) |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for m, by in mt.items():
        for share in shares:
            if share not in by:
                continue
            t = by[share]
            out.append(f"| {method_label(m)} | {_pct(share)} | {_f(t['two'][0])} "
                       f"| {_f(t['two'][1])} | {_f(t['three'][0])} | {_f(t['three'][1])} "
                       f"| {_f(t['all'][0])} | {_f(t['all'][1])} | {t['all'][2]} "
                       f"| {_f(t['unlabelled'])} |")
    out += ["", f"![error vs missing share]({MISSING_FIGURE})", ""]
    return out


# --------------------------------------------------------------------------- figures


def _new_figure(width: float, height: float, ncols: int = 1):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained", dpi=110)
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, ncols, squeeze=False)[0]
    return fig, axes


def _grouped_boxes(ax, data: dict, methods, levels, ylabel: str, title: str) -> None:
    """Box plots of ``data[(method, sigma)]`` grouped by sigma, one colour per method."""
    from matplotlib.patches import Patch

    width = 0.8 / max(1, len(methods))
    for j, m in enumerate(methods):
        pos, vals = [], []
        for i, s in enumerate(levels):
            v = data.get((m, s))
            if v is not None and len(v):
                pos.append(i + (j - (len(methods) - 1) / 2) * width)
                vals.append(v)
        if not vals:
            continue
        bp = ax.boxplot(vals, positions=pos, widths=width * 0.85, patch_artist=True,
                        manage_ticks=False, flierprops={"markersize": 3})
        for b in bp["boxes"]:
            b.set_facecolor(_COLORS.get(m, "#888888"))
            b.set_alpha(0.6)
        for med in bp["medians"]:
            med.set_color("black")
    ax.set_xticks(range(len(levels)), [_sigma(s) for s in levels])
    ax.set_xlim(-0.6, len(levels) - 0.4)
    ax.set_xlabel("noise σ (px)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    top = max((max(v) for v in data.values() if v is not None and len(v)), default=1.0)
    lo = min((min(v) for v in data.values() if v is not None and len(v)), default=0.0)
    span = (top - min(lo, 0.0)) or 1.0
    ax.set_ylim(min(lo, 0.0) - 0.03 * span, top + 0.2 * span)  # headroom for the legend
    ax.legend(handles=[Patch(facecolor=_COLORS.get(m, "#888888"), alpha=0.6,
                             label=method_label(m)) for m in methods],
              loc="upper center", ncols=max(1, len(methods)))


def write_figures(rows, out_dir: str | os.PathLike) -> list[Path]:
    """Write the three PNG figures of :data:`FIGURES` into ``out_dir`` (from the runs at
    missing share 0, or the smallest share), and :data:`MISSING_FIGURE` when ``rows`` hold
    more than one missing share; their paths."""
    out_dir = Path(out_dir)
    all_rows = rows
    rows, _ = _base(all_rows)
    methods, levels = _methods(rows), _levels(rows)
    paths = []
    if len(_shares(all_rows)) > 1:
        paths.append(_missing_figure(all_rows, out_dir / MISSING_FIGURE))

    # Fig. 2: mean error vs noise
    fig, (ax,) = _new_figure(6.4, 4.4)
    nm = _noise_means(rows)
    for m in methods:
        xs = [s for s in levels if s in nm[m]]
        ax.plot(xs, [nm[m][s][0] for s in xs], "o-", color=_COLORS.get(m), label=f"{method_label(m)} mean")
        ax.plot(xs, [nm[m][s][1] for s in xs], "s--", color=_COLORS.get(m), alpha=0.6,
                markersize=4, label=f"{method_label(m)} median")
    ax.set_xlabel("noise σ (px)")
    ax.set_ylabel("misclassification (%)")
    ax.set_title("Misclassification vs. pixel noise (Fig. 2)")
    ax.set_xticks(levels, [_sigma(s) for s in levels])
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(loc="best")
    paths.append(out_dir / FIGURES["noise"])
    fig.savefig(paths[-1])

    # Fig. 3: iterations and non-converged share
    fig, (ax1, ax2) = _new_figure(11.0, 4.4, 2)
    its = {(m, s): [r["iterations"] for r in _select(rows, m, s)] for m in methods for s in levels}
    _grouped_boxes(ax1, its, methods, levels, "voting iterations per run",
                   "Iterations (LAAV fine-tuning vs. plain RV)")
    cv = _convergence(rows)
    width = 0.8 / max(1, len(methods))
    for j, m in enumerate(methods):
        xs = [i for i, s in enumerate(levels) if s in cv[m]]
        ys = [cv[m][levels[i]][2] for i in xs]
        ax2.bar([x + (j - (len(methods) - 1) / 2) * width for x in xs], ys, width=width * 0.9,
                color=_COLORS.get(m), alpha=0.8, label=method_label(m))
    ax2.set_xticks(range(len(levels)), [_sigma(s) for s in levels])
    ax2.set_xlabel("noise σ (px)")
    ax2.set_ylabel("runs not converged (%)")
    ax2.set_ylim(0, 118)
    ax2.set_title("Non-converged share")
    ax2.grid(axis="y", alpha=0.3)
    ax2.legend(loc="upper right", ncols=max(1, len(methods)))
    fig.suptitle("Convergence of Random Voting (Fig. 3)")
    paths.append(out_dir / FIGURES["convergence"])
    fig.savefig(paths[-1])

    # Fig. 4: distribution over repetitions
    fig, (ax1, ax2) = _new_figure(11.0, 4.4, 2)
    err = {(m, s): [r["error"] for r in _select(rows, m, s)] for m in methods for s in levels}
    _grouped_boxes(ax1, err, methods, levels, "misclassification (%)",
                   "Error of every run (sequences x seeds)")
    std = {(m, s): [v[3] for v in per_sequence_errors(rows, m, s).values() if v[4] > 1]
           for m in methods for s in levels}
    if any(std.values()):
        _grouped_boxes(ax2, std, methods, levels, "std over seeds (percentage points)",
                       "Per-sequence spread over seeds")
    else:
        ax2.set_axis_off()
        ax2.text(0.5, 0.5, "one seed per sequence:\nrun with --seeds 2 or more\n"
                 "to see the spread over repetitions", ha="center", va="center",
                 transform=ax2.transAxes, fontsize=11)
        ax2.set_title("Per-sequence spread over seeds")
    fig.suptitle("Variation of the error over repetitions (Fig. 4)")
    paths.append(out_dir / FIGURES["repetitions"])
    fig.savefig(paths[-1])
    return paths


def _missing_figure(rows, path: Path) -> Path:
    """Fig. 5: mean (and median) error against the missing share, 2 and 3 motions."""
    sigma, mt = missing_table(rows)
    fig, axes = _new_figure(11.0, 4.4, 2)
    top = 0.0
    for ax, key, name in zip(axes, ("two", "three"), ("two motions", "three motions")):
        for m, by in mt.items():
            xs = [s for s in sorted(by) if by[s][key][2]]
            if not xs:
                continue
            x100 = [100 * s for s in xs]
            means = [by[s][key][0] for s in xs]
            meds = [by[s][key][1] for s in xs]
            n = by[xs[-1]][key][2]
            first = m == next(iter(mt))  # LAAV on top, RV drawn thinner with other markers
            z, lw = (3, 2.2) if first else (2, 1.4)
            ax.plot(x100, means, "o-" if first else "^-", color=_COLORS.get(m), lw=lw, zorder=z,
                    markersize=7 if first else 6, label=f"{method_label(m)} mean ({n} seq.)")
            ax.plot(x100, meds, "s--" if first else "v--", color=_COLORS.get(m), alpha=0.55,
                    lw=lw * 0.7, markersize=4, zorder=z, label=f"{method_label(m)} median")
            top = max(top, *means, *meds)
        shares = sorted({s for by in mt.values() for s in by})
        ax.set_xticks([100 * s for s in shares], [f"{100 * s:.4g}" for s in shares])
        ax.set_xlabel("entries missing (%)")
        ax.set_ylabel("misclassification (%)")
        ax.set_title(name.capitalize())
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left")
        else:
            ax.text(0.5, 0.5, f"no {name} sequences", ha="center", va="center",
                    transform=ax.transAxes)
    for ax in axes:  # one scale, so that the panels compare
        ax.set_ylim(0, max(1.0, top) * 1.15)
    fig.suptitle(f"Misclassification vs. missing entries (σ = {_sigma(sigma)} px; Fig. 5)")
    fig.savefig(path)
    return path


def write_report(out_dir: str | os.PathLike, csv_path: str | os.PathLike | None = None) -> Path:
    """Write ``report.md`` and the figures into ``out_dir`` from its ``runs.csv``."""
    out_dir = Path(out_dir)
    csv_path = Path(csv_path) if csv_path is not None else out_dir / RUNS_CSV
    rows = read_runs(csv_path)
    if rows:
        write_figures(rows, out_dir)
    path = out_dir / "report.md"
    path.write_text(report_from_csv(csv_path))
    return path
