"""Stage 2: the atom graph's edge errors and costs against a direct computation."""

from __future__ import annotations

import numpy as np
import pytest

from laav import LaavParams, atom_graph, build_atoms


def two_translations(seed: int, F: int = 12):
    """Two well separated grids of points, each moving by its own pure translation."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(np.arange(8) * 9.0, np.arange(8) * 9.0), -1).reshape(-1, 2)
    start = np.concatenate([g + 50.0, g + [400.0, 50.0]])  # 128 points, 2 motions
    labels = np.repeat([0, 1], 64)
    steps = rng.normal(0.0, 3.0, (F, 2, 2))
    steps[0] = 0.0
    shift = np.cumsum(steps, axis=0)  # (F, motion, 2)
    return start[None] + shift[:, labels], labels, shift


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_forward_backward_errors_equal_the_translation_difference(seed):
    """Pure translations: an atom's map carries another atom of its motion exactly (error
    0) and one of the other motion off by the difference of the two translations between
    the frames, so the error is the mean of |(t_a(r) - t_a(l)) - (t_b(r) - t_b(l))| over the
    graph's frame pairs, and the cost is 2 log(edge_scale / error) - cut_prior."""
    points, labels, shift = two_translations(seed)
    F = points.shape[0]
    p = LaavParams(r1=10.0, r2=20.0, cut_prior=0.5)
    atoms = build_atoms(points, p, np.random.default_rng(seed))
    graph = atom_graph(points, atoms, p)
    motion = np.array([labels[m[0]] for m in atoms.members])
    assert all((labels[m] == labels[m[0]]).all() for m in atoms.members)
    gap = max(1, F // 3)
    left = np.unique(np.round(np.linspace(0, F - 1 - gap, min(8, F - gap))).astype(int))
    right = left + gap
    cross = motion[graph.edges[:, 0]] != motion[graph.edges[:, 1]]
    assert cross.any() and (~cross).any()  # the graph joins both kinds of pairs
    d = (shift[right] - shift[left])  # (K, motion, 2): displacement between the frames
    expected = np.linalg.norm(d[:, 0] - d[:, 1], axis=-1).mean()
    np.testing.assert_allclose(graph.errors[cross], expected, rtol=1e-6)
    assert graph.errors[~cross].max() < 1e-6
    np.testing.assert_allclose(graph.costs[cross],
                               2 * np.log(p.edge_scale / expected) - p.cut_prior, rtol=1e-6)


def test_forward_backward_errors_equal_a_loop_over_edges():
    """Every edge's error against a plain loop (one edge, one direction, one frame pair at a
    time) on atoms of sizes 3 to ~100: the batches, grouped by the members' padded width
    (powers of two, not the largest atom's size), give each edge its own numbers."""
    from laav import synthetic
    from laav.graph import _GRAPH_PAIRS, forward_backward_error

    seq = synthetic.make_sequence(n_objects=2, n_frames=15, n_points=600, rng=3)
    p = LaavParams(r1=12.0, r2=60.0)
    atoms = build_atoms(seq, p, np.random.default_rng(0))
    sizes = np.array([m.size for m in atoms.members])
    assert sizes.min() < 8 and sizes.max() > 32  # several widths
    graph = atom_graph(seq, atoms, p)
    pts, F = seq.points, seq.n_frames
    gap = max(1, F // 3)
    left = np.unique(np.round(np.linspace(0, F - 1 - gap, min(_GRAPH_PAIRS, F - gap))).astype(int))

    def maps(i, l, r):
        H = np.zeros((F, 3, 3))
        H[:, :2] = atoms.affines[i]
        H[:, 2, 2] = 1.0
        fwd = H[r] @ np.linalg.inv(H[l])
        return fwd, np.linalg.inv(fwd)

    def one_way(a, b):
        errs = []
        for l in left:
            r = l + gap
            fwd, bwd = maps(a, l, r)
            x = np.c_[pts[l, atoms.members[b]], np.ones(atoms.members[b].size)]
            y = np.c_[pts[r, atoms.members[b]], np.ones(atoms.members[b].size)]
            ef = np.linalg.norm((x @ fwd.T)[:, :2] - y[:, :2], axis=1)
            eb = np.linalg.norm((y @ bwd.T)[:, :2] - x[:, :2], axis=1)
            errs.append(0.5 * (ef + eb))
        return np.mean(errs, axis=0).mean()

    want = np.array([max(one_way(a, b), one_way(b, a)) for a, b in graph.edges])
    np.testing.assert_allclose(forward_backward_error(pts, atoms, graph.edges), want, rtol=1e-9, atol=1e-12)
    np.testing.assert_array_equal(graph.errors, forward_backward_error(pts, atoms, graph.edges))
