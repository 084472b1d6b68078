"""Training and evaluation of driving policies: PPO (TorchRL), behaviour cloning (LeRobot),
evaluation, checkpoints and the record -> BC -> PPO -> eval pipeline. Their settings are the
dataclasses of :mod:`oasis_torchrl.config`."""
