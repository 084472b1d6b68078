"""Configs: one dataclass per command, YAML and ``key=value`` overrides on top, ``--help``
generated from the same dataclasses.

>>> from oasis_torchrl.config import load_config
>>> load_config("ppo", ["env.num_envs=2"]).env.num_envs
2
"""

from oasis_torchrl.config.env import EmbeddedServerConfig, EnvConfig, RewardConfig
from oasis_torchrl.config.evaluation import EvalConfig, EvaluationConfig
from oasis_torchrl.config.loading import (
    config_names,
    load_config,
    save_config,
    schema_of,
    section,
    to_object,
)
from oasis_torchrl.config.pipeline import DemoConfig
from oasis_torchrl.config.ray import RayCollectionConfig
from oasis_torchrl.config.training import BCConfig, BCSettings, PPOConfig, PPOSettings
from oasis_torchrl.options import option

__all__ = [
    "BCConfig",
    "BCSettings",
    "DemoConfig",
    "EmbeddedServerConfig",
    "EnvConfig",
    "EvalConfig",
    "EvaluationConfig",
    "PPOConfig",
    "PPOSettings",
    "RayCollectionConfig",
    "RewardConfig",
    "config_names",
    "load_config",
    "option",
    "save_config",
    "schema_of",
    "section",
    "to_object",
]
