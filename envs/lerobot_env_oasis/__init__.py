"""LeRobot env plugin ``lerobot_env_oasis``: the world model as a LeRobot simulation env, type
``oasis`` (``lerobot-eval --env.type=oasis``, ``lerobot-train --env.type=oasis``).

LeRobot 0.6 imports every installed distribution named ``lerobot_env_*`` before parsing the flags
of its tools; importing this package registers ``--env.type=oasis``.

>>> from lerobot.envs.configs import EnvConfig
>>> "oasis" in EnvConfig.get_known_choices()
True
"""

from lerobot_env_oasis.config_oasis import OasisEnvConfig
from lerobot_env_oasis.vector_env import OasisVectorEnv

__all__ = ["OasisEnvConfig", "OasisVectorEnv"]
