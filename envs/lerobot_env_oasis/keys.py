"""The observation keys of the oasis env: what :class:`~lerobot_env_oasis.OasisVectorEnv`
returns and :class:`~lerobot_env_oasis.OasisEnvConfig` maps to LeRobot's feature names (a module
of their own, so the vector env and its config need not import each other).

>>> from lerobot_env_oasis.keys import AGENT_POS, PIXELS
>>> AGENT_POS, PIXELS
('agent_pos', 'pixels')
"""

AGENT_POS = "agent_pos"
PIXELS = "pixels"
