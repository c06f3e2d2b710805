"""Exports: labels CSV, parameters JSON, and a PNG of the views drawn server-side with matplotlib."""

from __future__ import annotations

import io
import json

import numpy as np

import laav

from . import views as V

__all__ = ["labels_csv", "params_json", "views_png", "views_figure"]

#: bokeh marker names (views.MOTION_MARKERS) -> matplotlib markers
_MPL_MARKERS = {"circle": "o", "square": "s", "triangle": "^", "diamond": "D", "inverted_triangle": "v",
                "hex": "h"}


def labels_csv(seq: laav.Sequence, result: laav.LaavResult, point_ids=None) -> str:
    """0-based labels, first columns ``point,label`` as ``laav segment`` writes (see
    :func:`explorer.views.labels_table`; ``point_ids``: the file's number of each point)."""
    return V.labels_table(seq, result, point_ids)


def params_json(seq: laav.Sequence, result: laav.LaavResult) -> str:
    """The parameters, seed and C of ``result`` (loadable with ``LaavParams(**d["params"])``)."""
    d = {"sequence": seq.name, "n_motions": int(result.n_motions), "seed": int(result.seed),
         "params": result.params.to_dict()}
    return json.dumps(d, indent=2) + "\n"


def views_png(seq: laav.Sequence, result: laav.LaavResult, frame: int, mode: str,
              step: int | None = None, plain: laav.Voting | None = None, dpi: int = 100) -> bytes:
    """The views as a PNG (see :func:`views_figure`)."""
    import logging

    buf = io.BytesIO()
    # matplotlib's mathtext looks for TeX fonts that a Debian install lacks and logs a
    # "findfont: ... not found" line for each (nine on the first export) while it falls back to
    # DejaVu Sans, which it draws with: noise in the terminal of laav-explore, not an error
    fonts = logging.getLogger("matplotlib.font_manager")
    level = fonts.level
    fonts.setLevel(logging.ERROR)
    try:
        views_figure(seq, result, frame, mode, step, plain, dpi).savefig(buf, format="png")
    finally:
        fonts.setLevel(level)
    return buf.getvalue()


def views_figure(seq: laav.Sequence, result: laav.LaavResult, frame: int, mode: str,
                 step: int | None = None, plain: laav.Voting | None = None, dpi: int = 100):
    """A 2x2 PNG: frame view, multicut graph, affinity Z, RV convergence, under a header
    naming the sequence, C, the seed, every parameter off its default and each stage's error;
    every panel has its legend or colour bar."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.collections import LineCollection
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    from .state import Settings, non_defaults

    style = V.point_style(seq, result, mode, plain)
    fs = V.frame_sources(seq, result, frame, style)
    x0, x1, y0, y1 = V.view_extent(seq.extent())
    fig = Figure(figsize=(13, 10.8), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    num = V.stage_numbers(seq, result, plain)
    settings = Settings(result.params, int(result.seed), int(result.n_motions))
    off = non_defaults(settings, seq.n_motions if seq.labels is not None else None,
                       seq.is_complete)
    errs = ", ".join(f"{st} {V._pct(num[f'error_{st}'])}" for st in ("fine", "coarse", "final"))
    if plain is not None:
        errs += f"; plain RV {V._pct(num['error_plain'])}"
    p = result.params
    fig.suptitle(
        f"LAAV on {seq.name}: {seq.n_points} points, {seq.n_frames} frames, C = {result.n_motions}, "
        f"seed {result.seed}\n"
        f"R1 = {p.r1:g}, R2 = {p.r2:g}, λ = {p.lam:g}, fine models = {result.multicut.n_models}, "
        f"α = {p.rv_alpha:g}, "
        f"iteration cap {p.rv_max_iter}; not at the defaults: {', '.join(off) if off else 'none'}\n"
        + (f"errors vs ground truth: {errs} (fine and coarse on the points in atoms)"
           if seq.labels is not None else "no ground truth: errors cannot be scored"),
        fontsize=11)
    axs = fig.subplots(2, 2)
    # the colouring drawn (the final labels when ground truth is asked for and missing)
    mode_name = V.COLOR_LABELS.get(style["mode"], mode)

    ax = axs[0, 0]
    t = fs["trails"]
    if len(t["x0"]):
        segs = np.stack([np.c_[t["x0"], t["y0"]], np.c_[t["x1"], t["y1"]]], axis=1)
        ax.add_collection(LineCollection(segs, colors=list(t["color"]), linewidths=0.8, alpha=0.5))
    a = fs["atoms"]
    for x, y, r1, r2 in zip(a["x"], a["y"], a["r1"], a["r2"]):
        ax.add_patch(Circle((x, y), r1, fill=False, lw=0.5, alpha=0.5, color="0.3"))
        ax.add_patch(Circle((x, y), r2, fill=False, lw=0.4, alpha=0.25, ls="--", color="0.3"))
    p = fs["points"]
    labels = np.asarray(p["label"])
    for lab in dict.fromkeys(labels.tolist()):  # one legend entry per label, in order
        sel = labels == lab
        mk = _MPL_MARKERS.get(str(np.asarray(p["marker"])[sel][0]), "o")
        ax.scatter(np.asarray(p["x"])[sel], np.asarray(p["y"])[sel], c=list(np.asarray(p["color"])[sel]),
                   marker=mk, s=16, edgecolors="#333333", linewidths=0.3, label=lab)
    u = fs["unassigned"]
    # a cross inside each point, white or dark by its fill, as on the page (views.cross_colors)
    ax.scatter(u["x"], u["y"], marker="x", c=list(np.asarray(u["cross"])), s=6, lw=0.7)
    ax.scatter([], [], marker="x", c=V.NO_ATOM_DARK, s=20, lw=1.2, label="in no atom")
    e = fs["errors"]
    if seq.labels is not None:  # (without ground truth nothing is marked, as on the page)
        ax.scatter(e["x"], e["y"], facecolors="none", edgecolors=V.ERROR_MARK, s=80, lw=1.8,
                   label="misclassified")
    ax.set(xlim=(x0, x1), ylim=(y1, y0), aspect="equal", xlabel="x (px)", ylabel="y (px, down)",
           title=f"Frame {frame}, coloured by {mode_name}")
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)

    ax = axs[0, 1]
    K = len(result.multicut.contractions)
    step = K + 1 if step is None else step
    g = V.graph_sources(result, frame, step, V.fine_colors(seq, result))
    lim = V.cost_limit(result)
    from matplotlib.colors import ListedColormap
    cmap = ListedColormap(V.EDGE_PALETTE)  # the page's colours
    for key, ls, lw in (("joined", "-", 1.6), ("cut", "--", 1.0)):
        d = g[key]
        if len(d["x0"]):
            segs = np.stack([np.c_[d["x0"], d["y0"]], np.c_[d["x1"], d["y1"]]], axis=1)
            cols = cmap(np.clip((np.asarray(d["cost"]) + lim) / (2 * lim), 0, 1))
            ax.add_collection(LineCollection(segs, colors=cols, linewidths=lw, linestyles=ls))
    n = g["nodes"]
    ax.scatter(n["x"], n["y"], c=list(n["color"]), s=np.asarray(n["size"]) ** 2 / 2.5,
               edgecolors="k", linewidths=0.5, zorder=3)
    ax.set(xlim=(x0, x1), ylim=(y1, y0), aspect="equal", xlabel="x (px)", ylabel="y (px, down)",
           title=f"Multicut graph of {result.atoms.n_atoms} atoms (colour = fine model)")
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color="0.3", lw=1.6, label="kept by the multicut (solid)"),
               Line2D([], [], color="0.3", lw=1.0, ls="--", label="cut by the multicut (dashed)"),
               Line2D([], [], color=cmap(0.95), lw=2, label="edge cost > 0 (join)"),
               Line2D([], [], color=cmap(0.05), lw=2, label="edge cost < 0 (cut)")]
    fc = V.fine_colors(seq, result)
    mot = V.fine_motions(seq, result)
    handles += [Line2D([], [], ls="", marker="o", mfc=c, mec="k", label=f"f{j + 1} → motion {m + 1}")
                for j, (c, m) in enumerate(zip(fc.tolist(), mot.tolist()))][:12]
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, borderaxespad=0)

    ax = axs[1, 0]
    cells, factors = V.z_sources(result, seq, fit_votes=False)
    n = len(factors)
    shown = np.asarray(cells["z"], dtype=float).reshape(n, n)
    margins = V.shows_margins(result)  # card 3's map: the joint merge's margins, or Z
    top = V.margin_top(shown)
    if margins:
        from matplotlib.colors import ListedColormap

        cmap = ListedColormap(V.MARGIN_PALETTE).with_extremes(bad=V.UNDECIDED)
        im = ax.imshow(np.ma.masked_invalid(shown), cmap=cmap, vmin=-top, vmax=top)
    else:
        im = ax.imshow(shown, cmap="Blues", vmin=0, vmax=1)
    colors = np.asarray(cells["text_color"]).reshape(n, n)
    for (i, j), text in np.ndenumerate(np.asarray(cells["text"], dtype=object).reshape(n, n)):
        ax.text(j, i, text, ha="center", va="center", fontsize=8, color=colors[i, j])
    ax.set_xticks(range(n), factors, rotation=45)
    ax.set_yticks(range(n), factors)
    bar = fig.colorbar(im, ax=ax, shrink=0.8)
    if margins:
        from matplotlib.patches import Rectangle

        where, labels = V.margin_ticks(top)
        bar.set_ticks(where, labels=labels)
        for k in np.flatnonzero(V.close_calls(cells)):  # outlined, as in card 3
            ax.add_patch(Rectangle((k % n - 0.43, k // n - 0.43), 0.86, 0.86, fill=False, ec="k", lw=1.5))
        ax.set_title("Joint merge margins (nats; > 0: joined; outlined: "
                     f"< {V.CLOSE_CALL_NATS:g})\nfN→Mk: fine model N joined motion k", fontsize=10)
    else:
        ax.set_title("Affinity Z (fN→Mk: fine model N joined motion k)")

    ax = axs[1, 1]
    runs = ((result.voting, V.own_trial_name(result.voting), "-"), (plain, V.RV_PLAIN_NAME, "--"))
    for vt, name, ls in runs:  # (named as in card 4)
        r = V.rv_sources(vt)
        if len(r["iteration"]):
            ax.semilogy(r["iteration"], r["changed_plot"], ls, color="#222222" if ls == "-" else "#8C8C8C",
                        label=name)
    ax.set(xlabel="iteration", ylabel="labels changed (0 drawn at 0.5)",
           title="Random Voting convergence")
    ax.legend(fontsize=8)

    return fig
