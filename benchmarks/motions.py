"""How well :func:`laav.estimate_motions` finds the number of motions on Hopkins155.

    python benchmarks/motions.py --data DIR [--out docs/bench/motions.md] [--cache bench-out/motions]
                                 [--jobs N] [--noise 0,0.5,1] [--seeds 0,1]

1. Profiles (:func:`laav.motions.motion_profile`) of every sequence for seeds 0 and 1, and
   for seed 0 with pixel noise σ = 0.5 and 1 px added (``--noise``), cached in
   ``CACHE/profiles.npz`` (reruns only read them).
2. Every rule measured, each with its constants chosen by 5-fold cross-validation with
   folds grouped by source video (``benchmarks/cv.py``: ``X`` with ``X_g12`` ...): for
   each fold the constants best on the other four folds, their accuracy on this fold.
   Reported: the held-out share of sequences whose C is right, beside the all-data figure
   (tuned on everything, *not* held out).
3. The chosen rule (``laav.motions.decide``), fitted and cross-validated on the profiles at
   every noise level together (its levels noise-corrected, the share chosen with the other
   constants): held out per noise level against the rule fitted at σ = 0 without the
   correction, its held-out confusion table, the same for the seed-1 profiles, and LAAV's
   segmentation error with the held-out estimate against
   the true C (``laav.segment``, seed 0; runs cached in ``CACHE/segment.csv``).
4. The constants fitted on all 155 sequences, which ``laav/motions.py`` must hold.

Writes the report (machine, date, git commit), ``motions.csv`` (one row per sequence) and
``motions.png`` beside it.
"""

from __future__ import annotations

import argparse
import collections
import csv
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import cpu_model, git_commit, laav_version  # noqa: E402
from cv import folds_by_video  # noqa: E402

import laav  # noqa: E402
from laav import motions as M  # noqa: E402
from laav.bench import discover  # noqa: E402

FOLDS = 5
SEEDS = (0, 1)
#: Pixel noise σ (px) added to every sequence (laav.bench.add_pixel_noise, noise seed 0); the
#: chosen rule is fitted and cross-validated on all of them (seed-0 profiles).
NOISE = (0.0, 0.5, 1.0)
MAX_MOTIONS = 5
REG_GRID = (0.1, 1.0, 10.0)  # inverse L2 strength of the logistic step model
ONE_GRID = (0.05, 0.1, 0.2, 0.5)  # ONE_MOTION_RATIO candidates
#: FLOOR_SHARE candidates (here None means the levels as they are, no noise correction)
SHARE_GRID = (None, 0.1, 0.3, 1.0, 3.0)


# ------------------------------------------------------------------------ profiles


def _key(name: str, seed: int, sigma: float) -> str:
    return f"{name}|{seed}" if sigma == 0 else f"{name}|{seed}|noise{sigma:g}"


def _profile(args):
    """One profile (in a worker process): ``(key, arrays)``."""
    path, key, seed, sigma = args
    from laav.bench import add_pixel_noise

    seq = add_pixel_noise(laav.load_sequence(path), sigma, 0)
    t = time.perf_counter()
    pr = M.motion_profile(seq, MAX_MOTIONS, seed=seed)
    dt = time.perf_counter() - t
    return key, {"R": pr.residuals, "E": pr.epipolar, "L": pr.labels, "K": pr.coding,
                 "meta": np.array([seq.n_motions, pr.noise2, pr.n_atoms, dt, pr.sigma])}


def profiles(items, cache: Path, jobs: int = 1) -> dict:
    """Profiles of every sequence for every seed (:data:`SEEDS`) without added noise, and for
    the first seed at every pixel noise of :data:`NOISE`, cached in ``CACHE/profiles.npz``;
    ``jobs`` processes."""
    from concurrent.futures import ProcessPoolExecutor

    path = cache / "profiles.npz"
    z = dict(np.load(path)) if path.exists() else {}
    todo = [(it.path, _key(it.name, s, sg), s, sg) for sg in NOISE
            for s in (SEEDS if sg == 0 else SEEDS[:1]) for it in items  # (noise: seed 0 only)
            if f"{_key(it.name, s, sg)}|meta" not in z or z[f"{_key(it.name, s, sg)}|meta"].size < 5]
    if not todo:
        return z
    with ProcessPoolExecutor(max(1, jobs)) as pool:
        for k, (key, arrays) in enumerate(pool.map(_profile, todo, chunksize=2)):
            for part, value in arrays.items():
                z[f"{key}|{part}"] = value
            print(f"profile {k + 1}/{len(todo)} {key} {arrays['meta'][3] * 1e3:.0f} ms", file=sys.stderr,
                  flush=True)
            if (k + 1) % 20 == 0 or k + 1 == len(todo):
                cache.mkdir(parents=True, exist_ok=True)
                np.savez(path, **z)
    return z


class Data:
    def __init__(self, items, z):
        self.names = [it.name for it in items]
        self.true = {it.name: it.seq.n_motions for it in items}
        self.z = z
        self.levels = {(n, s): M.profile_levels(z[f"{n}|{s}|R"], z[f"{n}|{s}|E"],
                                                coding=z[f"{n}|{s}|K"])
                       for n in self.names for s in SEEDS}
        self.noise = {(n, s): float(z[f"{n}|{s}|meta"][1]) for n in self.names for s in SEEDS}
        # with pixel noise added (seed-0 profiles; NOISE[0] = 0 is the above)
        self.levels_at, self.noise_at, self.sigma_at = {}, {}, {}
        for n in self.names:
            for sg in NOISE:
                k = _key(n, 0, sg)
                self.levels_at[n, sg] = M.profile_levels(z[k + "|R"], z[k + "|E"], coding=z[k + "|K"])
                self.noise_at[n, sg] = float(z[k + "|meta"][1])
                self.sigma_at[n, sg] = float(z[k + "|meta"][4])
        self.fold = folds_by_video(self.names, FOLDS, 0)

    def step_levels(self, n, sigma, share):
        """Sequence ``n``'s seed-0 levels at pixel noise ``sigma`` as the later steps read them:
        noise-corrected with ``share`` (None: as they are)."""
        lv = self.levels_at[n, sigma]
        if share is None:
            return lv
        return M.noise_corrected(lv, M.noise_floors(self.sigma_at[n, sigma]), share)


# ------------------------------------------------------------------------ rules


def _first_small_gain(levels, t):
    """Smallest C whose step to C + 1 gains (subspace level ratio) less than t."""
    v = np.exp(levels[0])
    for c in range(len(v) - 1):
        if not np.isfinite(v[c + 1]) or v[c] / v[c + 1] < t:
            return c + 1
    return len(v)


def _knee(levels, beta, t1):
    lv = levels[0]
    if not np.isfinite(lv[1]) or lv[0] - lv[1] < np.log(t1):
        return 1
    sc = []
    for C in range(2, MAX_MOTIONS + 1):
        if not np.isfinite(lv[C - 1]):
            sc.append(-np.inf)
            continue
        nxt = lv[C] if np.isfinite(lv[C]) else lv[C - 1]
        sc.append((lv[C - 2] - lv[C - 1]) - beta * (lv[C - 1] - nxt))
    return int(np.argmax(sc)) + 2


def _unexplained(R, noise2, t, frac):
    fr = [(r > t * noise2).mean() if np.isfinite(r).all() else -1 for r in R]
    return next((c + 1 for c in range(len(fr)) if 0 <= fr[c] < frac), len(fr))


def fixed_rule_grids(D: Data, seed: int = 0) -> dict:
    """name -> {constant: {sequence: C}} for the rules with a grid of constants."""
    z, out = D.z, {}
    lv = {n: D.levels[n, seed] for n in D.names}
    out["always 2 (no estimate, the benchmark's prior)"] = {None: dict.fromkeys(D.names, 2)}
    out["subspace-residual ratio: first C whose next step gains < t"] = {
        t: {n: _first_small_gain(lv[n], t) for n in D.names} for t in (1.2, 1.5, 2, 2.5, 3, 4, 5, 7, 10)}
    out["knee of the subspace residual (log gain minus beta x next gain)"] = {
        (b, t1): {n: _knee(lv[n], b, t1) for n in D.names} for b in (0, 0.5, 1, 2) for t1 in (1.5, 2, 3)}
    out["unexplained share: first C with < f of points beyond t x noise (epipolar)"] = {
        (t, f): {n: _unexplained(z[f"{n}|{seed}|E"], D.noise[n, seed], t, f) for n in D.names}
        for t in (3, 10, 30, 100) for f in (0.02, 0.05, 0.08)}
    if len(SEEDS) < 2:
        return out
    # labels stable across seeds: the largest C whose two labellings agree on >= a
    agree = {n: [1 - laav.misclassification_rate(z[f"{n}|0|L"][c], z[f"{n}|1|L"][c])
                 for c in range(MAX_MOTIONS)] for n in D.names}
    out["label stability across seeds 0/1: largest C agreeing on >= a"] = {
        a: {n: max([c + 1 for c in range(MAX_MOTIONS) if agree[n][c] >= a] or [1]) for n in D.names}
        for a in (0.9, 0.95, 0.98, 0.99)}
    return out


def cv_grid(D: Data, grid: dict) -> dict:
    held, chosen = {}, []
    for k in range(FOLDS):
        train = [n for n in D.names if D.fold[n] != k]
        best = max(grid, key=lambda c: np.mean([grid[c][n] == D.true[n] for n in train]))
        chosen.append(best)
        held.update({n: grid[best][n] for n in D.names if D.fold[n] == k})
    best_all = max(grid, key=lambda c: np.mean([grid[c][n] == D.true[n] for n in D.names]))
    return {"held": held, "chosen": chosen, "all_data": grid[best_all], "best_all": best_all}


# ------------------------------------------------------------------------ the chosen rule


def step_examples(D: Data, names, share, noise=None):
    """Steps C -> C + 1 for C >= 2 (the 1 -> 2 step has its own test) of the seed-0 profiles
    at every pixel noise in ``noise``: features, label."""
    X, y = [], []
    for n in names:
        for sg in NOISE if noise is None else noise:
            lv = D.step_levels(n, sg, share)
            for C in range(2, D.true[n] + 1):
                X.append(M.step_features(lv, C))
                y.append(int(C < D.true[n]))
    return np.array(X), np.array(y)


def fit_steps(D: Data, names, reg, share, noise=None):
    from sklearn.linear_model import LogisticRegression

    X, y = step_examples(D, names, share, noise)
    clf = LogisticRegression(C=reg, max_iter=5000).fit(X, y)
    return clf.coef_[0].copy(), float(clf.intercept_[0])


def predict(D: Data, n, seed, w, b, one, share, sigma=0.0):
    """The rule's C for sequence ``n``: the profile of ``seed`` (without added noise), or the
    seed-0 profile at pixel noise ``sigma``; levels noise-corrected with ``share`` (None:
    not)."""
    if sigma == 0 and seed != 0:
        lv, noise2, sig = D.levels[n, seed], D.noise[n, seed], float(D.z[f"{n}|{seed}|meta"][4])
    else:
        lv, noise2, sig = D.levels_at[n, sigma], D.noise_at[n, sigma], D.sigma_at[n, sigma]
    if share is None:
        return M.decide(lv, noise2, MAX_MOTIONS, w, b, one)[0]
    return M.decide(lv, noise2, MAX_MOTIONS, w, b, one, sigma=sig, floor_share=share)[0]


def cv_chosen(D: Data, shares=SHARE_GRID, noise=None) -> dict:
    """The sequential test's constants (L2 strength, one-motion ratio, floor share, then the
    step weights) chosen on four folds, fitted and scored on the seed-0 profiles at every
    pixel noise of ``noise``; held out on the fifth: ``held[seed][sigma][sequence]`` (seed 1
    without added noise only)."""
    noise = NOISE if noise is None else noise
    held = {(s, sg): {} for s in SEEDS for sg in NOISE if s == 0 or sg == 0}
    folds = []

    def best_on(names):
        best = None
        for share in shares:
            for reg in REG_GRID:
                w, b = fit_steps(D, names, reg, share, noise)
                for one in ONE_GRID:
                    acc = np.mean([predict(D, n, 0, w, b, one, share, sg) == D.true[n]
                                   for n in names for sg in noise])
                    if best is None or acc > best[0]:
                        best = (acc, reg, one, share, w, b)
        return best

    for k in range(FOLDS):
        _, reg, one, share, w, b = best_on([n for n in D.names if D.fold[n] != k])
        for n in D.names:
            if D.fold[n] == k:
                for s, sg in held:
                    held[s, sg][n] = predict(D, n, s, w, b, one, share, sg)
        folds.append((k, reg, one, share, w, b, sum(D.fold[n] == k for n in D.names)))
    return {"held": held, "folds": folds, "all": best_on(D.names)}


# ------------------------------------------------------------------------ segmentation


def segment_runs(items, estimates: dict, cache: Path) -> dict:
    """(sequence, C) -> (error %, seconds) of laav.segment seed 0, cached in segment.csv."""
    path = cache / "segment.csv"
    done = {}
    if path.exists():
        with open(path, newline="") as fh:
            for r in csv.DictReader(fh):
                done[r["sequence"], int(r["C"])] = (float(r["error"]), float(r["seconds"]))
    todo = [(it, C) for it in items for C in sorted({it.seq.n_motions, estimates[it.name]})
            if (it.name, C) not in done]
    new = not path.exists()
    cache.mkdir(parents=True, exist_ok=True)
    with open(path, "a", newline="") as fh:
        w = csv.writer(fh)
        if new:
            w.writerow(("sequence", "C", "error", "seconds"))
        for k, (it, C) in enumerate(todo):
            t = time.perf_counter()
            res = laav.segment(it.seq, C, seed=0)
            dt = time.perf_counter() - t
            err = 100.0 * laav.misclassification_rate(it.seq.labels, res.labels)
            done[it.name, C] = (err, dt)
            w.writerow((it.name, C, f"{err:.4f}", f"{dt:.4f}"))
            fh.flush()
            print(f"segment {k + 1}/{len(todo)} {it.name} C={C} {err:.2f} %", file=sys.stderr, flush=True)
    return done


def timing_runs(items, cache: Path) -> dict:
    """sequence -> (estimate C, estimate s, LAAV at the true C s), timed one after the
    other (``laav.estimate_motions`` as the library runs it, candidates evaluated only as
    far as the test goes); cached in timing.csv."""
    path = cache / "timing.csv"
    done = {}
    if path.exists():
        with open(path, newline="") as fh:
            for r in csv.DictReader(fh):
                done[r["sequence"]] = (int(r["estimate"]), float(r["estimate_s"]), float(r["laav_s"]))
    todo = [it for it in items if it.name not in done]
    if todo:
        laav.estimate_motions(items[0].seq)  # warm-up
        laav.segment(items[0].seq, items[0].seq.n_motions)
    new = not path.exists()
    with open(path, "a", newline="") as fh:
        w = csv.writer(fh)
        if new:
            w.writerow(("sequence", "estimate", "estimate_s", "laav_s"))
        for k, it in enumerate(todo):
            t = time.perf_counter()
            C = laav.estimate_motions(it.seq, random_state=0).n_motions
            t1 = time.perf_counter()
            laav.segment(it.seq, it.seq.n_motions, seed=0)
            t2 = time.perf_counter()
            done[it.name] = (C, t1 - t, t2 - t1)
            w.writerow((it.name, C, f"{t1 - t:.4f}", f"{t2 - t1:.4f}"))
            fh.flush()
            print(f"timing {k + 1}/{len(todo)} {it.name}", file=sys.stderr, flush=True)
    return done


# ------------------------------------------------------------------------ report


def _acc(held, D, names=None):
    names = D.names if names is None else names
    return 100.0 * np.mean([held[n] == D.true[n] for n in names])


def _confusion(held, D) -> list[str]:
    cnt = collections.Counter((D.true[n], held[n]) for n in D.names)
    cols = list(range(1, MAX_MOTIONS + 1))
    lines = ["| true C \\ estimated | " + " | ".join(map(str, cols)) + " | right |",
             "|---|" + "---|" * (len(cols) + 1)]
    for t in (2, 3):
        tot = sum(cnt[t, c] for c in cols)
        lines.append(f"| {t} ({tot}) | " + " | ".join(str(cnt[t, c]) for c in cols)
                     + f" | {100.0 * cnt[t, t] / tot:.1f} % |")
    return lines


def plot(D: Data, held: dict, w, b, one, share, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    ax = axes[0]
    for t, col, mk in ((2, "#0072B2", "o"), (3, "#D55E00", "s")):
        ns = [n for n in D.names if D.true[n] == t]
        sc = [float(w @ M.step_features(D.step_levels(n, 0.0, share), 2) + b) for n in ns]
        x = t + np.random.default_rng(0).uniform(-0.25, 0.25, len(ns))
        ax.scatter(x, sc, s=14, c=col, marker=mk, alpha=0.7, label=f"{t} motions ({len(ns)})")
    ax.axhline(0, color="k", lw=0.8)
    ax.set_xticks([2, 3])
    ax.set_xlabel("true number of motions")
    ax.set_ylabel("score of the step 2 -> 3 (> 0: add a third motion)")
    ax.set_title("Step 2 -> 3, all-data constants (seed-0 profiles)")
    ax.legend(fontsize=8)
    ax = axes[1]
    for t, col in ((2, "#0072B2"), (3, "#D55E00")):
        ns = [n for n in D.names if D.true[n] == t]
        L = np.array([D.levels[n, 0][0] - D.levels[n, 0][0][t - 1] for n in ns])
        C = np.arange(1, L.shape[1] + 1)
        med = np.nanmedian(L, axis=0)
        q1, q3 = np.nanpercentile(L, [25, 75], axis=0)
        ax.plot(C, med, "-o", color=col, label=f"true C = {t}: median")
        ax.fill_between(C, q1, q3, color=col, alpha=0.2, label=f"true C = {t}: quartiles")
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("candidate C")
    ax.set_ylabel("log subspace level, relative to the true C")
    ax.set_title("Subspace residual level per candidate C")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    global SEEDS, NOISE
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=os.environ.get("HOPKINS155", "../shared/data/hopkins155"))
    ap.add_argument("--out", default="docs/bench/motions.md")
    ap.add_argument("--cache", default="bench-out/motions")
    ap.add_argument("--jobs", type=int, default=1, help="processes for the profiles")
    ap.add_argument("--noise", default=",".join(f"{v:g}" for v in NOISE),
                    help="pixel noise levels (px) the rule is fitted and cross-validated on; "
                         "the first must be 0")
    ap.add_argument("--seeds", default="0,1",
                    help="profile seeds (the first is the one reported; a second adds the "
                         "seed-to-seed figures and the label-stability rule)")
    args = ap.parse_args(argv)
    SEEDS = tuple(int(v) for v in args.seeds.split(","))
    NOISE = tuple(float(v) for v in args.noise.split(","))
    if NOISE[0] != 0:
        ap.error("--noise must start with 0")
    t_start = time.time()
    laav.preload()
    items = discover(args.data, log=lambda m: None)
    cache = Path(args.cache)
    D = Data(items, profiles(items, cache, args.jobs))

    alt = {name: cv_grid(D, g) for name, g in fixed_rule_grids(D).items()}
    ch = cv_chosen(D)
    before = cv_chosen(D, shares=(None,), noise=(0.0,))  # fitted without noise, no correction
    held = ch["held"][0, 0.0]
    held1 = ch["held"].get((1, 0.0))
    acc_all, reg_all, one_all, share_all, w_all, b_all = ch["all"]
    in_module = (np.allclose(w_all, M.STEP_WEIGHTS, atol=5e-3) and abs(b_all - M.STEP_BIAS) < 5e-3
                 and one_all == M.ONE_MOTION_RATIO and share_all == M.FLOOR_SHARE)
    runs = segment_runs(items, held, cache)
    timing = timing_runs(items, cache)
    lib_same = sum(timing[n][0] == predict(D, n, 0, w_all, b_all, one_all, share_all) for n in D.names)

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for it in items:
        n = it.name
        rows.append({"sequence": n, "motions": D.true[n], "fold": D.fold[n],
                     "estimate_held_out": held[n],
                     "estimate_held_out_seed1": held1[n] if held1 is not None else "",
                     **{f"estimate_held_out_noise{sg:g}": ch["held"][0, sg][n] for sg in NOISE[1:]},
                     "estimate_all_data": predict(D, n, 0, w_all, b_all, one_all, share_all),
                     "error_true_C": runs[n, D.true[n]][0], "error_estimated_C": runs[n, held[n]][0],
                     "estimate_ms": 1e3 * timing[n][1], "laav_true_C_ms": 1e3 * timing[n][2]})
    with open(out.with_suffix(".csv"), "w", newline="") as fh:
        wr = csv.DictWriter(fh, fieldnames=list(rows[0]))
        wr.writeheader()
        for r in rows:
            wr.writerow({k: (f"{v:.3f}" if isinstance(v, float) else v) for k, v in r.items()})
    plot(D, held, w_all, b_all, one_all, share_all, out.with_suffix(".png"))

    e_true = np.array([r["error_true_C"] for r in rows])
    e_est = np.array([r["error_estimated_C"] for r in rows])
    mot = np.array([r["motions"] for r in rows])
    prof = np.array([r["estimate_ms"] for r in rows])
    lt = np.array([r["laav_true_C_ms"] for r in rows])
    L = [f"# Number of motions on Hopkins155 ({time.strftime('%Y-%m-%d %H:%M %Z')})", "",
         f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores (shared with other jobs; "
         f"timings in one process; profiles in --jobs processes), {platform.system()} {platform.release()}",
         f"- Software: Python {platform.python_version()}, numpy {np.__version__}, laav "
         f"{laav_version()} (git {git_commit()})",
         f"- Data: {len(items)} sequences of {args.data} (120 with 2 motions, 35 with 3)",
         f"- Made by `benchmarks/motions.py` in {time.time() - t_start:.0f} s (cached profiles and "
         "runs are reused); per-sequence figures in [`motions.csv`](motions.csv).",
         "- Protocol: every constant chosen by 5-fold cross-validation, folds grouped by source "
         "video (`benchmarks/cv.py`: `X` with `X_g12`, `X_g13`, `X_g23`); **held out** = the "
         "accuracy of each fold under the constants chosen on the other four. *All data* = the "
         "best constants on all 155 (tuned on what it reports: not a held-out figure).",
         "", "## The chosen rule: `laav.estimate_motions` (sequential test)", "",
         f"Held-out share of sequences whose C is right: **{_acc(held, D):.1f} %** "
         f"(2 motions {_acc(held, D, [n for n in D.names if D.true[n] == 2]):.1f} %, 3 motions "
         f"{_acc(held, D, [n for n in D.names if D.true[n] == 3]):.1f} %); target >= 90 %: "
         f"**{'met' if _acc(held, D) >= 90 else 'not met'}**. "
         + (f"With the seed-1 profiles (same fold constants): {_acc(held1, D):.1f} %; the two "
            f"seeds give the same C on {100.0 * np.mean([held[n] == held1[n] for n in D.names]):.1f} "
            "% of the sequences." if held1 is not None else "Seed-0 profiles only (`--seeds 0`)."),
         "", "**Under pixel noise** (N(0, σ²) on every coordinate, `laav.bench.add_pixel_noise`, "
         "noise seed 0; seed-0 profiles): the rule is fitted and its constants chosen on the "
         f"sequences at σ = {', '.join(f'{v:g}' for v in NOISE)} px together, its levels noise-"
         "corrected (`laav.motions.noise_corrected`: each level's noise floor, 2σ̂² subspace and "
         "σ̂² epipolar, σ̂ the tracks' measured noise, counted at the chosen share). Held out, "
         "% of sequences right (2 / 3 motions), against the rule fitted without noise and "
         "without the correction (the protocol until 2026-12-06), under the same folds:", "",
         "| σ (px) | chosen rule | fitted at σ = 0, no correction |", "|---|---|---|"]
    two = [n for n in D.names if D.true[n] == 2]
    three = [n for n in D.names if D.true[n] == 3]
    for sg in NOISE:
        a, b0 = ch["held"][0, sg], before["held"][0, sg]
        L.append(f"| {sg:g} | **{_acc(a, D):.1f}** ({_acc(a, D, two):.0f} / {_acc(a, D, three):.0f}) | "
                 f"{_acc(b0, D):.1f} ({_acc(b0, D, two):.0f} / {_acc(b0, D, three):.0f}) |")
    L += ["", "Confusion (held out, seed 0, σ = 0):", "", *_confusion(held, D), "",
          "Per fold, the constants chosen on the other folds:", "",
          "| fold | sequences | L2 inverse strength | one-motion ratio | floor share | step weights "
          "(gain subspace, epipolar; next gain subspace, epipolar; coding length saved) | bias | "
          "held-out right (σ = 0) |",
          "|---|---|---|---|---|---|---|---|"]
    for k, reg, one, share, w, b, nk in ch["folds"]:
        ns = [n for n in D.names if D.fold[n] == k]
        L.append(f"| {k} | {nk} | {reg:g} | {one:g} | {share} | {', '.join(f'{v:.2f}' for v in w)} | "
                 f"{b:.2f} | {_acc(held, D, ns):.1f} % |")
    L += ["", f"All data: {acc_all * 100:.1f} % right over the {len(NOISE)} noise levels (not held "
          f"out) with L2 inverse strength {reg_all:g}, one-motion ratio {one_all:g}, floor share "
          f"{share_all}, weights {np.round(w_all, 4).tolist()}, "
          f"bias {b_all:.4f}: the constants in `laav/motions.py` "
          f"({'they match' if in_module else 'WARNING: the module holds other values'}).",
          "", "LAAV's error with the estimated C (held-out estimates, `laav.segment` seed 0; a "
          "point in a motion with no true partner counts as wrong):", "",
          "| C used | 2 motions mean % | 3 motions mean % | all mean % | median % |", "|---|---|---|---|---|"]
    for lab, e in (("true C", e_true), ("estimated C (held out)", e_est)):
        L.append(f"| {lab} | {e[mot == 2].mean():.2f} | {e[mot == 3].mean():.2f} | {e.mean():.2f} | "
                 f"{np.median(e):.2f} |")
    L += ["", f"Time (one process, each sequence's two runs back to back): `laav.estimate_motions` "
          f"median {np.median(prof):.0f} ms (p90 {np.percentile(prof, 90):.0f} ms), `laav.segment` "
          f"at the true C median {np.median(lt):.0f} ms (p90 {np.percentile(lt, 90):.0f} ms); per "
          f"sequence the estimate costs {np.median(prof / lt):.2f}x one LAAV run (median; "
          f"2 motions {np.median((prof / lt)[mot == 2]):.2f}x, 3 motions "
          f"{np.median((prof / lt)[mot == 3]):.2f}x). `segment(seq, \"auto\")` pays both. The "
          f"library's estimate (candidates evaluated only as far as the test goes) equals the "
          f"all-data rule on the cached full profiles on {lib_same} of {len(D.names)} sequences.",
          "", "![score of the step 2 -> 3 per sequence; subspace level per candidate C](motions.png)",
          "", "## Every rule measured", "",
          "Same folds, σ = 0 (no added noise); the profile (labellings per C) is the same for all "
          "rules.", "",
          "| rule | held out % right | 2 / 3 motions held out | all data % (tuned on it) | "
          "constants chosen per fold |", "|---|---|---|---|---|"]
    all0 = {n: predict(D, n, 0, w_all, b_all, one_all, share_all) for n in D.names}  # (σ = 0)
    L.append(f"| **sequential test (chosen)** | **{_acc(held, D):.1f}** | {_acc(held, D, two):.0f} / "
             f"{_acc(held, D, three):.0f} | {_acc(all0, D):.1f} | "
             f"{', '.join(f'({r:g}, {o:g}, {sh})' for _, r, o, sh, *_ in ch['folds'])} |")
    for name, r in sorted(alt.items(), key=lambda kv: -_acc(kv[1]["held"], D)):
        L.append(f"| {name} | {_acc(r['held'], D):.1f} | {_acc(r['held'], D, two):.0f} / "
                 f"{_acc(r['held'], D, three):.0f} | {_acc(r['all_data'], D):.1f} | "
                 f"{', '.join(str(c) for c in r['chosen'])} |")
    out.write_text("\n".join(L) + "\n")
    print(f"report: {out}")
    print(f"held-out {_acc(held, D):.1f} %; all-data constants: reg {reg_all:g} one {one_all:g} "
          f"share {share_all} "
          f"STEP_WEIGHTS = ({', '.join(f'{v:.4f}' for v in w_all)}) STEP_BIAS = {b_all:.4f}"
          + ("" if in_module else "  (module differs)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
