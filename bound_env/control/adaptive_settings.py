"""The settings of `bound_env.control.adaptive.AdaptiveMPC` (an mpc spec's ``adaptive``
block) and their check, apart from the controller so that the spec reader
(`bound_env.control.spec`) needs nothing of it."""

from __future__ import annotations

from ..files import schema

# settings (spec key ``adaptive``) and their defaults, chosen on the validation plants (seed
# 777; docs/controllers.md)
ADAPTIVE_DEFAULTS = {
    "window": 10,  # strides in the fit
    "prior": 0.1,  # prior standard deviation of each log factor
    "sigma": 0.01,  # assumed error of a one-stride prediction (normalized apex units)
    "identify": 20,  # strides from the start over which it fits (then: when the model is wrong)
    "trust_error": 0.15,  # an estimate is trusted after predicting an unseen stride this well
    "trust_std": 0.05,  # ... and its predicted apex's posterior std (normalized) is this small
    "trust_strides": 1,  # in-sample trust (off with trust_rms 0): once it fits this many ...
    "trust_rms": 0.05,  # ... strides with an rms residual at most this (normalized)
    "deadband": 1e-5,  # innovations at most this: no update (the nominal plant)
    "settle": 0.05,  # a trusted estimate is not refitted after innovations at most this
    "redesign": 0.005,  # a trusted estimate this far (max |log f|) from the design: redesign
    "iters": 10,  # Levenberg-Marquardt steps per fit (at most; the next fit continues)
    "candidates": 128,  # starting points of the search for the fit's global minimum
    "search": 4,  # descents from the cheapest of them while the estimate is not trusted
    "searches": 3,  # searching fits per episode at most (the work per episode is bounded)
    "delays": 2,  # actuation delays [intervals] the searching fits consider (0 ... delays)
    # stride evaluations of identification and design per apex decision (the work is spread
    # over the decisions, `bound_env.control.anytime`); 0: all of it in one decision
    "budget": 0,
    # a trusted estimate that mispredicts a stride: back to the shipped mpc and refit, also
    # after ``identify`` strides (false: the design stays and fitting ends at ``identify``;
    # chosen on the validation plants, docs/controllers.md)
    "fallback": False,
}
ADAPTIVE_BOOLS = ("fallback",)
ADAPTIVE_INTS = (
    "window", "identify", "iters", "trust_strides", "candidates", "search", "searches", "delays",
    "budget",
)  # fmt: skip
ADAPTIVE_LIMITS = {
    "window": (1, 1000),
    "prior": (1e-6, 10.0),  # the fit divides by prior^2 and sigma^2: 1e-300 overflowed
    "sigma": (1e-6, 10.0),
    "identify": (0, 100_000),
    "trust_error": (0.0, 100.0),
    "trust_strides": (1, 1000),
    "trust_rms": (0.0, 100.0),
    "trust_std": (0.0, 100.0),
    "deadband": (0.0, 1.0),
    "settle": (0.0, 100.0),
    "redesign": (0.0, 10.0),
    "iters": (1, 100),
    "candidates": (0, 65_536),
    "search": (0, 65_536),
    "searches": (0, 100_000),
    "delays": (0, 20),
    "budget": (0, 1_000_000),
    "fallback": (False, True),
}


# spellings that say which: ``search`` is the descents of one fit, ``searches`` the fits of an
# episode (the keys stay the short ones: they are in the fingerprints)
ADAPTIVE_ALIASES = {"descents_per_fit": "search", "fits_per_episode": "searches"}


def check_adaptive(value, path) -> dict | None:
    """The ``adaptive`` block of an mpc spec: ``true`` (the defaults), ``false`` (none) or a
    mapping of some of `ADAPTIVE_DEFAULTS`, each checked (a one-line ValueError naming the file
    and the key)."""
    out = schema.settings_block(
        value, path, "adaptive", ADAPTIVE_DEFAULTS, _adaptive_value, ADAPTIVE_ALIASES
    )
    if out is not None and out["trust_strides"] > out["window"]:
        raise ValueError(
            f"{path}: adaptive.trust_strides {out['trust_strides']} is longer than "
            f"adaptive.window {out['window']}: the fit never holds that many strides, so no "
            "estimate would ever be trusted"
        )
    return out


def _adaptive_value(key: str, v, where: str):
    """One setting within its `ADAPTIVE_LIMITS` (true or false for `ADAPTIVE_BOOLS`, an integer
    for `ADAPTIVE_INTS`, whose limits are integers; a real in [lo, hi] else)."""
    return schema.limited(v, where, *ADAPTIVE_LIMITS[key])
