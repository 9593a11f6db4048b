"""Gauss quadrature rules of discrete measures: a sum over many points replaced by a sum over a few nodes.

A discrete measure μ = Σ_i w_i δ(x − x_i) (w_i > 0, N distinct x_i) has, for any m ≤ N, a unique m-node rule
Σ_j λ_j f(ξ_j) that equals Σ_i w_i f(x_i) for every polynomial f of degree ≤ 2m − 1, with nodes inside
[min x, max x] and positive weights λ_j (the Gauss rule of μ; Gautschi, "Orthogonal Polynomials: Computation and
Approximation", Oxford 2004, §1.4 and §2.2.3.1). For a smooth f the rule's error falls like that of the best
polynomial approximation of degree 2m − 1 on the points. When m ≥ N the rule is the measure itself (exact).

The rule comes from the Jacobi matrix of μ — the recurrence coefficients of its orthonormal polynomials —
computed by the Lanczos process on diag(x) started from √w (Gautschi 2004, §2.2.3.2, with full
reorthogonalisation, which keeps it stable for any m ≤ N), and the Golub–Welsch eigen-decomposition (Golub &
Welsch, Math. Comp. 23 (1969) 221): nodes are the eigenvalues, λ_j = μ(1) · v_j[0]² with v_j the normalised
eigenvectors.
"""

from __future__ import annotations

import numpy as np


def gauss_rule(x: np.ndarray, w: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, weights) of the m-node Gauss rule of Σ_i w_i δ(x − x_i) (x distinct, w > 0), sorted by node.

    With m ≥ len(x) the points and weights themselves, padded to m with zero weights at x[0].

    >>> nodes, weights = gauss_rule(np.arange(10.0), np.ones(10), 2)
    >>> bool(np.isclose(weights @ nodes**3, np.sum(np.arange(10.0)**3)))
    True
    """
    x = np.asarray(x, float)
    w = np.asarray(w, float)
    if m >= x.size:
        pad = m - x.size
        return np.concatenate([x, np.full(pad, x[0])]), np.concatenate([w, np.zeros(pad)])
    lo, hi = x.min(), x.max()
    t = (2 * x - lo - hi) / (hi - lo)  # on [−1, 1]: the recurrence stays well scaled
    q = np.empty((m, x.size))
    q[0] = np.sqrt(w / w.sum())
    alpha, beta = np.empty(m), np.empty(m - 1)
    for j in range(m):
        v = t * q[j]
        alpha[j] = v @ q[j]
        v -= q[: j + 1].T @ (q[: j + 1] @ v)
        v -= q[: j + 1].T @ (q[: j + 1] @ v)
        if j + 1 < m:
            beta[j] = np.sqrt(v @ v)
            q[j + 1] = v / beta[j]
    values, vectors = np.linalg.eigh(np.diag(alpha) + np.diag(beta, 1) + np.diag(beta, -1))
    return lo + (values + 1) * (hi - lo) / 2, w.sum() * vectors[0] ** 2


def prefix_gauss_rules(x: np.ndarray, w: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Gauss rules of every prefix of a discrete measure: (nodes, weights), each (len(x) + 1, m); row p is the
    m-node rule of the first p points (x sorted, distinct), row 0 has zero weights (the empty sum)."""
    x = np.asarray(x, float)
    nodes = np.full((x.size + 1, m), x[0])
    weights = np.zeros((x.size + 1, m))
    for p in range(1, x.size + 1):
        nodes[p], weights[p] = gauss_rule(x[:p], w[:p], m)
    return nodes, weights
