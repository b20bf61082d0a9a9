"""Gates for the normalised squared error of a reported pose, with the errors' heavy tails (the standard library only).

A navigation filter tests each measurement before it takes it: the normalised squared error (NEES)
``d2 = e^T C^-1 e`` of its innovation against a gate. With normal errors ``d2`` follows a chi-square
law with ``dims`` degrees of freedom, and the 99 % gate for ``dims = 3`` is 11.34. The poses this
project reports have heavier tails (session 29: a 3-sigma gate rejects 3-8 % of right poses, a normal
0.3 %). A multivariate Student-t law with ``tail_dof = nu > 2`` degrees of freedom and covariance ``C``
(the one reported: ``position_cov``, or ``sigma_rotation_deg`` per axis) describes them better; then
``d2 * nu / ((nu - 2) * dims)`` follows Fisher's F law with ``(dims, nu)`` degrees of freedom, and the
gates are wider. ``nu`` is the bundle's ``uncertainty.tail_dof`` (0: normal), fitted by
:func:`spacepose.tools.calibrate_uncertainty.fit_tail_dof` on training frames.

:func:`nees_cdf` is the probability that a right pose's ``d2`` is at most the value given, and
:func:`nees_gate` the value a right pose's ``d2`` exceeds with probability ``1 - probability``. Both
come from the regularised incomplete gamma and beta functions (series and continued fraction, as in
Numerical Recipes), so the flight runtime needs no scipy; the tests compare them with scipy's.
"""

from __future__ import annotations

import math

__all__ = ["nees_cdf", "nees_gate"]

_EPS = 1e-14
_MAX_TERMS = 500
_TINY = 1e-300


def _gamma_p(a: float, x: float) -> float:
    """The regularised lower incomplete gamma function P(a, x)."""
    if x <= 0.0:
        return 0.0
    log_front = a * math.log(x) - x - math.lgamma(a)
    if x < a + 1.0:                       # series
        term = total = 1.0 / a
        ap = a
        for _ in range(_MAX_TERMS):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * _EPS:
                break
        return min(1.0, total * math.exp(log_front))
    return max(0.0, 1.0 - _continued_fraction_q(a, x) * math.exp(log_front))


def _lentz(d: float, c: float, a: float, b: float) -> tuple[float, float, float]:
    """One step of Lentz's method for the term ``a / (b + ...)``: the new ``d``, ``c`` and the factor."""
    d = b + a * d
    d = _TINY if abs(d) < _TINY else d
    c = b + a / c
    c = _TINY if abs(c) < _TINY else c
    d = 1.0 / d
    return d, c, d * c


def _continued_fraction_q(a: float, x: float) -> float:
    """Lentz's continued fraction of Q(a, x) without its front factor."""
    b = x + 1.0 - a
    c, d = 1.0 / _TINY, 1.0 / b
    h = d
    for i in range(1, _MAX_TERMS):
        b += 2.0
        d, c, delta = _lentz(d, c, -i * (i - a), b)
        h *= delta
        if abs(delta - 1.0) < _EPS:
            break
    return h


def _beta_i(a: float, b: float, x: float) -> float:
    """The regularised incomplete beta function I_x(a, b)."""
    if x <= 0.0:
        return 0.0
    if x >= 1.0:
        return 1.0
    log_front = (math.lgamma(a + b) - math.lgamma(a) - math.lgamma(b) + a * math.log(x) + b * math.log1p(-x))
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(log_front) * _beta_cf(a, b, x) / a
    return 1.0 - math.exp(log_front) * _beta_cf(b, a, 1.0 - x) / b


def _beta_cf(a: float, b: float, x: float) -> float:
    """Lentz's continued fraction of the incomplete beta function."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    d = _lentz(1.0, 1.0, -qab * x / qap, 1.0)[0]   # the leading 1 / (1 - qab x / qap)
    c, h = 1.0, d
    for m in range(1, _MAX_TERMS):
        m2 = 2 * m
        d, c, even = _lentz(d, c, m * (b - m) * x / ((qam + m2) * (a + m2)), 1.0)
        d, c, delta = _lentz(d, c, -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2)), 1.0)
        h *= even * delta
        if abs(delta - 1.0) < _EPS:
            break
    return h


def _check(dims: int, tail_dof: float) -> None:
    if int(dims) != dims or dims < 1:
        raise ValueError(f"dims must be a positive integer, got {dims!r}")
    if not (tail_dof == 0.0 or (math.isfinite(tail_dof) and tail_dof > 2.0)):
        raise ValueError(f"tail_dof must be 0 (normal) or a finite number > 2, got {tail_dof!r}")


def nees_cdf(d2: float, dims: int = 3, tail_dof: float = 0.0) -> float:
    """P(NEES <= ``d2``) for a right pose: chi-square with ``dims`` degrees of freedom when ``tail_dof`` is 0,
    else the Student-t law of the module docstring. ``d2`` NaN gives NaN; ``d2 <= 0`` gives 0."""
    _check(dims, tail_dof)
    d2 = float(d2)
    if math.isnan(d2):
        return float("nan")
    if d2 <= 0.0:
        return 0.0
    if math.isinf(d2):
        return 1.0
    if tail_dof == 0.0:
        return _gamma_p(dims / 2.0, d2 / 2.0)
    f = d2 * tail_dof / ((tail_dof - 2.0) * dims)            # ~ F(dims, tail_dof)
    return _beta_i(dims / 2.0, tail_dof / 2.0, dims * f / (dims * f + tail_dof))


def nees_gate(probability: float, dims: int = 3, tail_dof: float = 0.0) -> float:
    """The NEES a right pose stays at or under with ``probability`` (in (0, 1)): the gate a filter sets to
    keep that share of right poses (bisection on :func:`nees_cdf`, to 1e-10 relative)."""
    _check(dims, tail_dof)
    p = float(probability)
    if not 0.0 < p < 1.0:
        raise ValueError(f"probability must be in (0, 1), got {probability!r}")
    lo, hi = 0.0, float(dims)
    while nees_cdf(hi, dims, tail_dof) < p:
        lo, hi = hi, hi * 2.0
        if hi > 1e300:
            return float("inf")
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if nees_cdf(mid, dims, tail_dof) < p:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-10 * hi:
            break
    return 0.5 * (lo + hi)
