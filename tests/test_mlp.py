"""`agents.common.mlp.mlp_forward`, the one NumPy forward pass of the learned controllers."""

from __future__ import annotations

import numpy as np
import pytest

from agents.common.mlp import ACTIVATIONS, mlp_forward


def _layers(rng, sizes=(6, 16, 16, 3)):
    return [
        (rng.standard_normal((sizes[k + 1], sizes[k])), rng.standard_normal(sizes[k + 1]))
        for k in range(len(sizes) - 1)
    ]


@pytest.mark.parametrize("activation", sorted(ACTIVATIONS))
def test_one_input_and_rows_are_the_written_out_network(activation):
    """Bit for bit the loops it replaced: ``act(W @ h + b)`` for one input (the PPO and stride
    controllers), ``act(h @ W.T + b)`` for rows (the distilled student's logits)."""
    rng = np.random.default_rng(1)
    layers, act = _layers(rng), ACTIVATIONS[activation]
    x = rng.standard_normal(6)
    h = x
    for W, b in layers[:-1]:
        h = act(W @ h + b)
    W, b = layers[-1]
    assert np.array_equal(mlp_forward(layers, x, activation), W @ h + b)
    X = rng.standard_normal((7, 6))
    H = X
    for W, b in layers[:-1]:
        H = act(H @ W.T + b)
    W, b = layers[-1]
    assert np.array_equal(mlp_forward(layers, X, activation), H @ W.T + b)


def test_exact_rows_do_not_depend_on_the_other_rows():
    rng = np.random.default_rng(2)
    layers = _layers(rng)
    X = rng.standard_normal((33, 6))
    out = mlp_forward(layers, X, "Tanh", exact_rows=True)
    for i in (0, 5, 32):
        assert np.array_equal(out[i], mlp_forward(layers, X[i : i + 1], "Tanh", exact_rows=True)[0])
        one = mlp_forward(layers, X[i], "Tanh")
        np.testing.assert_allclose(out[i], one, rtol=1e-12, atol=1e-12)
