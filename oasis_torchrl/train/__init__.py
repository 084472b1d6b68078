"""Training and evaluation of driving policies: PPO (TorchRL), behaviour cloning (LeRobot),
evaluation, checkpoints, YAML configs and the record -> BC -> PPO -> eval pipeline.

>>> from oasis_torchrl.train import load_config
>>> load_config("ppo").logger.backend
'csv'
"""

from oasis_torchrl.train.config import apply_overrides, load_config, save_config

__all__ = ["apply_overrides", "load_config", "save_config"]
