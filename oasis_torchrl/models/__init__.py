"""The driving network shared by TorchRL PPO and the LeRobot policy plugin.

>>> from oasis_torchrl.models import DrivingNet, DrivingNetConfig, make_actor_critic
>>> modules = make_actor_critic(DrivingNet(DrivingNetConfig(shared_encoder=False)))
"""

from oasis_torchrl.models.actor_critic import (
    ActorCritic,
    make_actor_critic,
    make_deterministic_actor,
    observation_keys,
    observation_spec,
)
from oasis_torchrl.models.config import POLICY_FRAMES, POLICY_IMAGE_SIZE, DrivingNetConfig
from oasis_torchrl.models.encoder import MultiCameraEncoder
from oasis_torchrl.models.network import DrivingNet
from oasis_torchrl.protocol import CAMERAS, CHUNK

__all__ = [
    "CAMERAS",
    "CHUNK",
    "POLICY_FRAMES",
    "POLICY_IMAGE_SIZE",
    "ActorCritic",
    "DrivingNet",
    "DrivingNetConfig",
    "MultiCameraEncoder",
    "make_actor_critic",
    "make_deterministic_actor",
    "observation_keys",
    "observation_spec",
]
