"""Training of driving policies: PPO (TorchRL), behaviour cloning (LeRobot), checkpoints and the
record -> BC -> PPO -> eval pipeline, evaluating with :mod:`oasis_torchrl.evaluation`. Their
settings are the dataclasses of :mod:`oasis_torchrl.config`."""
