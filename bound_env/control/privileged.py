"""The privileged reference: the shipped MPC re-designed on the robot's **true** plant.

**Privileged: never a shipped or deployable policy.** It reads what no robot knows, the
parameters of the plant it runs on, and exists as the upper reference of the model-error
tables (``bound-env margins --mismatch``, compare's columns): what knowing the plant is worth.

    from bound_env.control.privileged import PrivilegedMPC
    ctrl = PrivilegedMPC(gait="default")      # the spec mpc-privileged (that of mpc)
    ctrl.set_plant(plant)                     # a Params, or info["plant"] of RandomizedPlant
    u = ctrl.stride_action(z)                 # as the mpc's, on that plant

``set_plant`` re-designs the shipped ``mpc`` (`bound_env.control.mpc.MPCController`: the same
search settings, weights and basis) on the plant (`bound_env.control.plant_design`):

- its planning map is the plant's stride map (``StrideMap(gait, gait_overrides=plant)``);
- it aims at the plant's own cycle: the passive cycle (Newton on the plant's apex map) where
  the plant has one near z*, else the cycle of least steady torque, so that it spends what the
  plant needs rather than what forcing the nominal z* costs;
- its LQR (the MPC's gate and terminal controller) is re-designed there, with the spec's Q, R.

On the nominal plant (and before any ``set_plant``) it is the shipped ``mpc``, bit for bit.
The plant stays until the next ``set_plant``: an episode's reset (`reset_controller`) keeps it.

Who hands it the plant: the model-error loop
(`bound_env.analysis.margins.model_error.mismatch_tasks.plant_runs`) calls ``set_plant`` with each
robot's plant, for a controller whose ``privileged`` is true only;
`bound_env.control.plain.PlainPolicy` passes ``info["plant"]`` at each reset of an env that reports
one (`bound_env.envs.wrappers.RandomizedPlant`). A DAgger teacher (issue 38) calls ``set_plant``
itself. The tools that ship or deploy a policy refuse it (`is_privileged`).
"""

from __future__ import annotations

import numpy as np

from .plant_design import PlantDesign, RedesignedMPC, plant_overrides

NAME = "mpc-privileged"  # the shipped spec's name (configs/controllers/mpc-privileged.yaml)


def is_privileged(controller) -> bool:
    """Whether ``controller`` reads the robot's true plant (never to be shipped or deployed);
    looks through wrappers that keep their controller as ``inner`` or ``controller``."""
    seen = set()
    while controller is not None and id(controller) not in seen:
        seen.add(id(controller))
        if getattr(controller, "privileged", False) is True:
            return True
        controller = getattr(controller, "inner", None) or getattr(controller, "controller", None)
    return False


def refuse_privileged(controller, what: str, name=None) -> None:
    """ValueError, saying why, if ``controller`` is privileged (`is_privileged`): the tools
    that ship, deploy or build on a policy (``what``: e.g. "use as a residual's base") call
    this; the evaluations (margins, compare, rollout) take it, marked."""
    if is_privileged(controller):
        label = name if name is not None else getattr(controller, "name", controller)
        raise ValueError(
            f"{label!r} is privileged: it reads the robot's true plant, which no robot knows "
            f"(an upper reference for the model-error tables, never a shipped or deployable "
            f"policy); it cannot {what}"
        )


class PrivilegedMPC(RedesignedMPC):
    """The shipped MPC planning on, aiming at the cycle of, and with its LQR designed on the
    robot's true plant (module docstring). ``spec``: an mpc spec (name, path or
    `bound_env.control.spec.ControllerSpec`; default ``mpc-privileged``); ``gait``: the gait
    it is designed for (default: the spec's). The design is `RedesignedMPC`'s."""

    NAME = NAME
    ROLE = "a privileged controller"
    privileged = True
    stateful = False  # the plant is not an episode's memory: a reset keeps it

    def __init__(self, gait=None, spec=NAME, name: str | None = None):
        super().__init__(gait, spec, name)
        self.plant_design: PlantDesign | None = None

    # -- the plant -------------------------------------------------------------------------------
    def set_plant(self, plant) -> PlantDesign | None:
        """Re-design on ``plant``: a `bound_env.model.params.Params` or a mapping of
        `bound_env.model.mismatch.PLANT_KEYS` to values in gait-file units (``info["plant"]``);
        None or the nominal plant: the shipped mpc. Returns the design (None: nominal)."""
        overrides = {} if plant is None else plant_overrides(plant, self.base.gait)
        if not overrides:
            self.mpc, self.plant_design = self.base, None
            return None
        d = self.designer.design(overrides)
        self.mpc = self.redesigned(d)
        self.plant_design = d
        return d

    @property
    def plant(self) -> dict:
        """The gait-file values of the current plant that differ from the gait's ({}:
        nominal)."""
        return dict(self.plant_design.overrides) if self.plant_design is not None else {}

    # -- the protocol of bound_env.control.controllers: the current plant's mpc -----------------
    lqr = property(lambda self: self.mpc.lqr)
    decision_seconds = property(lambda self: self.mpc.decision_seconds)
    decision_kinds = property(lambda self: self.mpc.decision_kinds)

    def coefficients(self, z) -> np.ndarray:
        return self.mpc.coefficients(z)

    def stride_action(self, z) -> np.ndarray:
        return self.mpc.stride_action(z)

    def plan(self, z) -> np.ndarray:
        return self.mpc.plan(z)

    def interval_actions(self, Z) -> np.ndarray:
        return self.mpc.interval_actions(Z)

    def apex_torques(self, z) -> np.ndarray:
        return self.mpc.apex_torques(z)

    def on_apex(self, z, time_since_apex: float = 0.0) -> None:
        self.mpc.on_apex(z, time_since_apex)

    def __call__(self, obs) -> float:
        return self.mpc(obs)

    def settings(self) -> dict:
        return {**self.base.settings(), "privileged": True}

    def fingerprint(self) -> str:
        """The base mpc's fingerprint, marked privileged (the plant is the evaluation's, not
        the controller's; the design code is in the margins' source hash)."""
        return self._fingerprint(b"privileged")

    def __repr__(self) -> str:
        return f"PrivilegedMPC({self.name!r}, plant={self.plant!r})"
