"""The NumPy MLP every learned controller runs: one forward pass, its activations, and the
reading of an SB3 actor into NumPy layers.

The layers are ``[(W, b), ...]``: hidden layers ``act(W h + b)``, then a linear output layer
``W h + b`` (float64). `mlp_forward` is the one forward pass of
`agents.runtime.controllers.MLPController` (a PPO actor),
`agents.runtime.choice_policy.ChoicePolicyController` (the student's logits) and
`agents.runtime.stride_policy.StridePolicyController` (the stride residual); no torch is needed to
run it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numba as nb
import numpy as np

# activations by the name of their torch module (``type(module).__name__``)
ACTIVATIONS = {
    "Tanh": np.tanh,
    "ReLU": lambda x: np.maximum(x, 0.0),
    "ELU": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0.0))),
    "Identity": lambda x: x,
}


def mlp_forward(layers, x, activation: str = "Tanh", exact_rows: bool = False) -> np.ndarray:
    """The MLP's output (before any clip) at ``x``: one input (1-D; ``W @ h + b``) or one per
    row (2-D; ``h @ W.T + b``).

    ``exact_rows`` (rows only): each row computed alone, its sums in index order, tanh element
    by element (`affine_rows`, `tanh_elements`): a row's output depends neither on the other
    rows nor on the machine's load (NumPy's vectorized tanh rounds differently in and after its
    SIMD blocks, and BLAS sums depend on alignment and threads)."""
    if exact_rows:
        act = tanh_elements if activation == "Tanh" else ACTIVATIONS[activation]
        affine = affine_rows
    else:
        act = ACTIVATIONS[activation]
        affine = _affine_one if np.ndim(x) == 1 else _affine_many
    h = x
    for W, b in layers[:-1]:
        h = act(affine(h, W, b))
    W, b = layers[-1]
    return affine(h, W, b)


def _affine_one(x, W, b):
    return W @ x + b


def _affine_many(x, W, b):
    return x @ W.T + b


@nb.njit(cache=True)
def tanh_elements(x):
    """tanh of each element by the same scalar routine, wherever it sits in the array."""
    out = np.empty_like(x)
    flat_in, flat_out = x.ravel(), out.ravel()
    for i in range(flat_in.size):
        flat_out[i] = math.tanh(flat_in[i])
    return out


@nb.njit(cache=True)
def affine_rows(x, W, b):
    """x @ W.T + b, one row at a time, each sum in index order (no fast-math: a vectorized
    sum would depend on the row's alignment in memory), so row i depends on x[i] only."""
    out = np.empty((x.shape[0], W.shape[0]))
    for i in range(x.shape[0]):
        for j in range(W.shape[0]):
            acc = b[j]
            for k in range(W.shape[1]):
                acc += W[j, k] * x[i, k]
            out[i, j] = acc
    return out


def linear_layers(modules) -> list:
    """The (W, b) of each torch ``Linear`` among ``modules``, in order, as float64 NumPy
    copies: the layers `mlp_forward` takes."""
    from torch import nn

    return [
        (m.weight.detach().double().numpy().copy(), m.bias.detach().double().numpy().copy())
        for m in modules
        if isinstance(m, nn.Linear)
    ]


def extract_actor(model, model_path: Path) -> tuple[list, str]:
    """(layers, activation) of an SB3 actor-critic: the hidden layers of
    ``mlp_extractor.policy_net`` plus ``action_net``, as float64 NumPy arrays."""
    from torch import nn

    policy = model.policy
    if type(policy.pi_features_extractor).__name__ != "FlattenExtractor":
        raise ValueError(f"{model_path}: only MLP policies on a flat observation are supported")
    activation = "Identity"
    for m in policy.mlp_extractor.policy_net:
        if isinstance(m, nn.Linear):
            continue
        if type(m).__name__ in ACTIVATIONS:
            activation = type(m).__name__
        else:
            raise ValueError(f"{model_path}: unsupported layer {m} in the policy network")
    layers = linear_layers([*policy.mlp_extractor.policy_net, policy.action_net])
    if getattr(policy, "squash_output", False):
        raise ValueError(f"{model_path}: squashed (gSDE) policies are not supported")
    return layers, activation


def checked_actor(model, model_path: Path) -> tuple[list, str]:
    """`extract_actor`'s layers and activation, refused unless they are an MLP's
    (`agents.common.schema.check_layers`, a one-line error naming ``model_path``)."""
    from .schema import check_layers

    layers, activation = extract_actor(model, model_path)
    check_layers(layers, str(model_path))
    return layers, activation
