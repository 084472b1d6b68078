"""The action queues SelectAction serves from: one per row of every client session.

A client names its session with any id; the session is private to the API key that used it
(another key naming the same id gets a session of its own). A row whose queue is empty gets
the next actions of a new chunk (the rows of one call that need one share a single forward
pass); every call takes the same number of actions from each row's queue. Reset drops rows'
queues. Sessions idle longer than ``idle_timeout`` are forgotten; the number of sessions is
bounded in total and per key (RESOURCE_EXHAUSTED).
"""

from __future__ import annotations

import re
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import grpc
import torch
from tensordict import TensorDictBase

from oasis_torchrl.sim.auth import key_fingerprint
from oasis_torchrl.sim.errors import StatusError

ChunkCall = Callable[[TensorDictBase], torch.Tensor]
_SESSION_ID = re.compile(r"[\x21-\x7e]{1,128}")


@dataclass
class _Session:
    queues: dict[int, deque[torch.Tensor]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)
    last_used: float = field(default_factory=time.monotonic)


class ActionQueues:
    """Per-row action queues of the client sessions of one server.

    Args:
        max_sessions: sessions at most (all keys).
        max_sessions_per_key: sessions of one key at most.
        idle_timeout: seconds after which an unused session is forgotten.

    Example:
        >>> from tensordict import TensorDict
        >>> queues = ActionQueues(max_sessions=8, max_sessions_per_key=4, idle_timeout=60)
        >>> chunk = lambda td: td["x"].reshape(-1, 1, 1) + torch.arange(4.0).reshape(1, 4, 1)
        >>> observation = TensorDict(x=torch.tensor([10.0, 20.0]), batch_size=[2])
        >>> [queues.select(b"key", "s", observation, chunk).flatten().tolist() for _ in range(2)]
        [[10.0, 20.0], [11.0, 21.0]]
        >>> queues.reset(b"key", "s", rows=[1])
        >>> queues.select(b"key", "s", observation, chunk, count=3).flatten().tolist()
        [12.0, 13.0, 10.0, 20.0, 21.0, 22.0]
    """

    def __init__(
        self, *, max_sessions: int, max_sessions_per_key: int, idle_timeout: float
    ) -> None:
        self.max_sessions = max_sessions
        self.max_sessions_per_key = max_sessions_per_key
        self.idle_timeout = idle_timeout
        self._sessions: dict[tuple[bytes, str], _Session] = {}
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._sessions)

    def select(
        self,
        key: bytes,
        session_id: str,
        observation: TensorDictBase,
        next_actions: ChunkCall,
        count: int = 1,
    ) -> torch.Tensor:
        """The next ``count`` actions of every row of ``observation`` (``[rows, count, ...]``);
        a row whose queue runs out gets ``next_actions`` of its observation (the rows that need
        them in one call, ``[k, n, ...]``)."""
        session = self._session(key, session_id)
        with session.lock:
            rows = observation.batch_size[0]
            taken: list[list[torch.Tensor]] = [[] for _ in range(rows)]
            while len(taken[0]) < count:
                self._refill(session, observation, next_actions)
                for row in range(rows):
                    queue = session.queues[row]
                    while queue and len(taken[row]) < count:
                        taken[row].append(queue.popleft())
            session.last_used = time.monotonic()
        return torch.stack([torch.stack(actions) for actions in taken])

    @staticmethod
    def _refill(session: _Session, observation: TensorDictBase, next_actions: ChunkCall) -> None:
        """Queue new actions for the rows whose queue is empty."""
        empty = [row for row in range(observation.batch_size[0]) if not session.queues.get(row)]
        if not empty:
            return
        chunks = next_actions(observation[torch.tensor(empty)])
        for row, chunk in zip(empty, chunks, strict=True):
            session.queues[row] = deque(chunk.unbind(0))

    def reset(self, key: bytes, session_id: str, rows: Sequence[int] = ()) -> None:
        """Drop the queued actions of ``rows`` of a session (all rows when empty); a session
        never used has nothing to drop."""
        _check_session_id(session_id)
        with self._lock:
            session = self._sessions.get((key, session_id))
        if session is None:
            return
        with session.lock:
            for row in rows or list(session.queues):
                session.queues.pop(row, None)
            session.last_used = time.monotonic()

    def _session(self, key: bytes, session_id: str) -> _Session:
        _check_session_id(session_id)
        with self._lock:
            session = self._sessions.get((key, session_id))
            if session is not None:
                return session
            self._forget_idle()
            if len(self._sessions) >= self.max_sessions:
                raise StatusError(
                    grpc.StatusCode.RESOURCE_EXHAUSTED,
                    f"the server holds {self.max_sessions} sessions, its limit; retry later",
                )
            if sum(k == key for k, _ in self._sessions) >= self.max_sessions_per_key:
                raise StatusError(
                    grpc.StatusCode.RESOURCE_EXHAUSTED,
                    f"key {key_fingerprint(key)} holds {self.max_sessions_per_key} sessions, "
                    "its limit; reuse a session id or let idle ones expire",
                )
            session = self._sessions[(key, session_id)] = _Session()
            return session

    def _forget_idle(self) -> None:
        oldest = time.monotonic() - self.idle_timeout
        for name in [name for name, s in self._sessions.items() if s.last_used < oldest]:
            del self._sessions[name]


def _check_session_id(session_id: str) -> None:
    if not _SESSION_ID.fullmatch(session_id):
        raise StatusError(
            grpc.StatusCode.INVALID_ARGUMENT,
            "session_id must be 1-128 printable ASCII characters without spaces",
        )
