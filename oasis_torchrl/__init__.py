"""oasis-torchrl: Decart's Oasis action-to-video world model in the PyTorch robot-learning stack.

Sub-packages, one concern each: ``client`` (A2V client and session pool), ``sim`` (the embedded
procedural A2V server), ``envs`` (TorchRL and Gymnasium envs), ``rewards``, ``data`` (LeRobot
datasets), ``viz`` (rerun), ``models`` (the driving network), ``train`` (PPO, BC, evaluation),
``distributed`` (Ray collection), ``commands`` (the ``oasis-torchrl`` CLI).

Importing the package registers the Gymnasium id ``"oasis_torchrl/Oasis-v0"`` (as Gymnasium's
own and most third-party env packages do; ``gymnasium.make("oasis_torchrl:oasis_torchrl/Oasis-v0")``
imports it by itself): ``gymnasium.make`` builds :class:`~oasis_torchrl.envs.OasisGymEnv`,
``gymnasium.make_vec`` :class:`~oasis_torchrl.envs.OasisVectorEnv` (N sessions stepped
concurrently); keyword arguments go to them. It also shortens LeRobot's fallback from torchcodec
to PyAV to one log line (:mod:`oasis_torchrl.video_fallback`).

>>> import gymnasium
>>> gymnasium.spec(GYMNASIUM_ID).vector_entry_point
'oasis_torchrl.envs.gym_vector:OasisVectorEnv'
"""

from importlib.metadata import PackageNotFoundError, version

import gymnasium

from oasis_torchrl.video_fallback import shorten_video_fallback

try:
    __version__ = version("oasis-torchrl")
except PackageNotFoundError:  # running from a source tree that was never installed
    __version__ = "0.0.0+unknown"

GYMNASIUM_ID = "oasis_torchrl/Oasis-v0"
"""The Gymnasium id of one Oasis session (episodes truncate at the env's ``max_steps``)."""

if GYMNASIUM_ID not in gymnasium.registry:
    gymnasium.register(
        id=GYMNASIUM_ID,
        entry_point="oasis_torchrl.envs.gym_adapter:OasisGymEnv",
        vector_entry_point="oasis_torchrl.envs.gym_vector:OasisVectorEnv",
    )

shorten_video_fallback()
