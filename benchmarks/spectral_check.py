"""The coarse merge's spectral clustering against scikit-learn's, on every Hopkins155 merge.

``laav._spectral.affinity_clustering`` replaced scikit-learn's
``SpectralClustering(affinity="precomputed", assign_labels="cluster_qr")`` in
:func:`laav.merge_models` (the pipeline then imports no scikit-learn). For every sequence,
seeds ``--seeds``, the default and paper presets, 2C / 3C / 4C fine models and λ 1 / 3 / 10,
this runs stages 1-4 and clusters the merge's affinity Z (``Coarse.affinity``) both ways;
it prints the number of merges compared and every one whose partition differs (labels up
to a permutation: the merge renumbers them canonically). Run on 2026-12-01 (git 4ff3819, and
again with this script the same day): 5,616 merges, none different.

    python benchmarks/spectral_check.py [--data DIR] [--seeds 2] [--part K --parts N]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402

import numpy as np  # noqa: E402

import laav  # noqa: E402
from laav._spectral import affinity_clustering  # noqa: E402
from laav.atoms import Neighbourhoods, build_atoms  # noqa: E402
from laav.coarse import merge_models  # noqa: E402
from laav.graph import atom_graph  # noqa: E402
from laav.multicut import solve_multicut  # noqa: E402
from laav.pipeline import _stage_rngs  # noqa: E402


def main(argv=None) -> int:
    from sklearn.cluster import SpectralClustering

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get("HOPKINS155", "../shared/data/hopkins155"))
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--part", type=int, default=0)
    ap.add_argument("--parts", type=int, default=1)
    a = ap.parse_args(argv)
    n = differ = 0
    for i, path in enumerate(laav.find_truth_files(a.data)):
        if i % a.parts != a.part:
            continue
        seq = laav.load_sequence(path)
        C = seq.n_motions
        D = Neighbourhoods(seq.points)
        for seed in range(a.seeds):
            rng = _stage_rngs(seed)
            for base in (laav.LaavParams(), laav.LaavParams.paper()):
                atoms = build_atoms(seq, base, np.random.default_rng(rng["atoms"]), D)
                graph = atom_graph(seq, atoms, base, D)
                for k in (2, 3, 4):
                    mc = solve_multicut(graph, k * C)
                    for lam in (1.0, 3.0, 10.0):
                        p = base.replace(lam=lam)
                        if p.merge_for(True) != "epipolar" or mc.n_models <= C:
                            continue
                        Z = merge_models(seq, atoms, mc, C, p,
                                         np.random.default_rng(rng["coarse"])).affinity + 1e-9
                        ours = affinity_clustering(Z, C)
                        ref = SpectralClustering(n_clusters=C, affinity="precomputed",
                                                 assign_labels="cluster_qr",
                                                 random_state=0).fit_predict(Z)
                        n += 1
                        if laav.misclassification_rate(ref, ours) > 0:
                            differ += 1
                            print(f"DIFFERENT {seq.name} seed {seed} {k}C lam {lam}: {ours} {ref}",
                                  flush=True)
    print(f"{n} merges compared, {differ} different")
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
