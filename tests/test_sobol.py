"""The line-integral estimator's randomised quasi-Monte Carlo sampler (skyref.plugins.sobol)."""

from __future__ import annotations

import math

import numpy as np


def sampler_for(mi, samples, scrambles, seed=7):
    from skyref.plugins.sobol import ScrambledSobolSampler, hash_combine

    index = mi.UInt32(np.arange(samples * scrambles, dtype=np.uint32))
    return ScrambledSobolSampler(index % samples, hash_combine(seed, index // samples))


def test_each_decision_is_stratified_and_a_net(mi):
    """For 2^m samples of one scramble, every decision is stratified in 2^m intervals, and the
    two dimensions of a 2-D decision (and the first two of a 3-D one) form a (0, m, 2)-net: one
    point in every dyadic box of area 2^-m."""
    n, scrambles = 256, 4
    sampler = sampler_for(mi, n, scrambles)
    one = sampler.next_1d().numpy().reshape(scrambles, n)
    two = np.stack([x.numpy() for x in sampler.next_2d()]).reshape(2, scrambles, n)
    three = np.stack([x.numpy() for x in sampler.next_3d()]).reshape(3, scrambles, n)
    for s in range(scrambles):
        assert np.array_equal(np.sort(np.floor(one[s] * n)), np.arange(n))
        for points in (two[:, s], three[:2, s]):
            for bits_x in range(9):
                cells = np.floor(points[0] * 2 ** bits_x) * 2 ** (8 - bits_x) + np.floor(points[1] * 2 ** (8 - bits_x))
                assert len(np.unique(cells)) == n, bits_x
        # the third dimension of a 3-D decision is stratified too, and 8x8x4 boxes hold one point each
        assert np.array_equal(np.sort(np.floor(three[2, s] * n)), np.arange(n))
        boxes = np.floor(three[0, s] * 8) * 32 + np.floor(three[1, s] * 8) * 4 + np.floor(three[2, s] * 4)
        assert len(np.unique(boxes)) == n


def test_scrambles_are_unbiased_and_beat_independent_numbers(mi):
    """The mean of f(u, v, w) = exp(2 u v) w (u, v one 2-D decision, w another decision) over 16
    points, across 4096 independent scrambles: unbiased (|z| < 4 against the closed form
    1/2 sum_k 2^k / (k! (k+1)^2)) and with a variance at least 3x below independent numbers'."""
    n, scrambles = 16, 4096
    sampler = sampler_for(mi, n, scrambles, seed=3)
    u, v = (x.numpy() for x in sampler.next_2d())
    w = sampler.next_1d().numpy()
    f = np.exp(2.0 * u * v) * w
    means = f.reshape(scrambles, n).mean(axis=1)
    exact = 0.5 * sum(2.0 ** k / (math.factorial(k) * (k + 1) ** 2) for k in range(40))
    z = (means.mean() - exact) / (means.std(ddof=1) / math.sqrt(scrambles))
    assert abs(z) < 4.0, z
    independent_variance = f.var() / n        # of a mean of n independent values of f
    assert means.var(ddof=1) < independent_variance / 3.0, (means.var(), independent_variance)


def test_decisions_in_a_symbolic_loop_are_new_on_every_iteration(mi):
    """The same call inside a symbolic loop is a new decision on each iteration (Mitsuba's
    ldsampler repeated its dimensions there): the iterations' numbers are uncorrelated, and each
    iteration's are stratified."""
    import drjit as dr

    n = 1024

    def body(sampler, first, second, i):
        u = sampler.next_1d()
        return sampler, dr.select(i == 0, u, first), dr.select(i == 1, u, second), i + 1

    state = (sampler_for(mi, n, 1), mi.Float(0.0), mi.Float(0.0), mi.UInt32(0))
    _, a, b, _ = dr.while_loop(state, lambda sampler, first, second, i: i < 2, body)
    a, b = a.numpy(), b.numpy()
    assert not np.allclose(a, b)
    for x in (a, b):
        assert np.array_equal(np.sort(np.floor(x * n)), np.arange(n))
    assert abs(np.corrcoef(a, b)[0, 1]) < 4.0 / math.sqrt(n)


def test_hash_combine_accepts_integers(mi):
    """Seeds are 32-bit: a Python integer or a UInt32 array gives the same seed."""
    from skyref.plugins.sobol import hash_combine

    assert hash_combine(5, 9).numpy()[0] == hash_combine(mi.UInt32(5), mi.UInt32(9)).numpy()[0]
    assert hash_combine(5, 9).numpy()[0] != hash_combine(5, 10).numpy()[0]
