"""The policy a server serves: a driver loaded by the project's one grammar
(:func:`~oasis_torchrl.drivers.load_driver`), its input features, and one batched, stateless
call that turns observations into plans (:meth:`~oasis_torchrl.drivers.Driver.plan`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import torch
from tensordict import TensorDictBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.drivers import Driver, load_driver
from oasis_torchrl.protocol import ACTION_DIM, ACTION_NAMES, CHUNK
from oasis_torchrl.remote.features import (
    Feature,
    as_tensordict,
    features_of_spec,
    neutral_observation,
)

logger = logging.getLogger(__name__)

ACTION = Feature("action", (ACTION_DIM,), torch.float32, -1.0, 1.0, ACTION_NAMES)
"""One ``[throttle, steering]`` action; a chunk holds :data:`~oasis_torchrl.protocol.CHUNK`."""


@dataclass
class ServedPolicy:
    """A driver and what it reads: what a policy server answers with.

    Args:
        driver: plans ``[rows, chunk_size, 2]`` actions from a TensorDict of observations
            (:meth:`~oasis_torchrl.drivers.Driver.plan`).
        inputs: the features it reads (from its ``observation_spec``, or declared).
        name: what Status and Describe call it.
        chunk_size: actions per plan.

    Example:
        >>> from oasis_torchrl.drivers import PolicyDriver
        >>> from oasis_torchrl.models import DrivingNet
        >>> from oasis_torchrl.remote.features import as_tensordict, sample_observation
        >>> served = ServedPolicy.of_driver(PolicyDriver.of_network(DrivingNet()), "fresh")
        >>> [feature.name for feature in served.inputs]
        ['frame_stack.left_forward', 'frame_stack.front', 'frame_stack.right_forward', 'state']
        >>> served.chunk_size, served.n_action_steps
        (4, 4)
    """

    driver: Driver
    inputs: tuple[Feature, ...]
    name: str
    chunk_size: int
    action: Feature = ACTION

    @property
    def n_action_steps(self) -> int:
        """Actions of each plan SelectAction serves before planning again."""
        return min(self.driver.n_action_steps, self.chunk_size)

    @classmethod
    def of_driver(
        cls, driver: Driver, name: str, inputs: Sequence[Feature] | None = None
    ) -> ServedPolicy:
        """Serve ``driver``, reading ``inputs`` (default: its ``observation_spec``). One plan
        of a neutral observation sizes the chunk (and warms the policy up)."""
        if inputs is None:
            if driver.observation_spec is None:
                raise ValueError(
                    f"{name} does not say what it reads: declare its inputs as "
                    "NAME:DTYPE:SHAPE features (e.g. inputs=[pixels.front:uint8:4x64x96x3,"
                    "state:float32:2])"
                )
            inputs = features_of_spec(driver.observation_spec)
        if not inputs:
            raise ValueError(f"{name} reads no input; a served policy needs at least one")
        served = cls(driver, tuple(inputs), name, chunk_size=CHUNK)
        probe = as_tensordict(neutral_observation(served.inputs, rows=1), rows=1)
        served.chunk_size = served.predict_chunk(probe).shape[1]
        return served

    @torch.no_grad()
    def predict_chunk(self, observation: TensorDictBase) -> torch.Tensor:
        """float32 ``[rows, chunk_size, 2]`` plans in ``[-1, 1]``, acting deterministically."""
        with set_exploration_type(ExplorationType.DETERMINISTIC):
            return self.driver.plan(observation)


def load_served_policy(spec: str, inputs: Sequence[Feature] | None = None) -> ServedPolicy:
    """Load the policy ``spec`` names (:func:`~oasis_torchrl.drivers.load_driver`) for serving.

    Args:
        spec: a saved policy: a LeRobot policy folder, a PPO checkpoint, a TorchScript or
            ``torch.save`` file.
        inputs: what a plain saved module reads (also its inputs, in order); policies that
            declare their inputs need none.

    Example:
        >>> load_served_policy("autopilot")
        Traceback (most recent call last):
        ...
        ValueError: autopilot does not say what it reads: declare its inputs as ...
    """
    in_keys = None if inputs is None else [feature.key for feature in inputs]
    driver = load_driver(spec, in_keys=in_keys)
    name = Path(spec).name if Path(spec).exists() else spec
    served = ServedPolicy.of_driver(driver, name, inputs)
    logger.info(
        "loaded %s: inputs %s", name, ", ".join(feature.describe() for feature in served.inputs)
    )
    return served
