"""The driven session: one world-model session stepped on a thread of its own, paced at the
world's rate (a chunk of 4 actions every ``period`` seconds, 0.2 s at 20 fps).

Each chunk: the :class:`~oasis_torchrl.web.takeover.Pilot` gives the actions (the person's input
or the policy's), the env steps, the step goes to the :class:`EpisodeRecording` if an episode
runs, and the 4 frame times go out as frame messages (:mod:`oasis_torchrl.web.frames`) followed
by one status message. A chunk that ends after its slot is counted late, and the next one is
timed from then (the world never races to catch up). Page commands (record, reset, takeover)
run on the session's thread between chunks, so the env and the dataset are only ever touched
there. The session idles while no page is connected.

A recorded step carries ``("next", "crash")`` (the dataset's ``next.crash``): the world's
collision where the endpoint sends ground truth, or the person's crash mark (the page's C key).
A mark lands on the chunk after the key press (about a person's reaction time later than what
they saw), ends the episode there and saves it; the scene goes on until the next reset.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import torch
from tensordict import TensorDictBase
from torchrl.envs import EnvBase
from torchrl.envs.utils import ExplorationType, set_exploration_type

from oasis_torchrl.data.chunk_rows import CRASH_STEP_KEY
from oasis_torchrl.data.features import INTERVENTION_KEY
from oasis_torchrl.web.frames import pack_frames
from oasis_torchrl.web.messages import Record, Refused, Reset, Takeover
from oasis_torchrl.web.recording import EpisodeRecording
from oasis_torchrl.web.takeover import Pilot

logger = logging.getLogger(__name__)

Publish = Callable[[bytes | dict[str, Any]], None]
Command = Record | Reset | Takeover
IDLE_S = 0.05
SHOWN_TRUTH = ("speed", "progress")
"""Ground truth the page shows where the server sends it (the hosted model does not)."""
RISKS = (("next", "reward_terms", "collision_ahead"), ("next", "reward_terms", "collision_risk"))
"""The page's risk bar: the motion reward's chance of a collision ahead (the frames-only
default), or the depth-collision reward's risk (``env.reward.kind=depth``)."""


def _known(value: torch.Tensor | None) -> float | None:
    """The last value of a per-frame tensor, or None where it is missing or NaN."""
    if value is None:
        return None
    last = float(value.reshape(-1)[-1])
    return last if math.isfinite(last) else None


def _risk(step: TensorDictBase) -> float | None:
    """The risk bar's value: the first of :data:`RISKS` the step holds, else None."""
    for key in RISKS:
        value = _known(step.get(key, None))
        if value is not None:
            return value
    return None


class DriveSession:
    """A world-model session driven from the page.

    Args:
        make_env: builds the one-row env (called on the session's thread): all 4 frames per
            chunk (``all_frames=True``), a ``"prompt"`` and ``"episode_seed"`` per step.
        pilot: who drives.
        publish: sends a frame message (bytes) or a status (dict) to every page; called on the
            session's thread, must not block.
        recording: where episodes go (None: recording is off).
        period: seconds per chunk (4 frames at the world's fps).
        jpeg_quality: quality of the frames sent.
    """

    def __init__(
        self,
        make_env: Callable[[], EnvBase],
        pilot: Pilot,
        publish: Publish,
        *,
        recording: EpisodeRecording | None = None,
        period: float = 0.2,
        jpeg_quality: int = 80,
    ) -> None:
        self.pilot = pilot
        self.recording = recording
        self.period = period
        self.jpeg_quality = jpeg_quality
        self.chunks = 0
        self.late = 0
        self.last: TensorDictBase | None = None
        """The latest step (observation, action and ``"next"``), for tests and tools."""
        self.step_seconds: list[float] = []
        """Seconds of world step plus frame encoding per chunk (the latest 1000)."""
        self._make_env = make_env
        self._publish = publish
        self._commands: queue.Queue[tuple[Command, Future]] = queue.Queue()
        self._crash_marked = False
        self._pages = 0
        self._pages_lock = threading.Lock()
        self._stop = threading.Event()
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, name="drive-session", daemon=True)

    # -- control from the server's thread --------------------------------------------------

    def start(self, timeout: float = 300.0) -> None:
        """Start the session's thread; returns once the world is open (raises what opening
        it raised)."""
        self._thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError(f"the world did not open within {timeout:.0f} s")
        if self._error is not None:
            raise self._error

    def page_opened(self) -> None:
        """A page connected: the world runs while at least one is."""
        with self._pages_lock:
            self._pages += 1

    def page_closed(self) -> None:
        """A page went away."""
        with self._pages_lock:
            self._pages = max(self._pages - 1, 0)

    def submit(self, command: Command) -> Future:
        """Run a page command between chunks; the future holds its result or its
        :class:`~oasis_torchrl.web.messages.Refused`."""
        done: Future = Future()
        self._commands.put((command, done))
        return done

    def close(self, timeout: float = 60.0) -> None:
        """Stop the loop, drop a running episode, close the world."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)

    # -- the session's thread --------------------------------------------------------------

    def _run(self) -> None:
        try:
            env = self._make_env()
            td = env.reset()
        except BaseException as error:
            self._error = error
            self._ready.set()
            return
        self._ready.set()
        try:
            with torch.no_grad(), set_exploration_type(ExplorationType.DETERMINISTIC):
                self._loop(env, td)
        except Exception:
            logger.exception("the drive session stopped")
            self._publish({"type": "error", "error": "session_failed", "message": "see the log"})
        finally:
            if self.recording is not None:
                self.recording.close()
            env.close()
            self._fail_pending()

    def _loop(self, env: EnvBase, td: TensorDictBase) -> None:
        slot = time.monotonic()
        while not self._stop.is_set():
            td = self._run_commands(env, td)
            if self._pages == 0:
                time.sleep(IDLE_S)
                slot = time.monotonic()
                continue
            started = time.monotonic()
            td = self._drive_chunk(env, td)
            self.step_seconds = [*self.step_seconds[-999:], time.monotonic() - started]
            slot += self.period
            delay = slot - time.monotonic()
            if delay < 0:
                self.late += 1
                slot = time.monotonic()
            else:
                self._stop.wait(delay)

    def _drive_chunk(self, env: EnvBase, td: TensorDictBase) -> TensorDictBase:
        seq = self.pilot.seq
        action, human = self.pilot.chunk(td)
        td.set("action", action)
        if self.pilot.policy is not None:
            td.set(INTERVENTION_KEY, torch.tensor([[human]]))
        step, following = env.step_and_maybe_reset(td)
        self.last = step
        self.chunks += 1
        saved = self._write(step)
        frames = step["next", "pixels"]
        cameras = list(frames.keys())
        for k in range(frames[cameras[0]].shape[1]):
            header = {"type": "frame", "chunk": self.chunks, "frame": k, "seq": seq}
            shown = {camera: frames[camera][0, k].numpy() for camera in cameras}
            self._publish(pack_frames(shown, cameras, header, self.jpeg_quality))
        self._publish(self.status(step, human=human, saved=saved))
        return following

    def _write(self, step: TensorDictBase) -> bool:
        """Record ``step`` with its crash flag if an episode runs; whether that saved it."""
        if self.recording is None or not self.recording.recording:
            return False
        marked, self._crash_marked = self._crash_marked, False
        collided = step.get(("next", "truth", "collided"), None)
        crashed = marked or (collided is not None and bool((collided > 0.5).any()))
        step.set(("next", CRASH_STEP_KEY), torch.tensor([[crashed]]))
        if marked:  # the person saw a crash: the episode ends here (the world's done is its own)
            step.set(("next", "done"), torch.tensor([[True]]))
        return self.recording.write(step)

    def status(
        self, step: TensorDictBase | None = None, *, human: bool = True, saved: bool = False
    ) -> dict[str, Any]:
        """What the page shows next to the cameras (None where not known)."""
        truth = (
            {}
            if step is None
            else {name: _known(step.get(("next", "truth", name), None)) for name in SHOWN_TRUTH}
        )
        recording = self.recording
        return {
            "type": "status",
            "chunk": self.chunks,
            "late": self.late,
            "period_ms": round(self.period * 1000),
            "human": human,
            "policy": self.pilot.policy is not None,
            "risk": None if step is None else _risk(step),
            "recording_enabled": recording is not None,
            "recording": recording is not None and recording.recording,
            "episode_steps": 0 if recording is None else recording.steps,
            "saved": 0 if recording is None else recording.saved,
            "episode_saved": saved,
            **truth,
        }

    def _run_commands(self, env: EnvBase, td: TensorDictBase) -> TensorDictBase:
        while True:
            try:
                command, done = self._commands.get_nowait()
            except queue.Empty:
                return td
            try:
                td, result = self._apply(command, env, td)
            except Refused as refused:
                done.set_exception(refused)
            except Exception as error:
                logger.exception("page command %s failed", command)
                done.set_exception(Refused("command_failed", f"{type(error).__name__}: {error}"))
            else:
                done.set_result(result)

    def _apply(
        self, command: Command, env: EnvBase, td: TensorDictBase
    ) -> tuple[TensorDictBase, Any]:
        if isinstance(command, Takeover):
            self.pilot.take_over(command.human)
            return td, command.human
        if isinstance(command, Reset):
            if self.recording is not None and self.recording.recording:
                raise Refused("recording", "stop or discard the running episode first")
            return env.reset(), None
        if self.recording is None:
            raise Refused("no_dataset", "recording is off (start the page with --root DIR)")
        if command.command == "start":
            self.recording.start()
            self._crash_marked = False
            return env.reset(), None  # each episode starts from a fresh scene, as `record`'s
        if command.command == "stop":
            return td, self.recording.stop()
        if command.command == "crash":
            if not self.recording.recording:
                raise Refused("not_recording", "no episode is running to mark a crash in")
            self._crash_marked = True
            return td, None
        self.recording.discard()
        return td, None

    def _fail_pending(self) -> None:
        while True:
            try:
                _, done = self._commands.get_nowait()
            except queue.Empty:
                return
            done.set_exception(Refused("session_closed", "the session has stopped"))
