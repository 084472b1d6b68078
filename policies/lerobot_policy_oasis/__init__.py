"""LeRobot policy plugin ``lerobot_policy_oasis``: the oasis driving policy, type ``oasis``.

LeRobot imports every installed distribution named ``lerobot_policy_*`` before parsing
``lerobot-train`` flags; importing this package registers ``--policy.type=oasis``.

>>> from lerobot.configs.policies import PreTrainedConfig
>>> "oasis" in PreTrainedConfig.get_known_choices()
True
"""

from lerobot_policy_oasis.configuration_oasis import POLICY_TYPE, OasisConfig
from lerobot_policy_oasis.modeling_oasis import OasisPolicy
from lerobot_policy_oasis.processor_oasis import make_oasis_pre_post_processors

__all__ = ["POLICY_TYPE", "OasisConfig", "OasisPolicy", "make_oasis_pre_post_processors"]
