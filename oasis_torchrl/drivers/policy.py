"""A torch policy as a driver: the driving network (a LeRobot ``oasis`` folder, a PPO
checkpoint), any TorchScript or ``torch.save``d module, or a policy served over the network."""

from __future__ import annotations

import pickle
from collections.abc import Sequence
from pathlib import Path

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import Composite

from oasis_torchrl.drivers.base import Driver
from oasis_torchrl.drivers.folders import load_net
from oasis_torchrl.models import DrivingNet, make_deterministic_actor, observation_spec
from oasis_torchrl.models.actor_critic import FRAME_STACK
from oasis_torchrl.models.checkpoint import load_checkpoint, net_from_checkpoint
from oasis_torchrl.models.config import POLICY_FRAMES
from oasis_torchrl.protocol import CAMERAS, CHUNK, FRONT_CROP
from oasis_torchrl.remote import RemotePolicy


def load_module(path: str | Path) -> torch.nn.Module:
    """A TorchScript archive or a ``torch.save``d module (unpickling runs code: trust the file).

    Example:
        >>> import tempfile
        >>> path = Path(tempfile.mkdtemp()) / "linear.pt"
        >>> torch.jit.save(torch.jit.script(torch.nn.Linear(2, 8)), path)
        >>> isinstance(load_module(path), torch.jit.ScriptModule)
        True
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"policy file {path} does not exist")
    try:
        return torch.jit.load(str(path), map_location="cpu")
    except RuntimeError:
        module = torch.load(path, map_location="cpu", weights_only=False)
    if not isinstance(module, torch.nn.Module):
        raise TypeError(f"{path} holds a {type(module).__name__}, not a torch module")
    return module


def _checkpoint_or_none(path: Path) -> dict | None:
    """The PPO checkpoint at ``path``, or None if the file is something else (a module)."""
    try:
        return load_checkpoint(path)
    except (ValueError, RuntimeError, pickle.UnpicklingError):
        return None


def _as_chunks(action: torch.Tensor, rows: int) -> torch.Tensor:
    """A policy output ``[N, 4, 2]``, ``[N, 8]`` or ``[N, 2]`` as ``[N, 4, 2]`` chunks."""
    action = action.detach().to("cpu", torch.float32)
    if action.shape in ((rows, CHUNK, 2), (rows, CHUNK * 2)):
        return action.reshape(rows, CHUNK, 2)
    if action.shape == (rows, 2):
        return action.unsqueeze(1).expand(-1, CHUNK, 2)
    raise ValueError(
        f"policy action must be [{rows}, 4, 2], [{rows}, 8] or [{rows}, 2], "
        f"got {list(action.shape)}"
    )


class PolicyDriver(Driver):
    """Drives with a torch policy.

    A TensorDict module (``tensordict.nn``) is called on the observation and must set
    ``"action"``; a plain module (e.g. TorchScript) is called with the tensors at ``in_keys``
    (default: ``("pixels", camera)`` of ``left_forward``, ``front``, ``right_forward`` as far
    as present, uint8 as the env gives them, then ``"state"``) and returns the actions.
    Outputs are clamped to [-1, 1]; NaN is an error.

    Args:
        module: the policy.
        in_keys: inputs of a plain module.
        image_size: see :attr:`Driver.image_size`.
        frame_stack: see :attr:`Driver.frame_stack`.
        observation_spec: see :attr:`Driver.observation_spec`.
        front_crop: see :attr:`Driver.front_crop`.
        chunk_actions: see :class:`Driver`.

    Example:
        >>> from tensordict import TensorDict
        >>> class Half(torch.nn.Module):
        ...     def forward(self, state):
        ...         return state * 0.5
        >>> driver = PolicyDriver(Half(), in_keys=["state"])
        >>> driver(TensorDict(state=torch.ones(3, 2), batch_size=[3]))["action"].shape
        torch.Size([3, 4, 2])
    """

    def __init__(
        self,
        module: torch.nn.Module,
        in_keys: Sequence[str | tuple[str, ...]] | None = None,
        *,
        image_size: tuple[int, int] | None = None,
        frame_stack: int = POLICY_FRAMES,
        observation_spec: Composite | None = None,
        front_crop: float | None = None,
        chunk_actions: bool = True,
    ) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self.front_crop = front_crop
        self.module = module.eval()
        self.in_keys = list(in_keys) if in_keys is not None else None
        self.image_size = image_size
        self.frame_stack = frame_stack
        self.observation_spec = observation_spec
        read = [] if observation_spec is None else observation_spec.keys(True, True)
        self._stack_keys = [key for key in read if isinstance(key, tuple) and key[0] == FRAME_STACK]

    @classmethod
    def of_network(cls, net: DrivingNet, **kwargs: object) -> PolicyDriver:
        """The deterministic actor of a driving network (its chunk ``tanh(loc)``), at the
        network's image size.

        Example:
            >>> driver = PolicyDriver.of_network(DrivingNet())
            >>> driver.image_size, driver.frame_stack, driver.observation_spec["state"].shape
            ((64, 96), 2, torch.Size([2]))
        """
        return cls(
            make_deterministic_actor(net),
            image_size=tuple(net.config.image_size),
            frame_stack=net.config.frames,
            observation_spec=observation_spec(net),
            front_crop=net.config.front_crop,
            **kwargs,
        )

    @classmethod
    def load(cls, path: str | Path, **kwargs: object) -> PolicyDriver:
        """Load a saved policy: a LeRobot policy folder or PPO checkpoint of the driving network,
        or any TorchScript / ``torch.save``d module (see :func:`load_module`)."""
        path = Path(path)
        if path.is_dir():
            return cls.of_network(load_net(path), **kwargs)
        if not path.is_file():
            raise FileNotFoundError(f"policy file {path} does not exist")
        payload = _checkpoint_or_none(path)
        if payload is not None:
            return cls.of_network(net_from_checkpoint(payload), **kwargs)
        return cls(load_module(path), **kwargs)

    @classmethod
    def remote(cls, url: str, **kwargs: object) -> PolicyDriver:
        """The policy a policy server serves (``grpc://host:port``, ``grpcs://`` with TLS; the
        key from ``$OASIS_POLICY_API_KEY``), at its image size."""
        policy = RemotePolicy(url)
        frame_stack = policy.frame_stack or POLICY_FRAMES
        return cls(policy, image_size=policy.image_size, frame_stack=frame_stack, **kwargs)

    def _inputs(self, td: TensorDictBase) -> list[torch.Tensor]:
        if self.in_keys is not None:
            return [td.get(key) for key in self.in_keys]
        keys = td.keys(True)
        pixels = [("pixels", c) for c in CAMERAS if ("pixels", c) in keys]
        return [td.get(key) for key in pixels] + [td.get("state")]

    def _check_frame_stack(self, td: TensorDictBase) -> None:
        """Name the missing frame stack (a bare ``OasisEnv``) instead of a bare KeyError."""
        missing = [key for key in self._stack_keys if key not in td.keys(True)]
        if (FRAME_STACK, FRONT_CROP) in missing:
            raise ValueError(
                f"the policy reads the front crop (a fraction {self.front_crop} of the front "
                f"frame), which the env does not give: build it with env.front_crop="
                f"{self.front_crop}"
            )
        if missing:
            raise ValueError(
                f"the policy reads {missing[0]} (frames one chunk apart), which the env does not "
                "give: build it with oasis_torchrl.envs.make_env, or append "
                "oasis_torchrl.envs.ChunkFrameStack(env.layout.cameras) to it"
            )

    @torch.no_grad()
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """Run the policy on ``td``."""
        self._check_frame_stack(td)
        if isinstance(self.module, TensorDictModuleBase):
            action = self.module(td.clone(False)).get("action")
        else:
            action = self.module(*self._inputs(td))
        chunk = _as_chunks(action, td.batch_size[0])
        if torch.isnan(chunk).any():
            raise ValueError("the policy returned NaN actions")
        return chunk
