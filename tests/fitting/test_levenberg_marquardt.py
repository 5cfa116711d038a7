"""The fitters' Levenberg-Marquardt (host/fitting/levenberg_marquardt.py): it finds a known
optimum, keeps to a box, counts its evaluations, and repeats itself exactly wherever its inputs
sit in memory (scipy 1.15-1.17's method="lm" did not: see the module docstring)."""

import numpy as np

from host.fitting.levenberg_marquardt import forward_difference_jacobian, minimize

X = np.linspace(0.0, 2.0, 40)
TRUE = np.array([1.5, -0.8])
Y = TRUE[0] * np.exp(TRUE[1] * X)


def residual(p):
    return p[0] * np.exp(p[1] * X) - Y


def jacobian(p):
    e = np.exp(p[1] * X)
    return np.stack([e, p[0] * X * e], axis=1)


def test_finds_the_optimum_of_a_nonlinear_fit():
    p, cost = minimize(residual, jacobian, [1.0, 0.0])
    assert np.allclose(p, TRUE, atol=1e-7)
    assert cost < 1e-14


def test_keeps_to_the_box_and_still_improves():
    start = np.array([1.0, 0.0])
    p, cost = minimize(residual, jacobian, start, lo=np.array([0.0, -0.5]), hi=np.array([3.0, 0.5]))
    assert p[1] == -0.5  # the optimum's -0.8 lies outside: pressed against the bound
    assert 0.0 <= p[0] <= 3.0
    assert cost < float(residual(start) @ residual(start))


def test_stops_after_max_evals_residual_calls():
    calls = []

    def counted(p):
        calls.append(1)
        return residual(p)

    minimize(counted, jacobian, [1.0, 0.0], max_evals=5)
    assert len(calls) <= 5


def test_forward_differences_match_the_analytic_jacobian():
    p = np.array([1.2, -0.3])
    assert np.allclose(forward_difference_jacobian(residual)(p), jacobian(p), rtol=1e-5, atol=1e-6)


def test_same_inputs_anywhere_in_memory_give_bit_identical_answers():
    rng = np.random.default_rng(5)
    noisy = Y + rng.normal(0.0, 0.01, X.size)
    answers = set()
    for offset in range(12):
        buf = np.empty(noisy.size + offset)  # the data at another address each time
        buf[offset:] = noisy
        y = buf[offset:]
        p, cost = minimize(lambda q, y=y: q[0] * np.exp(q[1] * X) - y, jacobian, [1.0, 0.0])
        answers.add((p.tobytes(), cost))
    assert len(answers) == 1
