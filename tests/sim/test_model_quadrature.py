"""Gauss rules of discrete measures: exact for polynomials of degree 2m − 1 (the defining property), positive
weights and nodes inside the points' range, the measure itself when it has no more points than nodes."""

import numpy as np
import pytest

from uwlab.model.quadrature import gauss_rule, prefix_gauss_rules


@pytest.mark.parametrize("m", [1, 4, 8, 24])
def test_a_gauss_rule_sums_polynomials_of_degree_2m_minus_1_exactly(m):
    rng = np.random.default_rng(m)
    x = np.sort(rng.uniform(2.0, 7.0, 300))
    w = rng.uniform(0.5, 3.0, 300)
    nodes, weights = gauss_rule(x, w, m)
    assert np.all(weights > 0) and x[0] < nodes.min() and nodes.max() < x[-1]
    t = (x - 4.5) / 2.5  # Chebyshev polynomials on the points' range: well conditioned up to high degree
    tn = (nodes - 4.5) / 2.5
    for degree in range(2 * m):
        exact = w @ np.cos(degree * np.arccos(t))
        assert weights @ np.cos(degree * np.arccos(tn)) == pytest.approx(exact, abs=1e-12 * w.sum())
    too_high = w @ np.cos(2 * m * np.arccos(t))
    assert abs(weights @ np.cos(2 * m * np.arccos(tn)) - too_high) > 1e-6 * w.sum()


def test_a_measure_with_no_more_points_than_nodes_is_its_own_rule():
    nodes, weights = gauss_rule(np.array([1.0, 2.0, 5.0]), np.array([2.0, 1.0, 4.0]), 5)
    assert nodes.tolist() == [1.0, 2.0, 5.0, 1.0, 1.0] and weights.tolist() == [2.0, 1.0, 4.0, 0.0, 0.0]


def test_prefix_rules_sum_each_prefix():
    x = np.linspace(0.0, 1.0, 40) ** 2
    w = np.arange(1.0, 41.0)
    nodes, weights = prefix_gauss_rules(x, w, 6)
    assert nodes.shape == weights.shape == (41, 6) and np.all(weights[0] == 0)
    for p in range(1, 41):
        assert weights[p] @ np.exp(-3 * nodes[p]) == pytest.approx(w[:p] @ np.exp(-3 * x[:p]), rel=1e-9)
