"""Who drives the next chunk: the person at the page, or a policy the person can take over from.

Without a policy the person always drives. With one, the policy drives until the person takes
over (a key or a gamepad button) and drives again once the person hands back; each chunk says
whether the person drove it, which the dataset keeps as LeRobot's ``intervention`` flag.
"""

from __future__ import annotations

import threading

import torch
from tensordict import TensorDictBase

from oasis_torchrl.drivers import Driver
from oasis_torchrl.drivers.base import bounded
from oasis_torchrl.protocol import CHUNK
from oasis_torchrl.web.messages import Control, Refused


class Pilot:
    """The person's latest input and, optionally, a policy; thread-safe (the page's messages
    arrive on the server's thread, chunks are asked for on the session's).

    Args:
        policy: a driver (:func:`~oasis_torchrl.drivers.load_driver`) that drives until the
            person takes over; None: the person drives.

    Example:
        >>> from oasis_torchrl.drivers import load_driver
        >>> from tensordict import TensorDict
        >>> pilot = Pilot(load_driver("constant:throttle=0.3"))
        >>> pilot.steer(Control(throttle=1.0, steering=-0.5, seq=1))
        >>> pilot.chunk(TensorDict(batch_size=[1]))[0][0, 0].tolist(), pilot.human
        ([0.30000001192092896, 0.0], False)
        >>> pilot.take_over(True)
        >>> pilot.chunk(TensorDict(batch_size=[1]))[0][0, 0].tolist()
        [1.0, -0.5]
    """

    def __init__(self, policy: Driver | None = None) -> None:
        self.policy = policy
        self._lock = threading.Lock()
        self._control = Control(0.0, 0.0, 0)
        self._human = policy is None

    @property
    def human(self) -> bool:
        """Whether the person drives the next chunk."""
        return self._human

    @property
    def seq(self) -> int:
        """The ``seq`` of the person's latest input."""
        return self._control.seq

    def steer(self, control: Control) -> None:
        """The person's input, held until the next."""
        with self._lock:
            self._control = control

    def release(self) -> None:
        """The person left: their input drops to zero and a policy (if any) drives."""
        with self._lock:
            self._control = Control(0.0, 0.0, self._control.seq)
            self._human = self.policy is None

    def take_over(self, human: bool) -> None:
        """The person drives (``True``) or hands back to the policy (``False``).

        Raises:
            Refused: ``no_policy``: there is no policy to hand back to or take over from.
        """
        if self.policy is None:
            raise Refused("no_policy", "no policy drives this session (start it with --policy)")
        self._human = human

    def chunk(self, td: TensorDictBase) -> tuple[torch.Tensor, bool]:
        """The next ``[1, 4, 2]`` chunk for the observation ``td`` and whether the person
        drives it (their input held for the chunk's 4 actions)."""
        with self._lock:
            control, human = self._control, self._human
        if human:
            action = torch.tensor([control.throttle, control.steering], dtype=torch.float32)
            return action.expand(1, CHUNK, 2).clone(), True
        return bounded(self.policy.chunks(td)), False
