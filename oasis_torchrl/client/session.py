"""One A2V session's state machine, without I/O: the sync client and the pool both drive it.

:class:`SessionState` builds every call of a session (request plus metadata: the API key, the
pinning target Initialize returned, a Prompt's seed) and interprets every answer one way:
in-band errors raised as :class:`~oasis_torchrl.client.errors.A2VError` subclasses (API key
masked), the negotiated format and the streams checked, sequence numbers counted (restarting at
0 after each Prompt), the prompt and seed kept for a replay, one stateful decoder per stream
reset at every new clip, ground truth read from the trailing metadata. The transports (blocking
stubs in ``sync_client``, asyncio stubs in ``pool``) only send the :class:`Call` it returns and
hand the answer back.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from oasis_torchrl.client import wire
from oasis_torchrl.client.decoding import FrameDecoder, FrontCrop, make_decoder
from oasis_torchrl.client.errors import DecartRoboticsError
from oasis_torchrl.client.ground_truth import parse_truth
from oasis_torchrl.client.types import FrameFormat
from oasis_torchrl.proto import a2v_pb2, sim_pb2

MetadataItems = Iterable[tuple[str, str | bytes]]
SIM_METHODS = frozenset({"GetDepth", "GetScene"})
"""The methods of the embedded simulator's ``SimService``; every other call is ``A2VService``'s."""


@dataclass(frozen=True)
class Call:
    """One unary call to send: the method's name (an ``A2VService`` method, or one of
    :data:`SIM_METHODS`), its request and its metadata.

    >>> call = Call("Finish", a2v_pb2.FinishRequest(session_id="s"), ())
    >>> call.method, call.on_sim_service
    ('Finish', False)
    """

    method: str
    request: object
    metadata: wire.Metadata

    @property
    def on_sim_service(self) -> bool:
        """Whether the call goes to ``SimService`` (else ``A2VService``)."""
        return self.method in SIM_METHODS


@dataclass(frozen=True)
class InferReply:
    """A successful Infer: its sequence number, the packets of each stream, the ground truth
    (None when the server sends none)."""

    sequence_num: int
    packets: dict[str, Sequence[bytes]]
    truth: sim_pb2.InferTruth | None


class SessionState:
    """Where one A2V session stands, and the calls that move it on.

    Args:
        api_key: The key sent in Initialize and on every call.
        sdk_version: ``client_sdk_version`` of Initialize.
        accepted_formats: Frame formats offered, in preference order.
        required_streams: Streams the server must advertise.
        decoder_threads: Threads of each stream's decoder (0: the codec's choice).
        last_frame_only: Ask for the last frame of each chunk alone (``x-oasis-frames``); a
            server that does not grant it sends all 4.
        expert: Ask every Prompt for the embedded server's expert (``x-oasis-expert``), whose
            next chunk then comes with the ground truth of every Infer.
        front_crop: The fraction of the ``front`` frame a derived narrow camera reads
            (:class:`~oasis_torchrl.client.decoding.FrontCrop`; None: none).

    >>> state = SessionState("k", sdk_version="0.0.2", accepted_formats=[FrameFormat.VP9],
    ...                      required_streams=["front"])
    >>> call = state.initialize()
    >>> call.method, call.metadata
    ('Initialize', (('x-api-key', 'k'),))
    >>> state.infer(np.zeros((4, 2), np.float32))
    Traceback (most recent call last):
    ...
    oasis_torchrl.client.errors.DecartRoboticsError: A2V session is not initialized
    """

    def __init__(
        self,
        api_key: str | None,
        *,
        sdk_version: str,
        accepted_formats: Sequence[FrameFormat],
        required_streams: Sequence[str],
        decoder_threads: int = 0,
        last_frame_only: bool = False,
        expert: bool = False,
        front_crop: float | None = None,
    ) -> None:
        self.api_key = api_key
        self.front_crop = None if front_crop is None else FrontCrop(front_crop)
        self.last_frame_only = last_frame_only
        self.expert = expert
        self.sdk_version = sdk_version
        self.accepted_formats = tuple(accepted_formats)
        self.required_streams = tuple(required_streams)
        self.decoder_threads = decoder_threads
        self.info: wire.SessionInfo | None = None
        self.metadata: wire.Metadata = wire.call_metadata(api_key)
        self.sequence_num = 0
        self.prompt_text: str | None = None
        self.seed: int | None = None
        self._asked: tuple[str, int | None] | None = None
        self.decoders: dict[str, FrameDecoder] = {}

    @property
    def session_id(self) -> str | None:
        """The open session's id (None before Initialize and after Finish)."""
        return self.info.session_id if self.info is not None else None

    def initialize(self) -> Call:
        """The Initialize call (raises before any I/O when there is no API key)."""
        if not self.api_key:
            raise wire.missing_api_key_error()
        request = wire.initialize_request(self.sdk_version, self.api_key, self.accepted_formats)
        return Call(
            "Initialize", request, wire.initialize_metadata(self.api_key, self.last_frame_only)
        )

    def on_initialize(
        self, response: a2v_pb2.InitializeResponse, initial_metadata: MetadataItems
    ) -> wire.SessionInfo:
        """Take Initialize's answer. If the server chose a format or streams this client
        cannot use, the session is open but unusable: this raises, and the caller Finishes it
        (:meth:`finish`)."""
        wire.raise_if_error(response, self.api_key)
        info = wire.parse_session(response, initial_metadata)
        self.info, self.sequence_num = info, 0
        self.metadata = wire.call_metadata(self.api_key, info.session_target)
        wire.check_session(
            info, accepted_formats=self.accepted_formats, required_streams=self.required_streams
        )
        self.decoders = {
            stream.name: make_decoder(
                info.output_format,
                stream.name,
                (stream.height, stream.width),
                threads=self.decoder_threads,
            )
            for stream in info.streams
        }
        return info

    def prompt(self, prompt: str, seed: int | None) -> Call:
        """The Prompt call (``seed`` travels as ``x-oasis-seed``; None: the server's default)."""
        request = a2v_pb2.PromptRequest(session_id=self._require_id(), prompt=prompt)
        call = Call("Prompt", request, wire.prompt_metadata(self.metadata, seed, self.expert))
        self._asked = (prompt, seed)
        return call

    def replay_prompt(self) -> Call:
        """The Prompt call of the last prompt and seed (a new clip of the same world)."""
        if self.prompt_text is None:
            raise DecartRoboticsError("the session was never prompted")
        return self.prompt(self.prompt_text, self.seed)

    def on_prompt(self, response: a2v_pb2.PromptResponse) -> None:
        """Take the answer of the last :meth:`prompt`: the rollout restarts (sequence 0, a new
        clip for every decoder) and its prompt and seed are kept for :meth:`replay_prompt`."""
        wire.raise_if_error(response, self.api_key)
        assert self._asked is not None, "on_prompt answers a prompt() call"
        (self.prompt_text, self.seed), self._asked = self._asked, None
        self.sequence_num = 0
        for decoder in self.decoders.values():
            decoder.reset()

    def infer(self, actions: np.ndarray) -> Call:
        """The Infer call of one validated ``(4, 2)`` action chunk, at the next sequence number."""
        request = wire.infer_request(self._require_id(), self.sequence_num, actions)
        return Call("Infer", request, self.metadata)

    def on_infer(
        self, response: a2v_pb2.InferResponse, trailing_metadata: MetadataItems | None
    ) -> InferReply:
        """Take Infer's answer: the sequence number advances."""
        wire.raise_if_error(response, self.api_key)
        self.sequence_num += 1
        return InferReply(
            sequence_num=response.sequence_num,
            packets={stream.name: stream.frames for stream in response.streams},
            truth=parse_truth(trailing_metadata),
        )

    def depth(self) -> Call:
        """The ``SimService/GetDepth`` call (the embedded simulator only)."""
        return Call("GetDepth", sim_pb2.DepthRequest(session_id=self._require_id()), self.metadata)

    def scene(self) -> Call:
        """The ``SimService/GetScene`` call: the static world of the current prompt and seed
        (the embedded simulator only)."""
        return Call("GetScene", sim_pb2.SceneRequest(session_id=self._require_id()), self.metadata)

    def finish(self) -> Call | None:
        """The Finish call of the open session, or None. The session is forgotten first, so a
        failing Finish is never sent twice."""
        if self.info is None:
            return None
        request = a2v_pb2.FinishRequest(session_id=self.info.session_id)
        self.info = None
        return Call("Finish", request, self.metadata)

    def on_finish(self, response: a2v_pb2.FinishResponse) -> None:
        """Take Finish's answer (raises its in-band error, if any)."""
        wire.raise_if_error(response, self.api_key)

    def _require_id(self) -> str:
        if self.info is None:
            raise DecartRoboticsError("A2V session is not initialized")
        return self.info.session_id
