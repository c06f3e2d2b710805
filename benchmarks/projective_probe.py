"""Probe (not a stage of laav): can projective rigidity find a small motion?

Issue 12's ``small_motion`` family (one car with 3 % of the points, a perspective
background) fails because the default's candidates split the background and the joint
score prefers that. This script measures, for each scene, outside the package:

* every labelling the default's model selection polished (its candidates: LAAV's informed
  trial and plain RV's), recorded by wrapping ``laav.selection.Polished`` (internal);
* **projective missing-motion starts** from the default's result: for each pair of its
  motions (g, h), the two as one, a rank-4 *projective* factorization of every remaining
  motion (8 evenly spaced frames, Sturm-Triggs depths from the fundamental matrices of
  consecutive frames, 10 refinement iterations, refitted twice on its best 80 %), its
  points above 5 x max(sqrt(2) sigma, 1.4826 x median residual) as the C-th motion; each
  start fine-tuned by LAAV's informed trial (``rv_select="none"``);
* each candidate's **projective cost**: the mean over points of ``log(1 + (r / s)^2)``,
  ``r`` the point's RMS reprojection error under its motion's projective fit, ``s`` =
  sqrt(2) max(sigma, 0.01 px), sigma = ``laav.noise.estimate_noise``;
* a **gate**: the default result's *perspective strength*, the median over points of
  ``log((a^2 + s^2) / (r^2 + s^2))``, ``a`` the rank-4 affine residual: above 3 (the
  projective model explains the motions far better than the affine one, relative to the
  noise) the candidates are chosen by joint score + w x projective cost, else the
  default's result stands.

It prints, per data set, the default's mean error, the gated and the forced (no gate)
selection for w in 10 / 30, and the oracle (best candidate). Measured 2026-12-02
(benchmarks/TUNING.md, "Projective rigidity for small motions"); nothing here is used by
``laav``.

    python benchmarks/projective_probe.py --family small_motion --seeds 0-29 [--noise 0.2]
    python benchmarks/projective_probe.py --hopkins --seeds 0,1 --every 1 [--jobs 2]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import cpu_model, git_commit  # noqa: E402

import laav  # noqa: E402
import laav.selection as selection_module  # noqa: E402
import laav.synthetic  # noqa: E402
import laav.voting as voting_module  # noqa: E402
from laav.geometry import fit_fundamental  # noqa: E402
from laav.metrics import misclassification_rate  # noqa: E402
from laav.noise import estimate_noise  # noqa: E402

K_FRAMES, ITERS, GATE, OUTLIER_K, WEIGHTS = 8, 10, 3.0, 5.0, (10, 30)


def _frames(F: int) -> np.ndarray:
    return np.unique(np.round(np.linspace(0, F - 1, min(K_FRAMES, F))).astype(int))


def projective_fit(x: np.ndarray):
    """Rank-4 projective factorization of x (F, n, 2), n >= 8: (frames, centres, scales,
    cameras (K, 3, 4)) in each frame's Hartley-normalised coordinates."""
    fr = _frames(x.shape[0])
    x = x[fr]
    K, n, _ = x.shape
    c = x.mean(1, keepdims=True)
    s = (np.sqrt(2) / np.maximum(np.sqrt(((x - c) ** 2).sum(-1).mean(1, keepdims=True)), 1e-12))[..., None]
    xn = (x - c) * s
    hp = np.concatenate([xn, np.ones((K, n, 1))], -1)  # (K, n, 3)
    lam = np.ones((K, n))
    Fm = fit_fundamental(xn[:-1], xn[1:])  # x_{i+1}^T F x_i = 0
    e = np.linalg.svd(np.swapaxes(Fm, -1, -2))[2][:, -1]  # epipoles in frame i + 1
    for i in range(K - 1):  # Sturm-Triggs: depths from the epipolar geometry
        ex = np.cross(e[i][None], hp[i + 1])
        lam[i + 1] = (ex * (hp[i] @ Fm[i].T)).sum(1) / np.maximum((ex * ex).sum(1), 1e-300) * lam[i]
    lam *= np.sign(np.median(lam, axis=1, keepdims=True) + 1e-300)
    h = hp.transpose(0, 2, 1)  # (K, 3, n)
    hh = (h * h).sum(1)
    for _ in range(ITERS):
        lam = lam / np.sqrt((lam * lam).sum(0, keepdims=True) / K)
        lam = lam / np.sqrt((lam * lam).sum(1, keepdims=True) / n)
        W = (lam[:, None, :] * h).reshape(3 * K, n)
        U = np.linalg.eigh(W @ W.T)[1][:, -4:]
        Wr = (U @ (U.T @ W)).reshape(K, 3, n)
        new = (Wr * h).sum(1) / hh
        lam = np.where(np.abs(new) > 1e-9, new, lam)
    return fr, c, s, U.reshape(K, 3, 4)


def reprojection(x: np.ndarray, fit) -> np.ndarray:
    """RMS reprojection error (px) of every point of x (F, n, 2) under ``fit``'s cameras,
    each point placed by linear triangulation."""
    fr, c, s, M = fit
    xn = (x[fr] - c) * s
    n = xn.shape[1]
    A = np.concatenate([xn[..., 0:1, None] * M[:, None, 2:3] - M[:, None, 0:1],
                        xn[..., 1:2, None] * M[:, None, 2:3] - M[:, None, 1:2]], axis=2)
    A = A.transpose(1, 0, 2, 3).reshape(n, -1, 4)
    X = np.linalg.eigh(np.swapaxes(A, 1, 2) @ A)[1][:, :, 0]
    p = np.einsum("kij,nj->kni", M, X)
    z = p[..., 2:3]
    err = (p[..., :2] / np.where(np.abs(z) > 1e-12, z, 1e-12) - xn) / s
    return np.sqrt((err ** 2).sum(-1).mean(0))


def residuals(points, labels, robust=False) -> np.ndarray:
    """Each point's reprojection error under its motion's projective fit (0 for a motion
    under 8 points); ``robust``: the fit refitted twice on its best 80 %."""
    out = np.zeros(points.shape[1])
    for g in np.unique(labels):
        m = np.flatnonzero(labels == g)
        if m.size < 8:
            continue
        keep = np.arange(m.size)
        for _ in range(3 if robust else 1):
            r = reprojection(points[:, m], projective_fit(points[:, m[keep]]))
            keep = np.argsort(r)[: max(8, int(0.8 * m.size))]
        out[m] = r
    return out


def affine_residuals(points, labels) -> np.ndarray:
    out = np.zeros(points.shape[1])
    fr = _frames(points.shape[0])
    for g in np.unique(labels):
        m = labels == g
        W = points[fr][:, m].transpose(0, 2, 1).reshape(2 * fr.size, -1)
        W = W - W.mean(1, keepdims=True)
        U, S, Vt = np.linalg.svd(W, full_matrices=False)
        R = W - (U[:, :3] * S[:3]) @ Vt[:3]
        out[m] = np.sqrt((R.reshape(fr.size, 2, -1) ** 2).sum(1).mean(0))
    return out


def projective_starts(points, labels, C, sigma):
    starts = []
    for g in range(C):
        for h in range(g + 1, C):
            M = np.where(labels == h, g, labels)
            M = np.where(M > h, M - 1, M)
            r = residuals(points, M, robust=True)
            thr = np.zeros_like(r)
            for k in range(C - 1):
                mk = M == k
                thr[mk] = OUTLIER_K * max(np.sqrt(2) * sigma, 1.4826 * np.median(r[mk]))
            new = r > thr
            if 8 <= new.sum() <= new.size - 8:
                starts.append(np.where(new, C - 1, M))
    return starts


def scene(job):
    kind, name, seed, noise = job
    if kind == "hopkins":
        seq = laav.load_sequence(Path(HOPKINS) / name)
        lseed = seed
    else:
        seq = laav.synthetic.make_family(name, rng=seed)
        lseed = 0
    if noise:
        rng = np.random.default_rng([seed, 12345])
        seq = laav.Sequence(seq.points + rng.normal(0, noise, seq.points.shape), seq.labels,
                            name=seq.name)
    return seq, lseed


def job_run(job) -> dict:
    seq, lseed = scene(job)
    P, T, C = seq.points, seq.labels, seq.n_motions
    polished = []
    real = selection_module.Polished.__init__

    def record(self, *a, **k):
        real(self, *a, **k)
        polished.append(self)

    selection_module.Polished.__init__ = record
    try:
        result = laav.segment(seq, C, seed=lseed)
    finally:
        selection_module.Polished.__init__ = real
    sigma = estimate_noise(P)
    params = laav.LaavParams()
    run = params.for_noise(sigma)
    labellings = {pol.final()[0].tobytes(): pol.final()[0] for pol in polished}
    for j, start in enumerate(projective_starts(P, result.labels, C, sigma)):
        v = laav.random_voting(seq, C, params.replace(rv_select="none"),
                               np.random.default_rng([lseed, 99, j]), init_labels=start)
        labellings[v.labels.tobytes()] = v.labels
    s = np.sqrt(2) * max(sigma, 0.01)
    cands = []
    for L in labellings.values():
        js = voting_module.joint_score(P, L, C, run) / P.shape[1]
        cost = float(np.mean(np.log1p((residuals(P, L) / s) ** 2)))
        cands.append((misclassification_rate(T, L), js if np.isfinite(js) else 1e9, cost))
    a, r = affine_residuals(P, result.labels), residuals(P, result.labels)
    strength = float(np.median(np.log((a ** 2 + s ** 2) / (r ** 2 + s ** 2))))
    return {"C": C, "default": misclassification_rate(T, result.labels), "cands": cands,
            "strength": strength}


def summarise(rows: list) -> dict:
    out = {"runs": len(rows), "default": 100 * np.mean([r["default"] for r in rows]),
           "gate on": int(sum(r["strength"] > GATE for r in rows)),
           "oracle": 100 * np.mean([min(c[0] for c in r["cands"]) for r in rows])}
    for w in WEIGHTS:
        for gated in (True, False):
            errs = []
            for r in rows:
                if gated and r["strength"] <= GATE:
                    errs.append(r["default"])
                else:
                    errs.append(min(r["cands"], key=lambda c: c[1] + w * c[2])[0])
            out[f"{'gated' if gated else 'forced'} w={w}"] = 100 * np.mean(errs)
    return out


def _seeds(text: str) -> list:
    if "-" in text:
        a, b = text.split("-")
        return list(range(int(a), int(b) + 1))
    return [int(s) for s in text.split(",")]


HOPKINS = os.environ.get("HOPKINS155", str(Path(__file__).resolve().parents[2] / "shared/data/hopkins155"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--family", help="a laav.synthetic family (scene seeds = --seeds)")
    ap.add_argument("--hopkins", action="store_true", help="Hopkins155 (LAAV seeds = --seeds)")
    ap.add_argument("--seeds", default="0-9")
    ap.add_argument("--noise", type=float, default=0.0, help="pixel noise sigma added, px")
    ap.add_argument("--every", type=int, default=1, help="Hopkins155: every k-th sequence")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    if args.hopkins:
        names = sorted(d.name for d in Path(HOPKINS).iterdir() if d.is_dir() and d.name != "dancing")
        jobs = [("hopkins", n, s, args.noise) for s in _seeds(args.seeds) for n in names[::args.every]]
        what = f"Hopkins155 ({len(names[::args.every])} sequences), LAAV seeds {args.seeds}"
    else:
        jobs = [("family", args.family, s, args.noise) for s in _seeds(args.seeds)]
        what = f"make_family({args.family!r}), scene seeds {args.seeds}, LAAV seed 0"
    t0 = time.perf_counter()
    if args.jobs > 1:
        with ProcessPoolExecutor(args.jobs) as ex:
            rows = list(ex.map(job_run, jobs, chunksize=1))
    else:
        rows = [job_run(j) for j in jobs]
    res = summarise(rows)
    lines = [f"# Projective rigidity probe ({time.strftime('%Y-%m-%d %H:%M %Z')})", "",
             f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, {platform.system()} "
             f"{platform.release()}; git {git_commit()}; {time.perf_counter() - t0:.0f} s",
             f"- Data: {what}, pixel noise sigma = {args.noise:g} px", "",
             "| " + " | ".join(res) + " |", "|" + "---|" * len(res),
             "| " + " | ".join(f"{v:.2f}" if isinstance(v, float) else str(v) for v in res.values()) + " |"]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
