"""Tests of spacepose.tails (NEES gates with Student-t tails), against scipy's distributions."""

import math

import numpy as np
import pytest
from scipy import stats

from spacepose.tails import nees_cdf, nees_gate


def _reference_cdf(d2, dims, nu):
    if nu == 0.0:
        return stats.chi2.cdf(d2, dims)
    return stats.f.cdf(d2 * nu / ((nu - 2.0) * dims), dims, nu)


@pytest.mark.parametrize("dims", [1, 2, 3, 6])
@pytest.mark.parametrize("nu", [0.0, 2.2, 3.59, 10.0, 300.0])
def test_the_cdf_is_scipys(dims, nu):
    for d2 in (1e-3, 0.3, 1.0, 2.9, 11.3, 26.8, 120.0, 1e5):
        assert nees_cdf(d2, dims, nu) == pytest.approx(_reference_cdf(d2, dims, nu), abs=1e-12)


@pytest.mark.parametrize("dims", [1, 3])
@pytest.mark.parametrize("nu", [0.0, 2.5, 3.59, 30.0])
@pytest.mark.parametrize("p", [0.05, 0.5, 0.95, 0.99, 0.997, 0.99999])
def test_the_gate_is_scipys_quantile(dims, nu, p):
    ref = stats.chi2.ppf(p, dims) if nu == 0.0 else (nu - 2.0) / nu * dims * stats.f.ppf(p, dims, nu)
    assert nees_gate(p, dims, nu) == pytest.approx(ref, rel=1e-8)


def test_known_values_and_the_normal_limit():
    assert nees_gate(0.99, 3, 0.0) == pytest.approx(11.3449, abs=1e-4)
    assert nees_gate(0.997, 3, 0.0) == pytest.approx(13.9314, abs=1e-3)
    # heavy tails widen the far gates; many degrees of freedom give chi-square's back
    assert nees_gate(0.99, 3, 3.59) > 2.0 * nees_gate(0.99, 3, 0.0)
    assert nees_gate(0.99, 3, 1e4) == pytest.approx(nees_gate(0.99, 3, 0.0), rel=1e-3)


def test_monte_carlo_multivariate_t_matches_the_gate():
    """Errors drawn as a 3-D Student-t with covariance C (not just its shape): the gate keeps its share."""
    rng = np.random.default_rng(3)
    nu, n = 4.0, 200_000
    C = np.array([[4.0, 0.5, 0.0], [0.5, 1.0, 0.2], [0.0, 0.2, 0.25]])
    L = np.linalg.cholesky(C)
    x = (rng.standard_normal((n, 3)) @ L.T) * np.sqrt((nu - 2.0) / rng.chisquare(nu, (n, 1)))
    d2 = np.einsum("ni,ij,nj->n", x, np.linalg.inv(C), x)
    assert d2.mean() == pytest.approx(3.0, rel=0.05)     # the covariance is C: NEES averages the dimension
    for p in (0.95, 0.99):
        assert np.mean(d2 <= nees_gate(p, 3, nu)) == pytest.approx(p, abs=0.002)


def test_edges_and_refusals():
    assert nees_cdf(0.0) == 0.0 and nees_cdf(-1.0) == 0.0 and nees_cdf(math.inf) == 1.0
    assert math.isnan(nees_cdf(math.nan, 3, 3.59))
    for bad in (dict(dims=0), dict(dims=1.5), dict(tail_dof=2.0), dict(tail_dof=1.0), dict(tail_dof=-3.0),
                dict(tail_dof=math.inf), dict(tail_dof=math.nan)):
        with pytest.raises(ValueError):
            nees_cdf(1.0, **bad)
        with pytest.raises(ValueError):
            nees_gate(0.9, **bad)
    for p in (0.0, 1.0, -0.1, math.nan):
        with pytest.raises(ValueError):
            nees_gate(p)
