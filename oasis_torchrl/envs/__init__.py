"""TorchRL and Gymnasium environments over Oasis world-model sessions."""

from oasis_torchrl.envs.episodes import EpisodePlanner
from oasis_torchrl.envs.gym_adapter import OasisGymEnv
from oasis_torchrl.envs.oasis_env import OasisEnv
from oasis_torchrl.envs.transforms import make_training_env

__all__ = ["EpisodePlanner", "OasisEnv", "OasisGymEnv", "make_training_env"]
