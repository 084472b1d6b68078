"""Drivers: TorchRL-policy-like callables ``td -> td`` that set ``"action"``, and the one
grammar that names them (:func:`load_driver`).

- :class:`Autopilot`: the embedded server's privileged expert; the server runs it next to each
  session's world and sends its next chunk with the ground truth, which an env built with
  ``expert=True`` exposes as ``"expert_action"`` (a driver's :attr:`~Driver.needs_expert`).
- :class:`ScriptedDriver`: constant or sinusoidal throttle and steering from a small spec.
- :class:`PolicyDriver`: a torch policy: the driving network of a LeRobot policy folder or a PPO
  checkpoint, any TorchScript / ``torch.save``d module, or a policy served by a policy server
  (``grpc://host:port``, :class:`~oasis_torchrl.serving.RemotePolicy`).
- :class:`~oasis_torchrl.lerobot_driver.LeRobotDriver`: any other LeRobot policy folder (``act``,
  ``diffusion``, plugins, ...) with its saved processors, four ``select_action`` calls per chunk.
- :class:`DriverSpec`: any of them named by a spec string, picklable, built where it drives
  (e.g. in a Ray worker: a loaded TorchScript policy does not pickle, its file name does).

Every driver returns action chunks ``[N, 4, 2]`` (or ``[N, 2]`` for an env built with
``chunk_actions=False``).
"""

from __future__ import annotations

import logging
import pickle
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.data import Composite

from oasis_torchrl.models import DrivingNet, make_deterministic_actor, observation_spec
from oasis_torchrl.models.checkpoint import load_checkpoint, load_net, net_from_checkpoint
from oasis_torchrl.protocol import CAMERAS, CHUNK
from oasis_torchrl.serving.client import RemotePolicy, is_policy_url

logger = logging.getLogger(__name__)


class Driver(ABC):
    """Base of the drivers: computes ``[N, 4, 2]`` chunks and writes them to ``"action"``.

    Args:
        chunk_actions: write ``[N, 4, 2]`` chunks; if false, ``[N, 2]`` (the chunk's first).

    Example:
        >>> from tensordict import TensorDict
        >>> class Stop(Driver):
        ...     def chunks(self, td):
        ...         return torch.zeros(td.batch_size[0], 4, 2)
        >>> Stop(chunk_actions=False)(TensorDict(batch_size=[3]))["action"].shape
        torch.Size([3, 2])
    """

    image_size: tuple[int, int] | None = None
    """``(height, width)`` of the frames the driver looks at (None: it does not look)."""
    needs_expert: bool = False
    """Whether the driver drives with the embedded server's expert: build its env with
    ``expert=True``."""
    observation_spec: Composite | None = None
    """What the driver reads of one row (shapes without batch dimensions; None: undeclared).
    A policy server describes its inputs with it."""
    n_action_steps: int = CHUNK
    """Actions of each :meth:`plan` a policy server queues for a row before planning again."""

    def __init__(self, *, chunk_actions: bool = True) -> None:
        self.chunk_actions = chunk_actions

    @abstractmethod
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """float32 ``[N, 4, 2]`` action chunks for the observation rows of ``td``."""

    def plan(self, td: TensorDictBase) -> torch.Tensor:
        """The actions ``[N, K, 2]`` (``K >= n_action_steps``) each row would take from its
        observation alone, bounded to ``[-1, 1]``: what a policy server queues for a row. The
        chunk, unless the driver keeps state between calls (a queue, a history): then it
        plans without touching that state."""
        return bounded(self.chunks(td))

    def __call__(self, td: TensorDictBase) -> TensorDictBase:
        """Set ``td["action"]`` and return ``td`` (as a TorchRL policy does)."""
        chunk = bounded(self.chunks(td))
        td.set("action", chunk if self.chunk_actions else chunk[:, 0].contiguous())
        return td


def bounded(actions: torch.Tensor) -> torch.Tensor:
    """Actions as float32 in ``[-1, 1]``, the world model's box.

    Example:
        >>> bounded(torch.tensor([2.0, -0.5], dtype=torch.float64))
        tensor([ 1.0000, -0.5000])
    """
    return actions.to(torch.float32).clamp(-1.0, 1.0)


# -- autopilot ----------------------------------------------------------------------------

EXPERT_ACTION = "expert_action"


class Autopilot(Driver):
    """The embedded server's privileged expert: drives with each row's ``"expert_action"``.

    The embedded server runs an autopilot beside every session's world (it knows the scene and
    the car's exact state) and sends the chunk it would take next with the ground truth; an env
    built with ``expert=True`` exposes it as ``"expert_action"``. Rows without one (NaN: the
    row's session was lost) get zeros.

    Args:
        chunk_actions: see :class:`Driver`.

    Example:
        >>> from tensordict import TensorDict
        >>> expert = torch.tensor([[[0.6, 0.1]] * 4, [[float("nan")] * 2] * 4])
        >>> Autopilot()(TensorDict(expert_action=expert, batch_size=[2]))["action"][:, 0]
        tensor([[0.6000, 0.1000],
                [0.0000, 0.0000]])
    """

    needs_expert = True

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """The expert's next chunk for every row."""
        expert = td.get(EXPERT_ACTION, None)
        if expert is None:
            raise KeyError(
                f"the autopilot drives with {EXPERT_ACTION!r}, which only the embedded server "
                "sends, to an env built with expert=True (endpoint 'local', or an "
                "'oasis-torchrl serve' server)"
            )
        return torch.nan_to_num(expert, nan=0.0)


# -- scripted driver ----------------------------------------------------------------------

Signal = Callable[[np.ndarray], np.ndarray]


def _parse_signal(name: str, text: str) -> Signal:
    """``"0.5"`` (constant) or ``"sine:AMPLITUDE:PERIOD[:OFFSET]"`` (period in frames)."""
    parts = text.split(":")
    try:
        if len(parts) == 1:
            level = float(parts[0])
            return lambda frames: np.full(frames.shape, level)
        if parts[0] == "sine" and len(parts) in (3, 4):
            amplitude, period = float(parts[1]), float(parts[2])
            offset = float(parts[3]) if len(parts) == 4 else 0.0
            if period <= 0:
                raise ValueError
            return lambda frames: offset + amplitude * np.sin(2 * np.pi * frames / period)
    except ValueError:
        pass
    raise ValueError(f"{name}={text!r}: expected a number or sine:AMPLITUDE:PERIOD_FRAMES[:OFFSET]")


class ScriptedDriver(Driver):
    """Open-loop driving from a spec such as ``"throttle=0.5,steering=sine:0.3:40"``.

    Each of ``throttle`` and ``steering`` is a constant or a sine over frames (period in
    frames, 20 per second); unset channels are 0. Time counts frames since the driver was
    created, the same for every row.

    Example:
        >>> from tensordict import TensorDict
        >>> driver = ScriptedDriver.from_spec("throttle=0.5,steering=sine:0.2:8")
        >>> chunk = driver(TensorDict(batch_size=[2]))["action"]
        >>> chunk.shape, chunk[0, :, 0].tolist(), round(chunk[0, 2, 1].item(), 3)
        (torch.Size([2, 4, 2]), [0.5, 0.5, 0.5, 0.5], 0.2)
    """

    def __init__(self, throttle: Signal, steering: Signal, *, chunk_actions: bool = True) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self._signals = (throttle, steering)
        self._frame = 0

    @classmethod
    def from_spec(cls, spec: str, *, chunk_actions: bool = True) -> ScriptedDriver:
        """Parse ``name=value`` pairs separated by commas (names: throttle, steering)."""
        signals = {"throttle": "0", "steering": "0"}
        for item in filter(None, (part.strip() for part in spec.split(","))):
            name, sep, value = item.partition("=")
            if not sep or name.strip() not in signals:
                raise ValueError(
                    f"bad driver spec item {item!r}: expected throttle=... or steering=..."
                )
            signals[name.strip()] = value.strip()
        throttle, steering = (_parse_signal(name, text) for name, text in signals.items())
        return cls(throttle, steering, chunk_actions=chunk_actions)

    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """The next 4 frames of the script, the same for every row."""
        frames = self._frame + np.arange(CHUNK)
        self._frame += CHUNK
        chunk = np.stack([signal(frames) for signal in self._signals], axis=-1)
        rows = td.batch_size[0] if td.batch_dims else 1
        return torch.from_numpy(chunk.astype(np.float32)).expand(rows, -1, -1)


# -- saved policy ---------------------------------------------------------------------------


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
        observation_spec: see :attr:`Driver.observation_spec`.
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
        observation_spec: Composite | None = None,
        chunk_actions: bool = True,
    ) -> None:
        super().__init__(chunk_actions=chunk_actions)
        self.module = module.eval()
        self.in_keys = list(in_keys) if in_keys is not None else None
        self.image_size = image_size
        self.observation_spec = observation_spec

    @classmethod
    def of_network(cls, net: DrivingNet, **kwargs: object) -> PolicyDriver:
        """The deterministic actor of a driving network (its chunk ``tanh(loc)``), at the
        network's image size.

        Example:
            >>> driver = PolicyDriver.of_network(DrivingNet())
            >>> driver.image_size, driver.observation_spec["state"].shape
            ((64, 96), torch.Size([2]))
        """
        return cls(
            make_deterministic_actor(net),
            image_size=tuple(net.config.image_size),
            observation_spec=observation_spec(net),
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
        return cls(policy, image_size=policy.image_size, **kwargs)

    def _inputs(self, td: TensorDictBase) -> list[torch.Tensor]:
        if self.in_keys is not None:
            return [td.get(key) for key in self.in_keys]
        keys = td.keys(True)
        pixels = [("pixels", c) for c in CAMERAS if ("pixels", c) in keys]
        return [td.get(key) for key in pixels] + [td.get("state")]

    @torch.no_grad()
    def chunks(self, td: TensorDictBase) -> torch.Tensor:
        """Run the policy on ``td``."""
        if isinstance(self.module, TensorDictModuleBase):
            action = self.module(td.clone(False)).get("action")
        else:
            action = self.module(*self._inputs(td))
        chunk = _as_chunks(action, td.batch_size[0])
        if torch.isnan(chunk).any():
            raise ValueError("the policy returned NaN actions")
        return chunk


# -- one grammar for naming a driver ---------------------------------------------------------

AUTOPILOT = "autopilot"
SCRIPTED = ("scripted:", "constant:")
GRAMMAR = (
    "'autopilot', 'scripted:<script>' (or 'constant:<script>', e.g. "
    "'constant:throttle=1.0,steering=0.0'), the path of a saved policy (a LeRobot policy "
    "folder of any type LeRobot loads, a PPO checkpoint, a TorchScript or torch.save file), or "
    "a policy server ('grpc://host:port', 'grpcs://host:port' with TLS)"
)
NETWORK_POLICY_TYPE = "oasis"
"""The LeRobot policy type whose folders load as the driving network itself."""


def load_driver(
    spec: str | Path, *, in_keys: Sequence[str | tuple[str, ...]] | None = None
) -> Driver:
    """The driver a spec names (:data:`GRAMMAR`), everywhere a driver or policy is named:
    ``oasis-torchrl eval policy=``, ``record --driver``, the pipeline's references and learners.

    A LeRobot policy folder of type ``oasis`` loads as the driving network
    (:class:`PolicyDriver`, the TorchRL actor); any other type through LeRobot's factory and
    the processors saved with it (:class:`~oasis_torchrl.lerobot_driver.LeRobotDriver`).

    Args:
        spec: the driver's name.
        in_keys: inputs of a plain saved module (see :class:`PolicyDriver`).

    Example:
        >>> type(load_driver("constant:throttle=1.0")).__name__
        'ScriptedDriver'
        >>> load_driver("nowhere.pt")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        ValueError: driver 'nowhere.pt' is none of 'autopilot', 'scripted:<script>' ...
    """
    text = str(spec)
    if text == AUTOPILOT:
        return Autopilot()
    for prefix in SCRIPTED:
        if text.startswith(prefix):
            return ScriptedDriver.from_spec(text.removeprefix(prefix))
    if is_policy_url(text):
        return PolicyDriver.remote(text)
    path = Path(text)
    if not path.exists():
        raise ValueError(f"driver {text!r} is none of {GRAMMAR}")
    if path.is_dir():
        from oasis_torchrl.lerobot_driver import LeRobotDriver, policy_type

        if policy_type(path) != NETWORK_POLICY_TYPE:
            return LeRobotDriver.load(path)
    return PolicyDriver.load(path, in_keys=in_keys)


@dataclass(frozen=True)
class DriverSpec:
    """A driver named by plain values: picklable and small, so it can be shipped (to a Ray
    worker, say) and built there by calling it.

    Args:
        spec: the driver (:func:`load_driver`); a path is made absolute (a worker may run
            elsewhere).
        in_keys: inputs of a plain saved module (see :class:`PolicyDriver`).

    Example:
        >>> import pickle
        >>> spec = pickle.loads(pickle.dumps(DriverSpec("scripted:throttle=0.3")))
        >>> type(spec()).__name__
        'ScriptedDriver'
    """

    spec: str = AUTOPILOT
    in_keys: tuple[tuple[str, ...], ...] | None = None

    def __post_init__(self) -> None:
        if Path(self.spec).exists():
            object.__setattr__(self, "spec", str(Path(self.spec).absolute()))

    def __call__(self) -> Driver:
        """Build the driver."""
        return load_driver(self.spec, in_keys=self.in_keys)
