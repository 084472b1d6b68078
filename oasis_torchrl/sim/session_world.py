"""The world side of a session: simulator, expert, encoders, rollout position, last answer.

A :class:`SessionWorld` is what a session *is* to the simulation: it runs wherever the server
keeps its worlds, in the server's own process (:class:`LocalWorlds`) or in a worker process
(:mod:`oasis_torchrl.sim.worker_pool`). Both give the server the same :class:`WorldHandle`, and
every answer comes back already serialised (the bytes gRPC sends), so a world in another
process costs no second encoding.
"""

from __future__ import annotations

import logging
from concurrent.futures import Executor, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from oasis_torchrl.proto import a2v_pb2, common_pb2, sim_pb2
from oasis_torchrl.protocol import CAMERAS
from oasis_torchrl.sim.autopilot import Autopilot
from oasis_torchrl.sim.config import ServerConfig
from oasis_torchrl.sim.encoding import FrameEncoder, make_encoder
from oasis_torchrl.sim.errors import RequestError
from oasis_torchrl.sim.simulator import Simulator

logger = logging.getLogger(__name__)

#: Builds a simulator from ``(width, height, fps)``; the real :class:`Simulator` by default.
SimulatorFactory = Any


@dataclass(frozen=True)
class InferRecord:
    """The answer to one Infer: the serialised ``InferResponse`` and ``InferTruth``."""

    response: bytes
    truth: bytes


class WorldHandle(Protocol):
    """A session's world as the server drives it, wherever it runs."""

    def prompt(self, prompt: str, seed: int) -> None:
        """Set a new scene (the rollout restarts at sequence number 0)."""
        ...

    def infer(self, sequence_num: int, actions: np.ndarray) -> InferRecord:
        """Advance by 4 actions (or replay the last answer for a retried sequence number)."""
        ...

    def depth(self) -> bytes:
        """The serialised ``DepthResponse`` of the last frame of each stream."""
        ...

    def scene(self) -> bytes:
        """The serialised ``SceneResponse`` of the current scene."""
        ...

    def release(self) -> None:
        """Drop the world (the session is over)."""
        ...


class WorldHost(Protocol):
    """Where a server keeps its sessions' worlds."""

    def start(self) -> None:
        """Get ready to open worlds."""
        ...

    def open(self, session_id: str, output_format: int) -> WorldHandle:
        """A new session's world (built at its first Prompt)."""
        ...

    def close(self) -> None:
        """Release everything the host runs."""
        ...


class SessionWorld:
    """One session's simulator, its expert (the autopilot, restarted at every Prompt), one
    encoder per stream, and the rollout position with the last answer for retries.

    The simulator and encoders are built at the first Prompt. Streams are encoded on
    ``encode_pool`` when encoding is slow (VP9, JPEG) and there is a pool, else one by one.

    Example:
        >>> from concurrent.futures import ThreadPoolExecutor
        >>> config = ServerConfig(width=64, height=48, api_keys=("k",))
        >>> with ThreadPoolExecutor(3) as pool:
        ...     world = SessionWorld(common_pb2.FRAME_FORMAT_JPEG, config, pool)
        ...     world.prompt("a quiet road", seed=3)
        ...     record = world.infer(0, np.zeros((4, 2), np.float32))
        >>> [len(s.frames) for s in a2v_pb2.InferResponse.FromString(record.response).streams]
        [4, 4, 4]
    """

    def __init__(
        self,
        output_format: int,
        config: ServerConfig,
        encode_pool: Executor | None,
        simulator_factory: SimulatorFactory = Simulator,
    ) -> None:
        self.output_format = output_format
        self._config = config
        self._encode_pool = encode_pool
        self._simulator_factory = simulator_factory
        self._simulator: Any = None
        self._expert: Autopilot | None = None
        self._encoders: dict[str, FrameEncoder] = {}
        self._seed = 0
        self._next_sequence_num = 0
        self._last: tuple[int, np.ndarray, InferRecord] | None = None

    def prompt(self, prompt: str, seed: int) -> None:
        """Set a new scene: reset the world and the expert, restart every stream with a key
        frame."""
        if self._simulator is None:
            config = self._config
            self._simulator = self._simulator_factory(
                width=config.width, height=config.height, fps=config.fps
            )
            self._encoders = {
                name: make_encoder(
                    self.output_format,
                    config.width,
                    config.height,
                    config.fps,
                    **config.encoder_settings(),
                )
                for name in CAMERAS
            }
        self._simulator.reset(prompt, seed)
        self._expert = Autopilot(self._simulator)
        for encoder in self._encoders.values():
            encoder.restart()
        self._seed = seed
        self._next_sequence_num = 0
        self._last = None

    def infer(self, sequence_num: int, actions: np.ndarray) -> InferRecord:
        """Advance the world by 4 actions and encode the frames, or replay the last call."""
        self._require_prompt()
        if self._last is not None and sequence_num == self._last[0]:
            if not np.array_equal(actions, self._last[1]):
                raise RequestError(
                    common_pb2.ERROR_CODE_INVALID_REQUEST,
                    f"sequence_num {sequence_num} was already processed with other actions; "
                    f"expected sequence_num {self._next_sequence_num}",
                )
            return self._last[2]
        if sequence_num != self._next_sequence_num:
            raise RequestError(
                common_pb2.ERROR_CODE_INVALID_REQUEST,
                f"unexpected sequence_num: expected {self._next_sequence_num}, got {sequence_num}"
                " (it restarts at 0 after every Prompt)",
                {"expected": str(self._next_sequence_num), "got": str(sequence_num)},
            )
        result = self._simulator.step(actions)
        encode = lambda name: self._encode(name, result.rgb[name])  # noqa: E731
        pool = self._encode_pool if self._encoders[CAMERAS[0]].threaded else None
        streams = map(encode, CAMERAS) if pool is None else pool.map(encode, CAMERAS)
        truth = sim_pb2.InferTruth(
            sequence_num=sequence_num,
            seed=self._seed,
            frames=[frame.to_proto() for frame in result.truth],
            expert_actions=self._expert.act().ravel().tolist(),
        )
        response = a2v_pb2.InferResponse(sequence_num=sequence_num, streams=list(streams))
        record = InferRecord(response.SerializeToString(), truth.SerializeToString())
        self._last = (sequence_num, actions, record)
        self._next_sequence_num = sequence_num + 1
        return record

    def depth(self) -> bytes:
        """Metric depth of the last frame of each stream, as little-endian float16."""
        self._require_prompt()
        depths = self._simulator.depth()
        with np.errstate(over="ignore"):  # beyond float16 range (65504 m) is as good as inf
            maps = [
                sim_pb2.DepthMap(
                    name=name,
                    height=depths[name].shape[0],
                    width=depths[name].shape[1],
                    depth_f16=depths[name].astype("<f2").tobytes(),
                )
                for name in CAMERAS
            ]
        last_sequence_num = self._last[0] if self._last is not None else 0
        return sim_pb2.DepthResponse(sequence_num=last_sequence_num, maps=maps).SerializeToString()

    def scene(self) -> bytes:
        """The static world of the current scene."""
        self._require_prompt()
        return self._simulator.scene_proto().SerializeToString()

    def release(self) -> None:
        """Drop the simulator (its threads stopped), the expert and the encoders."""
        if self._simulator is not None:
            self._simulator.close()
        self._simulator = None
        self._expert = None
        self._encoders = {}
        self._last = None

    def _require_prompt(self) -> None:
        if self._simulator is None:
            raise RequestError(
                common_pb2.ERROR_CODE_PROMPT_SET,
                "no scene yet: call Prompt before Infer (and before depth or scene queries)",
            )

    def _encode(self, name: str, frames: np.ndarray) -> a2v_pb2.OutputStream:
        encoder = self._encoders[name]
        return a2v_pb2.OutputStream(name=name, frames=[encoder.encode(frame) for frame in frames])


class LocalWorlds:
    """Sessions' worlds in one process, encoding on one shared thread pool (none when the
    config gives the process a single encoder thread).

    Example:
        >>> worlds = LocalWorlds(ServerConfig(width=64, height=48, api_keys=("k",)))
        >>> worlds.start()
        >>> world = worlds.open("id", common_pb2.FRAME_FORMAT_JPEG)
        >>> world.prompt("rural", 1)
        >>> worlds.close()
    """

    def __init__(
        self, config: ServerConfig, simulator_factory: SimulatorFactory = Simulator
    ) -> None:
        self._config = config
        self._simulator_factory = simulator_factory
        threads = config.resolved_encode_workers
        self._encode_pool = (
            ThreadPoolExecutor(threads, thread_name_prefix="oasis-encode") if threads > 1 else None
        )

    def start(self) -> None:
        """Nothing to start: worlds are built in this process when sessions open."""

    def open(self, session_id: str, output_format: int) -> SessionWorld:
        """A new world for session ``session_id``."""
        return SessionWorld(output_format, self._config, self._encode_pool, self._simulator_factory)

    def close(self) -> None:
        """Stop the encoder threads."""
        if self._encode_pool is not None:
            self._encode_pool.shutdown(wait=True)
