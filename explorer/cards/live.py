"""Frame moves drawn in the browser: the views that follow the frame (card 1's points,
trails, atoms and marks; card 2's nodes and edges) are sent once per result as *templates*
(:func:`explorer.views.frame_templates`, :func:`~explorer.views.graph_templates`) with the
sequence's tracks (every frame's positions, once per sequence), and a bokeh ``CustomJS``
makes a frame's rows from them (the rules of :func:`explorer.views.instantiate`, in
JavaScript) whenever the frame player moves, in the page: no server round trip.

The server still learns the frame (the player's value), keeps its own copy of each view at
that frame (the same rows, made in Python: exports, tests and the next diff read them) and
updates what truly needs it (the URL, the video frame behind the points, the compare card,
the 3-D view); the copies' changes are not sent (:meth:`LiveFrames.models`: the app drops
their events from the batch). A draw of a result, colouring or GAEC step that changed a
track, a template, a text format or the frame bumps a generation number (``meta``), sent
last: the page then makes its views again, at the frame its player shows; a draw that
changed none of them sends nothing (the page's views are already those).

Above :data:`LIVE_MAX_ENTRIES` tracked positions (frames x points) the tracks are not sent
and a frame move is drawn by the server, as before (docs/bench/explorer_browser_latency.md).
"""

from __future__ import annotations

import os

import numpy as np
from bokeh.core.property.vectorization import Field
from bokeh.models import ColumnDataSource, CustomJS, GlyphRenderer

from .. import views as V
from .base import set_data

#: Largest frames x points whose tracks go to the browser (x, y as float32: 8 bytes per
#: entry, plus one byte where a sequence is incomplete). 5,000 points x 100 frames (the
#: largest the explorer was measured with) is 500,000: 4 MB, once per sequence.
#: ``$LAAV_EXPLORE_LIVE_MAX`` overrides it (0: every frame move drawn by the server, as
#: before; for measurements).
LIVE_MAX_ENTRIES = 1_000_000

#: The page's side, once per page: glyph renderers on the overlay level (:meth:`LiveFrames.repaint_alone`)
#: clipped to the plot's frame. Bokeh clips every renderer of the image, underlay and glyph levels
#: to the frame, but on the overlay canvas only those whose view asks for it (``needs_clip``),
#: which a glyph renderer's does not: zoomed or panned, their points were drawn over the axes.
#: The getter is set on the glyph renderers' view class and answers True for the overlay level
#: only (other levels as before); the overlay glyphs already drawn are then drawn again.
#: ``clip``: a list holding one such renderer, or empty. Run when the document is ready (a
#: served page), by every derive, and when the figure's range changes (a zoom before either).
JS_CLIP_OVERLAYS = r"""
for (const r of clip) {
  const proto = r.default_view ? r.default_view.prototype : null;
  if (proto && !Object.prototype.hasOwnProperty.call(proto, 'needs_clip')) {
    Object.defineProperty(proto, 'needs_clip', {configurable: true,
                                                get() { return this.model.level === 'overlay'; }});
    const doc = r.document, index = window.Bokeh ? Bokeh.index : null;
    if (doc && index) for (const m of doc.all_models) {
      if (m.level !== 'overlay' || m.default_view !== r.default_view) continue;
      const v = index.find_one(m);
      if (v) v.request_paint();
    }
  }
  break;
}
"""

#: The page's side: make every registered view at the frame shown. ``cb_data.frame`` is the
#: player's value when the player moved; after a draw of the server (``meta`` changed) the
#: page's last frame, else the server's.
JS_DERIVE = r"""
if (cb_data && cb_data.frame !== undefined && cb_data.frame !== null) meta._laav_frame = cb_data.frame;
const m = meta.data;
if (!m.live || Number(m.live[0]) !== 1) return;
let f = meta._laav_frame;
if (f === undefined || f === null) f = Number(m.frame[0]);
f = Math.round(Number(f)) || 0;
const tr = {};
for (const name of Object.keys(tracks)) {
  const d = tracks[name].data;
  const F = Number(m[name + '_f'][0]) || 0, N = Number(m[name + '_n'][0]) || 0;
  const x = d.x || [], y = d.y || [], v = d.v;
  const ok = x.length === F * N && y.length === F * N;
  const seen = name === 'atoms'
    ? (t, i) => i >= 0 && i < N && Number.isFinite(x[t * N + i]) && Number.isFinite(y[t * N + i])
    : (v && v.length === F * N) ? (t, i) => i >= 0 && i < N && v[t * N + i] !== 0
    : (t, i) => i >= 0 && i < N;
  tr[name] = {F: ok ? F : 0, N, x, y, seen};
}
const like = (c, n) => c instanceof Float64Array ? new Float64Array(n) : c instanceof Float32Array
  ? new Float32Array(n) : c instanceof Int32Array ? new Int32Array(n) : c instanceof Uint32Array
  ? new Uint32Array(n) : c instanceof Int16Array ? new Int16Array(n) : c instanceof Uint16Array
  ? new Uint16Array(n) : c instanceof Int8Array ? new Int8Array(n) : c instanceof Uint8Array
  ? new Uint8Array(n) : new Array(n);
const out = {};
for (const [name, src, tsrc, spec] of views) {
  const t = tr[spec.track], T = tsrc.data, a = T['@a'] || [], b = T['@b'];
  const fc = Math.min(Math.max(f, 0), t.F - 1);
  const keeps = [];
  let total = 0;
  if (t.F > 0) {
    for (const blk of spec.blocks) {
      const fa = fc + (blk.da || 0), fb = fc + (blk.db || 0);
      if (fa < 0 || fa >= t.F || (b !== undefined && (fb < 0 || fb >= t.F))) continue;
      const k = [];
      for (let r = 0; r < a.length; r++) {
        if (t.seen(fa, a[r]) && (b === undefined || t.seen(fb, b[r]))) k.push(r);
      }
      keeps.push([blk, fa, fb, k]);
      total += k.length;
    }
  }
  const d = {};
  for (const [col, [anchor, dim]] of Object.entries(spec.coords)) {
    const ids = anchor === '_a' ? a : b, c = dim === 0 ? t.x : t.y, o = new Float64Array(total);
    let j = 0;
    for (const [, fa, fb, k] of keeps) {
      const base = (anchor === '_a' ? fa : fb) * t.N;
      for (const r of k) o[j++] = c[base + ids[r]];
    }
    d[col] = o;
  }
  const bconst = [];
  for (const blk of spec.blocks) for (const n of Object.keys(blk.const || {}))
    if (!bconst.includes(n)) bconst.push(n);
  for (const n of bconst) {
    const o = new Float64Array(total);
    let j = 0;
    for (const [blk, , , k] of keeps) {
      const val = blk.const && blk.const[n] !== undefined ? blk.const[n] : NaN;
      for (let q = 0; q < k.length; q++) o[j++] = val;
    }
    d[n] = o;
  }
  const whole = keeps.length === 1 && keeps[0][3].length === a.length;
  for (const key of Object.keys(T)) {
    if (key[0] !== '=') continue;
    const c = T[key];
    if (whole) { d[key.slice(1)] = c; continue; }
    const o = like(c, total);
    let j = 0;
    for (const [, , , k] of keeps) for (const r of k) o[j++] = c[r];
    d[key.slice(1)] = o;
  }
  out[name] = [src, d, fc];
}
const fp = tr.points ? Math.min(Math.max(f, 0), tr.points.F - 1) : f;
const fill = (fmt) => String(fmt).replace(/\{(f|n|k)(?::(\w+)(?:\.(\w+))?)?\}/g, (s, kind, name, col) => {
  if (kind === 'f') return String(fp);
  const o = out[name];
  if (!o) return s;
  const d = o[1], ks = Object.keys(d);
  if (kind === 'n') return String(ks.length ? d[ks[0]].length : 0);
  return String(new Set(Array.from(d[col] || [])).size);
});
// texts (titles, legend labels) before the data: a legend repainted while a glyph's new
// data is being mapped read past its old colours (see Explorer.hold)
// (only when they change: a legend rebuilds its entries, blank, on any change of an item,
// and draws their glyphs only when its figure's main layer is painted, which a frame move
// no longer does: repaint_alone; so a legend whose label changed is asked to repaint)
const repaint = new Set();
for (const [key, model, attr, wrap, owner] of texts) {
  const fmt = m['t_' + key];
  if (fmt === undefined || fmt.length === 0) continue;
  const text = fill(fmt[0]);
  const cur = model[attr];
  if ((cur !== null && typeof cur === 'object' ? cur.value : cur) === text) continue;
  model.setv({[attr]: wrap ? {value: text} : text}, {sync: false});
  if (owner) repaint.add(owner);
}
const index = (cb_context && cb_context.index) || (window.Bokeh && Bokeh.index);
for (const owner of index ? repaint : []) {
  const view = index.find_one(owner);
  if (view) view.request_paint();
}
for (const name of Object.keys(out)) out[name][0].setv({data: out[name][1]}, {sync: false});
"""


def packed_colors(col: np.ndarray) -> np.ndarray:
    """``col`` with CSS hex colours (``#rrggbb``, every entry: the explorer's palettes) as
    bokeh's packed RGBA, uint32 ``0xRRGGBBFF``; any other column unchanged.

    The page's copy of a view is made again at every frame move and result
    (:data:`JS_DERIVE`), and bokeh then maps its colour columns again: from strings, a CSS
    parse per point and glyph (about 6 ms of a frame move's ~30 ms of script on the demo,
    measured with a CPU profile); a uint32 column is taken as it is. Only the templates the
    page reads are packed; the server's own views keep the strings (exports, tests, the
    server-drawn frames above :data:`LIVE_MAX_ENTRIES`). :func:`unpacked_colors` undoes it."""
    col = np.asarray(col)
    if col.dtype.kind not in "UO" or col.size == 0:
        return col
    text = col.astype(str)
    if not (np.char.startswith(text, "#") & (np.char.str_len(text) == 7)).all():
        return col
    try:
        rgb = V.hex_to_rgb(text).astype(np.uint32)
    except ValueError:  # not hex after all
        return col
    return (rgb[:, 0] << 24) | (rgb[:, 1] << 16) | (rgb[:, 2] << 8) | np.uint32(255)


def unpacked_colors(col: np.ndarray) -> np.ndarray:
    """:func:`packed_colors` undone: ``#RRGGBB`` strings for a uint32 column, anything else
    unchanged."""
    col = np.asarray(col)
    if col.dtype != np.uint32:
        return col
    return np.char.mod("#%06X", (col >> np.uint32(8)).astype(np.int64))


def legend_rows(tpl: dict, spec: dict, by: str | None = None) -> dict:
    """The rows a legend's stand-in renderer holds for view template ``tpl`` (see
    :meth:`LiveFrames.detach_legend`): its first row (one per distinct value of column ``by``,
    for a legend listing them), the last block's constants (the newest trail step), no
    position (NaN: drawn nowhere in the plot)."""
    consts = {k: np.asarray(v) for k, v in tpl.items() if k not in ("_a", "_b")}
    n = len(np.asarray(tpl["_a"]))
    if by is not None and by in consts:
        _, rows = np.unique(consts[by], return_index=True)
        rows = np.sort(rows)
    else:
        rows = np.arange(min(n, 1))
    out = {c: np.full(rows.size, np.nan) for c in spec["coords"]}
    last = spec["blocks"][-1].get("const", {}) if spec["blocks"] else {}
    for name, val in last.items():
        out[name] = np.full(rows.size, float(val))
    for name, col in consts.items():
        out[name] = col[rows]
    return out


def _swatch_needs_no_row(proxy, spec: dict) -> bool:
    """Whether legend stand-in ``proxy`` draws the same swatch whatever its row holds: its
    glyph reads no column but the view's coordinates (``spec``'s)."""
    return not (_columns_read(proxy.glyph) - set(spec["coords"]))


def _columns_read(glyph) -> set:
    """The data columns ``glyph``'s properties read (its fields; a constant is none)."""
    used = set()
    for name in glyph.dataspecs():
        spec = glyph.lookup(name).get_value(glyph)  # a Field or a Value
        if isinstance(spec, Field):
            used.add(spec.field)
        elif isinstance(spec, dict) and "field" in spec:
            used.add(spec["field"])
    return used


class LiveFrames:
    """The browser's copy of the views that follow the frame, and the script making them.

    Cards register their sources (:meth:`add`) and texts (:meth:`add_text`) when built; the
    app then links the frame player (:meth:`link`). A card's draw gives its templates
    (:meth:`template`) and text formats (:meth:`text`); the app ends every draw with
    :meth:`commit`."""

    def __init__(self, max_entries: int | None = None) -> None:
        if max_entries is None:
            try:
                max_entries = int(os.environ.get("LAAV_EXPLORE_LIVE_MAX", LIVE_MAX_ENTRIES))
            except ValueError:
                max_entries = LIVE_MAX_ENTRIES
        self.max_entries = int(max_entries)
        self.tracks = {"points": ColumnDataSource({"x": [], "y": []}),
                       "atoms": ColumnDataSource({"x": [], "y": []})}
        self.meta = ColumnDataSource({"gen": [0], "frame": [0], "live": [0], "points_f": [0],
                                      "points_n": [0], "atoms_f": [0], "atoms_n": [0]})
        self.views: dict[str, tuple] = {}  # name -> (shown source, template source, spec)
        self.texts: dict[str, tuple] = {}  # key -> (model, attribute, as a value spec)
        self.derive: CustomJS | None = None
        self.overlays: list = []  # renderers drawn on their figure's overlay canvas
        self.enabled = False  # the tracks of the sequence shown are in the page
        self._seq = None  # the sequence whose tracks were set
        self._atoms = None  # the graph whose atom track was set
        self._fmt: dict[str, str] = {}
        self._proxies: dict[str, list] = {}  # view name -> [(legend's stand-in renderer, by)]
        self._stand_in: dict[int, GlyphRenderer] = {}  # id(renderer) -> its legend stand-in
        self._shape = {"points": (0, 0), "atoms": (0, 0)}
        #: a track or template changed since the last :meth:`commit` (formats, shapes and the
        #: frame it compares itself): the next commit has the page remake its views
        self._changed = True

    # ------------------------------------------------------------------ building
    def repaint_alone(self, fig, renderers) -> None:
        """Draw ``renderers`` and ``fig``'s title on the figure's overlay canvas: bokeh repaints
        only that layer when they change (a frame move), not the axes, grid, legend and colour
        bar of its primary canvas, which were most of a frame move's painting (measured:
        docs/bench/explorer_browser_latency.md). They are drawn in their order, over the image
        and grid as before, and clipped to the plot's frame by the page (:data:`JS_CLIP_OVERLAYS`,
        run by :meth:`clip_script` when the document is ready and by every derive)."""
        for r in renderers:
            r.level = "overlay"
        fig.title.level = "overlay"
        self.overlays.extend(renderers)
        if renderers:  # a zoom or pan before the document is ready or a derive ran (notebooks)
            clip = CustomJS(args={"clip": list(renderers[:1])}, code=JS_CLIP_OVERLAYS)
            for rng in (fig.x_range, fig.y_range):
                rng.js_on_change("start", clip)

    def clip_script(self) -> CustomJS:
        """The script that has the page clip the overlay glyphs to their plot's frame
        (:data:`JS_CLIP_OVERLAYS`), for the document's ``document_ready`` event."""
        return CustomJS(args={"clip": self.overlays[:1]}, code=JS_CLIP_OVERLAYS)

    def add(self, name: str, src: ColumnDataSource, spec: dict) -> None:
        """Make ``src`` in the page from the template ``name`` (a word: letters, digits, _)
        by ``spec`` (:func:`explorer.views.frame_specs`)."""
        self.views[name] = (src, ColumnDataSource({"@a": []}), spec)

    def add_text(self, key: str, model, attr: str, legend=None) -> None:
        """Fill ``model.attr`` from the format :meth:`text` gives ``key``; ``legend``: the
        Legend ``model`` (a LegendItem, whose label takes ``{"value": text}``) belongs to."""
        if model is not None:
            self.texts[key] = (model, attr, legend is not None, legend)

    def detach_legend(self, fig) -> None:
        """``fig``'s legend items drawn from stand-ins of the registered views' renderers.

        Bokeh's legend rebuilds itself whenever anything its items reference changes, data
        sources included, and draws its entries' glyphs only with the figure's main canvas:
        with the moving renderers in its items, every frame move repainted the whole figure
        (axes, grid, legend), most of a frame move's painting. The stand-ins (a copy of each
        glyph, rows made once per result by :func:`legend_rows`, drawn nowhere) keep the
        legend's look; a click on an entry shows or hides the real renderers as before (a
        callback on the legend: nothing the items reference points back to them)."""
        by_src = {id(src): name for name, (src, _, _) in self.views.items()}
        legend = fig.legend[0]
        pairs = []
        for item in legend.items:
            label = item.label
            by = label.get("field") if isinstance(label, dict) else getattr(label, "field", None)
            reps = []
            for r in item.renderers:
                name = by_src.get(id(getattr(r, "data_source", None)))
                if name is None:
                    reps.append(r)
                    continue
                # only the columns its glyph reads (and the legend's field): the page's other
                # readers of the views (tests, benchmarks) do not take it for one
                by_name = by if isinstance(by, str) else None
                used = _columns_read(r.glyph)
                cols = {c: [] for c in r.data_source.data if c in used or c == by_name}
                proxy = GlyphRenderer(data_source=ColumnDataSource(cols), glyph=r.glyph.clone(),
                                      visible=r.visible)
                fig.renderers.append(proxy)
                pairs.append([proxy, r])
                self._proxies.setdefault(name, []).append((proxy, by if isinstance(by, str) else None))
                self._stand_in[id(r)] = proxy
                reps.append(proxy)
            item.renderers = reps
        if pairs:  # (the legend toggles its items' renderers after it sends the click)
            legend.js_on_event("legend_item_click", CustomJS(args={"pairs": pairs}, code=(
                "Promise.resolve().then(() => { for (const [p, r] of pairs) r.visible = p.visible; });")))

    def stand_in(self, renderer):
        """The legend's stand-in for ``renderer`` (itself when it has none)."""
        return self._stand_in.get(id(renderer), renderer)

    def link(self, player) -> CustomJS:
        """Build the script and run it when ``player`` (a panel Player) moves or the server
        draws (``meta`` changes)."""
        self.derive = CustomJS(
            args={"meta": self.meta, "tracks": dict(self.tracks),
                  "views": [[n, src, tsrc, spec] for n, (src, tsrc, spec) in self.views.items()],
                  "texts": [[k, m, a, w, o] for k, (m, a, w, o) in self.texts.items()],
                  "clip": self.overlays[:1]},
            code=JS_CLIP_OVERLAYS + JS_DERIVE)
        self.meta.js_on_change("data", self.derive)
        player.jscallback(value="derive.execute(cb_obj, {frame: cb_obj.value});",
                          args={"derive": self.derive})
        return self.derive

    # ------------------------------------------------------------------ drawing (document thread)
    def set_sequence(self, seq) -> bool:
        """The points' track of ``seq`` (sent once per sequence); False when ``seq`` is above
        :attr:`max_entries` (then nothing is sent and the server draws every frame)."""
        if seq is self._seq:
            return self.enabled
        self._seq = seq
        self._changed = True
        F, P = seq.n_frames, seq.n_points
        self.enabled = F * P <= self.max_entries
        if not self.enabled:
            set_data(self.tracks["points"], {"x": np.zeros(0, np.float32), "y": np.zeros(0, np.float32)})
            self._shape["points"] = (0, 0)
            for _, tsrc, _ in self.views.values():
                set_data(tsrc, {"@a": np.zeros(0, np.int32)})
            return False
        xy, vis = V.point_track(seq)
        d = {"x": xy[..., 0].astype(np.float32).ravel(), "y": xy[..., 1].astype(np.float32).ravel()}
        if vis is not None:
            d["v"] = vis.astype(np.uint8).ravel()
        self.tracks["points"].data = d
        self._shape["points"] = (F, P)
        return True

    def set_atoms(self, result) -> None:
        """The atoms' track (``AtomGraph.positions``) of ``result`` (once per graph)."""
        if not self.enabled or result.graph is self._atoms:
            return
        self._atoms = result.graph
        self._changed = True
        pos, _ = V.atom_track(result)
        self.tracks["atoms"].data = {"x": pos[..., 0].astype(np.float32).ravel(),
                                     "y": pos[..., 1].astype(np.float32).ravel()}
        self._shape["atoms"] = pos.shape[:2]

    def template(self, name: str, tpl: dict) -> None:
        """The template of view ``name`` (sent only when it differs from the page's)."""
        _, tsrc, spec = self.views[name]
        for proxy, by in self._proxies.get(name, ()):
            rows = legend_rows(tpl, spec, by)
            cols = {c: rows[c] for c in proxy.data_source.data if c in rows}
            if not any(len(v) for v in cols.values()) and _swatch_needs_no_row(proxy, spec):
                # no row (no point misclassified, none changed): the entry keeps its swatch,
                # drawn from one row at no position, as its glyph's look is all constants
                cols = {c: np.full(1, np.nan) for c in cols}
            set_data(proxy.data_source, cols)
        if not self.enabled:
            return
        if set_data(tsrc, {("@" + k[1:]) if k in ("_a", "_b") else "=" + k: packed_colors(v)
                           for k, v in tpl.items()}):
            self._changed = True

    def text(self, key: str, fmt: str, frame: int, sources: dict) -> str:
        """Remember ``key``'s format (:func:`explorer.views.fill_text`) and return it filled
        at ``frame`` with ``sources`` (the views made at that frame, by name)."""
        self._fmt[key] = fmt
        return V.fill_text(fmt, frame, sources)

    def commit(self, frame: int) -> bool:
        """End of a draw: the generation, frame, shapes and formats (sent last in the batch:
        the page then makes its views again). When nothing the page makes its views from
        changed since the last commit (same tracks, templates, formats and frame: e.g. a λ
        move that merged the fine models as before), nothing is sent and the page's views,
        already those, are neither remade nor repainted. Returns whether it was sent."""
        old = self.meta.data
        (pf, pn_), (af, an) = self._shape["points"], self._shape["atoms"]
        data = {"gen": [int(old["gen"][0]) + 1], "frame": [int(frame)], "live": [int(self.enabled)],
                "points_f": [int(pf)], "points_n": [int(pn_)], "atoms_f": [int(af)], "atoms_n": [int(an)],
                **{"t_" + k: [v] for k, v in self._fmt.items()}}
        if not self._changed and set(data) == set(old) and all(
                list(old[k]) == data[k] for k in data if k != "gen"):
            return False
        self._changed = False
        self.meta.data = data
        return True

    @property
    def active(self) -> bool:
        """The page makes the views that follow the frame (the server's copies need not be sent)."""
        return self.enabled and self.derive is not None

    def models(self, frame_move: bool = False) -> list:
        """What the page makes itself: the views' sources and texts (and, for a frame move,
        ``meta``: its new frame needs no redraw). Empty when not :attr:`active`."""
        if not self.active:
            return []
        out = [src for src, _, _ in self.views.values()] + [t[0] for t in self.texts.values()]
        return out + [self.meta] if frame_move else out
