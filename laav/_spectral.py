"""Spectral clustering of a co-association affinity without the P x P matrix.

Random Voting's consensus (:func:`laav.rv.consensus`) splits the co-association of T
labellings, ``A = mean_t [l_t(i) == l_t(j)] + 1e-6``, by scikit-learn's
``SpectralClustering(affinity="precomputed", assign_labels="cluster_qr")``. Built
densely that is 8 bytes x P^2 (plus T bytes x P^2 for the comparison) and a shift-invert
LU factorisation of a P x P matrix, O(P^3): 3.2 GB and minutes at 20,000 points.

``A`` is low rank: ``A = H H^T / T + eps 11^T`` with ``H`` the (P, T x C) one-hot matrix
of the labellings. :func:`coassociation_clustering` solves the same eigenproblem as
scikit-learn (the normalised Laplacian of ``A`` with its diagonal ignored, as
``scipy.sparse.csgraph.laplacian`` does; its C smallest eigenvectors, divided by the
square root of the degrees; the same ``cluster_qr``), with Lanczos iterations (ARPACK,
same start vector from the same random state) whose products with ``A`` cost O(P T).
The eigenvectors agree with scikit-learn's to the solvers' precision, and ``cluster_qr``
does not depend on their signs, order or rotation within the subspace.
"""

from __future__ import annotations

import numpy as np

__all__ = ["coassociation_clustering", "cluster_qr", "affinity_clustering"]

_EPS = 1e-6  # the constant laav.rv.consensus adds to the affinity (connects the graph)


def cluster_qr(vectors: np.ndarray) -> np.ndarray:
    """scikit-learn's ``cluster_qr`` (Damle, Minden & Ying 2019), copied: labels of the
    rows of a spectral embedding (P, k)."""
    from scipy.linalg import qr, svd

    k = vectors.shape[1]
    _, _, piv = qr(vectors.T, pivoting=True)
    ut, _, v = svd(vectors[piv[:k], :].T)
    vectors = abs(np.dot(vectors, np.dot(ut, v.conj())))
    return vectors.argmax(axis=1)


def affinity_clustering(affinity: np.ndarray, n_clusters: int) -> np.ndarray:
    """Spectral clustering of a small dense affinity: scikit-learn's
    ``SpectralClustering(affinity="precomputed", assign_labels="cluster_qr")`` without
    importing scikit-learn (0.3-2 s on first use, felt in the explorer's first move).

    The same steps: the normalised Laplacian of the affinity (its diagonal ignored, as
    ``scipy.sparse.csgraph.laplacian`` does), its ``n_clusters`` smallest eigenvectors
    divided by the square root of the degrees, ``cluster_qr``. scikit-learn finds the
    eigenvectors with ARPACK (shift-invert, a start vector from its ``random_state``);
    here a dense symmetric solver does, which for the n <= a few dozen nodes of the coarse
    stage's affinity is exact and cheaper. ``cluster_qr`` depends only on the subspace they
    span, so the labels are scikit-learn's unless the n_clusters-th and next eigenvalues tie
    (``benchmarks/spectral_check.py``: all 5,616 Hopkins155 merges compared agree;
    ``tests/test_coarse.py`` compares random affinities).

    Parameters
    ----------
    affinity : ndarray of shape (n, n)
        Symmetric, non-negative.
    n_clusters : int

    Returns
    -------
    ndarray of shape (n,), int64
    """
    from scipy.linalg import eigh
    from scipy.sparse.csgraph import laplacian

    A = np.asarray(affinity, dtype=np.float64)
    A = 0.5 * (A + A.T)  # exact for a symmetric input, as scikit-learn's check_symmetric
    L, dd = laplacian(A, normed=True, return_diag=True)
    np.fill_diagonal(L, 1.0)  # scikit-learn's _set_diag (an isolated node's 0 becomes 1)
    _, vecs = eigh(L, check_finite=False)
    return cluster_qr(vecs[:, : int(n_clusters)] / dd[:, None]).astype(np.int64)


def coassociation_clustering(labels: np.ndarray, n_clusters: int, random_state: int,
                             eps: float = _EPS) -> np.ndarray:
    """Spectral clustering (``cluster_qr``) of the co-association of labellings.

    Parameters
    ----------
    labels : ndarray of shape (T, P), int
        T labellings of P points (any non-negative integers).
    n_clusters : int
    random_state : int
        Seeds ARPACK's start vector, as scikit-learn's ``random_state`` does.
    eps : float
        Added to every entry of the affinity.

    Returns
    -------
    ndarray of shape (P,), int64
    """
    from scipy.sparse import csr_matrix
    from scipy.sparse.linalg import LinearOperator, eigsh

    labs = np.asarray(labels, dtype=np.int64)
    T, P = labs.shape
    k = int(n_clusters)
    width = int(labs.max()) + 1
    cols = (labs + width * np.arange(T)[:, None]).T.ravel()  # point-major
    H = csr_matrix((np.full(T * P, 1.0), cols, np.arange(0, T * P + 1, T)), shape=(P, T * width))
    HT = H.T.tocsr()
    size = np.asarray(H.sum(axis=0)).ravel()  # members of each (trial, label)
    # degrees without the diagonal (1 + eps): scipy's normalised Laplacian ignores it
    deg = (H @ size) / T + eps * P - (1.0 + eps)
    isolated = deg == 0
    dd = np.sqrt(np.where(isolated, 1.0, deg))

    def matvec(x):  # D^-1/2 (A - diag A) D^-1/2 x
        x = np.ravel(x)
        y = x / dd
        z = (H @ (HT @ y)) / T + eps * y.sum() - (1.0 + eps) * y
        return z / dd

    rs = np.random.RandomState(random_state)
    v0 = rs.uniform(-1, 1, P)  # scikit-learn's _init_arpack_v0
    if P <= 4 * k + 1:  # too small for ARPACK: the dense matrix is tiny
        Nm = np.stack([matvec(e) for e in np.eye(P)], axis=1)
        vals, vecs = np.linalg.eigh(Nm)
        vecs = vecs[:, -k:]
    else:
        op = LinearOperator((P, P), matvec=matvec, dtype=np.float64)
        vals, vecs = eigsh(op, k=k, which="LA", v0=v0, tol=0)
    # the largest eigenvalues of D^-1/2 A0 D^-1/2 are the smallest of the Laplacian
    embedding = vecs / dd[:, None]
    return cluster_qr(embedding).astype(np.int64)
