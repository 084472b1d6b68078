"""Every use of another library's private internals, each checked against the installed version.

Nothing else in the project touches a private attribute of LeRobot, TorchRL or Ray. Each helper
first checks that the installed release is one whose internals it was written against, and
otherwise fails with an error naming the installed and the supported versions (rather than
misbehaving on a layout it does not know). What is used, and why no public API does the job:

- LeRobot's streaming video encoder (:func:`wait_for_encoder_room`,
  :func:`dropped_video_frames`): it was built for live cameras and drops a frame when a camera's
  queue stays full for 0.1 s. Frames replayed from a rollout must all land, so the writer waits
  for queue room before each frame and refuses to save an episode that lost one anyway.
- LeRobot's running image statistics (:func:`count_image_statistics`): each streaming encoder
  thread updates LeRobot's ``RunningQuantileStats`` with every frame it encodes, and at the
  main job's 96x64 that update (float casts, reductions and a 5000-bin histogram per channel)
  costs more than encoding the frame. For 8-bit frames :class:`CountedImageStats` derives the
  same statistics from one count of each channel's 256 levels; the encoder thread creates its
  tracker from LeRobot's module, so the writer puts that class there.
- LeRobot's episode table (:func:`embed_only_image_tables`): ``save_episode`` runs the
  ``datasets`` library's ``map`` over every row of the episode to embed image files into the
  table, even when no column holds images (camera frames go to videos), and that row-by-row map
  cost about a third of recording a demonstration. The writer module's ``embed_images`` is
  replaced by one that returns a table without image columns unchanged (what the map would
  give) and hands any other to LeRobot's.
- TorchRL's ``RayCollector`` (:func:`drop_ray_collectors`): it can add remote collectors but not
  remove one, so after a worker died the survivors are kept by rewriting its actor list and
  those of its weight senders.
- TorchRL's Ray weight sync (:func:`ray_weight_sync_scheme`): the learner publishes the address
  its hostname resolves to, and every rank's gloo device binds to it; on the many hosts whose
  hostname maps to a loopback address (Debian's and Ubuntu's 127.0.1.1) collectors on other
  nodes then cannot reach the learner. TorchRL has no setting for it, so the scheme runs its
  set-up with this node's cluster address as Ray knows it (``ray.util.get_node_ip_address()``)
  in place of the hostname and gloo on that address's interface (``GLOO_SOCKET_IFNAME``).
- LeRobot's episode announcements (:func:`on_lerobot_episode_start`): a robot has no hook for
  the start of an episode, but ``lerobot-record`` and ``lerobot-rollout``'s episodic strategy
  announce each one with ``log_say("Recording episode N")`` (a root-logger INFO record); the oasis
  robot listens for it to re-prompt its world for that episode.

Example:
    >>> SUPPORTED["lerobot"]
    ((0, 6), (0, 7))
    >>> require("lerobot")
"""

from __future__ import annotations

import contextlib
import functools
import importlib.metadata
import logging
import os
import re
import socket
import time
import types
from collections.abc import Callable, Iterator, Sequence
from typing import Any

SUPPORTED: dict[str, tuple[tuple[int, int], tuple[int, int]]] = {
    "lerobot": ((0, 6), (0, 7)),
    "torchrl": ((0, 14), (0, 15)),
}
"""Distribution -> ``(lowest, first unsupported)`` ``(major, minor)`` whose internals are used."""


class UnsupportedVersionError(RuntimeError):
    """An installed library's release is not one this module's private accesses were written for."""


def _release(version: str) -> tuple[int, int]:
    """``(major, minor)`` of a version string.

    Example:
        >>> _release("0.14.1"), _release("0.6.1.dev0")
        ((0, 14), (0, 6))
    """
    numbers = re.findall(r"\d+", version)[:2]
    return int(numbers[0]), int(numbers[1]) if len(numbers) > 1 else 0


def _range_text(package: str) -> str:
    (low_major, low_minor), (high_major, high_minor) = SUPPORTED[package]
    return f">={low_major}.{low_minor},<{high_major}.{high_minor}"


@functools.cache
def _installed(package: str) -> str:
    # Looked up once per process: a lookup scans the installed distributions, and
    # the dataset writer checks before every frame it streams.
    return importlib.metadata.version(package)


def require(package: str) -> None:
    """Check that the installed ``package`` is a release :data:`SUPPORTED` lists.

    Raises:
        UnsupportedVersionError: naming the installed and the supported versions.

    Example:
        >>> require("torchrl")
    """
    installed = _installed(package)
    low, high = SUPPORTED[package]
    if not low <= _release(installed) < high:
        raise UnsupportedVersionError(
            f"oasis_torchrl.compat supports {package}{_range_text(package)}, "
            f"found {package} {installed}; install a supported release "
            f"(pip install '{package}{_range_text(package)}')"
        )


# -- LeRobot: the streaming video encoder ------------------------------------------------------


def _streaming_encoder(dataset: Any) -> Any | None:
    require("lerobot")
    writer = dataset.writer
    return None if writer is None else writer._streaming_encoder


def wait_for_encoder_room(dataset: Any) -> None:
    """Block until every camera's streaming-encoder queue of ``dataset`` can take a frame.

    Returns at once when the dataset encodes without streaming, or a camera's encoder thread
    has stopped (LeRobot then raises its error at the next frame).
    """
    encoder = _streaming_encoder(dataset)
    if encoder is None:
        return
    for key, frames in encoder._frame_queues.items():
        thread = encoder._threads[key]
        while frames.full() and thread.is_alive():
            time.sleep(0.001)


def dropped_video_frames(dataset: Any) -> dict[str, int]:
    """Frames the streaming encoder dropped in the current episode, per camera (none: empty)."""
    encoder = _streaming_encoder(dataset)
    counts = {} if encoder is None else encoder._dropped_frames
    return {key: count for key, count in counts.items() if count}


# -- LeRobot: the streaming encoder's running image statistics ----------------------------------


LEVELS = 256
"""The values an 8-bit channel takes."""


@functools.cache
def _counted_image_stats() -> type:
    """:class:`CountedImageStats`, built on first use (it subclasses a LeRobot class)."""
    import numpy as np
    from lerobot.datasets.compute_stats import RunningQuantileStats

    class CountedImageStats(RunningQuantileStats):
        """LeRobot's running statistics, updated from per-channel level counts for uint8 rows.

        For ``uint8`` batches ``[..., channels]`` every statistic LeRobot keeps (min, max,
        mean, mean of squares, the quantile histograms) follows from how often each channel
        takes each of its 256 levels, one ``bincount`` per batch instead of float reductions
        and a sorted histogram per channel. The histograms and extremes are LeRobot's to the
        bit; the means are exact sums (LeRobot's float32 sums of squares put its standard
        deviation of camera frames about 4e-5 off). Other dtypes (depth, state vectors) take
        LeRobot's own update.

        Example:
            >>> import numpy as np
            >>> from oasis_torchrl.compat import CountedImageStats
            >>> LeRobotStats = CountedImageStats.__bases__[0]  # even once installed in LeRobot
            >>> frames = np.random.default_rng(0).integers(0, 256, (2, 6144, 3), dtype=np.uint8)
            >>> counted, lerobot = CountedImageStats(), LeRobotStats()
            >>> for frame in frames:
            ...     counted.update(frame)
            ...     lerobot.update(frame)
            >>> ours, theirs = counted.get_statistics(), lerobot.get_statistics()
            >>> all(np.allclose(ours[key], theirs[key], rtol=1e-4) for key in theirs)
            True
        """

        def update(self, batch: np.ndarray) -> None:
            if batch.dtype != np.uint8 or batch.size == 0:
                super().update(batch)  # LeRobot's own update, and its error on an empty batch
                return
            rows = batch.reshape(-1, batch.shape[-1])
            channels = rows.shape[1]
            offsets = np.arange(channels, dtype=np.intp) * LEVELS
            counts = np.bincount((rows + offsets).ravel(), minlength=channels * LEVELS)
            counts = counts.reshape(channels, LEVELS)
            present = counts > 0
            low = present.argmax(axis=1).astype(np.float32)
            high = (LEVELS - 1 - present[:, ::-1].argmax(axis=1)).astype(np.float32)
            levels = np.arange(LEVELS, dtype=np.float64)
            mean = (counts @ levels / len(rows)).astype(np.float32)
            mean_of_squares = (counts @ levels**2 / len(rows)).astype(np.float32)
            if self._count == 0:
                self._mean, self._mean_of_squares = np.zeros_like(mean), np.zeros_like(mean)
                self._min, self._max = low, high
                self._histograms = [np.zeros(self._num_quantile_bins) for _ in range(channels)]
                self._bin_edges = [
                    np.linspace(low[i] - 1e-10, high[i] + 1e-10, self._num_quantile_bins + 1)
                    for i in range(channels)
                ]
            elif channels != self._mean.size:
                raise ValueError(
                    f"image rows of {channels} channels after rows of {self._mean.size}"
                )
            elif np.any(high > self._max) or np.any(low < self._min):
                self._max, self._min = np.maximum(self._max, high), np.minimum(self._min, low)
                self._adjust_histograms()
            self._count += len(rows)
            weight = len(rows) / self._count
            self._mean += (mean - self._mean) * weight
            self._mean_of_squares += (mean_of_squares - self._mean_of_squares) * weight
            self._add_level_counts(counts)

        def _add_level_counts(self, counts: np.ndarray) -> None:
            """Each level's count into the bin LeRobot's histogram puts that level in (bins
            closed on the left, the last one on both sides)."""
            for histogram, edges, level_counts in zip(
                self._histograms, self._bin_edges, counts, strict=True
            ):
                values = np.arange(LEVELS, dtype=edges.dtype)
                inside = (values >= edges[0]) & (values <= edges[-1])
                bins = np.searchsorted(edges, values[inside], side="right") - 1
                bins = np.minimum(bins, len(histogram) - 1)
                histogram += np.bincount(bins, level_counts[inside], minlength=len(histogram))

    return CountedImageStats


def count_image_statistics() -> None:
    """Make LeRobot's streaming encoder threads keep their image statistics with
    :class:`CountedImageStats` (LeRobot's running statistics, updated from level counts).

    Idempotent; the class replaces ``RunningQuantileStats`` in LeRobot's ``compute_stats``
    module, which the encoder threads read when they start, and behaves as LeRobot's for every
    input but 8-bit rows (``benchmarks/export_speed.py`` times the recorder with both).

    Example:
        >>> from lerobot.datasets import compute_stats
        >>> count_image_statistics()
        >>> compute_stats.RunningQuantileStats.__name__
        'CountedImageStats'
    """
    require("lerobot")
    from lerobot.datasets import compute_stats

    compute_stats.RunningQuantileStats = _counted_image_stats()


def _embeds_images(features: Any) -> bool:
    """Whether a ``datasets`` features dict has a column whose storage LeRobot's
    ``embed_images`` rewrites (images, audio, also nested)."""
    from datasets.features.features import require_storage_embed

    return any(require_storage_embed(feature) for feature in features.values())


def embed_only_image_tables() -> None:
    """Make LeRobot's ``save_episode`` skip its row-by-row image embedding for an episode
    table without image columns (the table is already what the embedding would give).

    Idempotent; replaces ``embed_images`` in LeRobot's ``dataset_writer`` module.

    Example:
        >>> from lerobot.datasets import dataset_writer
        >>> embed_only_image_tables()
        >>> dataset_writer.embed_images.__name__
        'embed_images_if_any'
    """
    require("lerobot")
    from lerobot.datasets import dataset_writer
    from lerobot.datasets.io_utils import embed_images

    def embed_images_if_any(dataset: Any) -> Any:
        return embed_images(dataset) if _embeds_images(dataset.features) else dataset

    dataset_writer.embed_images = embed_images_if_any


def __getattr__(name: str) -> Any:
    # The subclasses are built lazily (importing this module must not import LeRobot or
    # TorchRL); the names resolve here so that pickles of their instances find them.
    if name == "CountedImageStats":
        return _counted_image_stats()
    if name == "NodeAddressRayWeightSyncScheme":
        return _node_address_scheme()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# -- TorchRL: removing remote collectors from a RayCollector ------------------------------------


def drop_ray_collectors(collector: Any, keep: Sequence[int]) -> None:
    """Keep only the remote collectors at indices ``keep`` of a TorchRL ``RayCollector``.

    The collector and its weight-sync schemes then address the kept actors only (TorchRL has no
    public way to shrink a ``RayCollector``).
    """
    require("torchrl")
    actors = [collector.remote_collectors[index] for index in keep]
    collector._remote_collectors = actors
    collector.num_collectors = len(actors)
    collector._batches_since_weight_update = [0] * len(actors)
    for scheme in (collector._weight_sync_schemes or {}).values():
        scheme._remote_collectors = list(actors)
        scheme._num_workers = len(actors)


# -- TorchRL: the address Ray weight sync listens and connects on --------------------------------

GLOO_INTERFACE_VARIABLE = "GLOO_SOCKET_IFNAME"
"""The variable naming the network interface of gloo's device (read when a group is made)."""


def _interface_of(address: str) -> str | None:
    """Name of this machine's network interface holding IPv4 ``address`` (None: none does)."""
    import psutil  # a TorchRL dependency

    for name, entries in psutil.net_if_addrs().items():
        if any(entry.family == socket.AF_INET and entry.address == address for entry in entries):
            return name
    return None


@contextlib.contextmanager
def _on_ray_node_address() -> Iterator[str]:
    """Within it, TorchRL's Ray weight sync takes this node's cluster address (as Ray knows it)
    for its hostname's address, and gloo's device binds to that address's interface (unless
    ``GLOO_SOCKET_IFNAME`` is already set). Yields the address."""
    require("torchrl")
    import ray
    from torchrl.weight_update import _ray as ray_weight_sync

    address = ray.util.get_node_ip_address()
    interface = _interface_of(address)
    set_interface = interface is not None and GLOO_INTERFACE_VARIABLE not in os.environ
    hostname_module = ray_weight_sync.socket
    ray_weight_sync.socket = types.SimpleNamespace(
        gethostname=lambda: address,  # an address resolves to itself
        gethostbyname=socket.gethostbyname,
        gaierror=socket.gaierror,
    )
    if set_interface:
        os.environ[GLOO_INTERFACE_VARIABLE] = interface
    try:
        yield address
    finally:
        ray_weight_sync.socket = hostname_module
        if set_interface:
            del os.environ[GLOO_INTERFACE_VARIABLE]


@functools.cache
def _node_address_scheme() -> type:
    require("torchrl")
    from torchrl.weight_update import RayWeightSyncScheme

    class NodeAddressRayWeightSyncScheme(RayWeightSyncScheme):
        """TorchRL's Ray weight sync, reached at each node's cluster address."""

        def _setup_distributed_connection_sender(self, *args: Any, **kwargs: Any) -> None:
            with _on_ray_node_address():
                super()._setup_distributed_connection_sender(*args, **kwargs)

        def _setup_connection_and_weights_on_receiver_impl(self, *args: Any, **kwargs: Any) -> None:
            with _on_ray_node_address():
                super()._setup_connection_and_weights_on_receiver_impl(*args, **kwargs)

    NodeAddressRayWeightSyncScheme.__module__ = __name__
    NodeAddressRayWeightSyncScheme.__qualname__ = NodeAddressRayWeightSyncScheme.__name__
    return NodeAddressRayWeightSyncScheme


def ray_weight_sync_scheme() -> Any:
    """TorchRL's ``RayWeightSyncScheme`` whose learner and collectors meet at their nodes'
    cluster addresses, whatever each node's hostname resolves to.

    Example:
        >>> import pickle
        >>> scheme = ray_weight_sync_scheme()
        >>> type(pickle.loads(pickle.dumps(scheme))).__name__
        'NodeAddressRayWeightSyncScheme'
    """
    return _node_address_scheme()()


# -- LeRobot: the episode announcements of its recording loops -----------------------------------

_EPISODE_ANNOUNCEMENT = re.compile(r"Recording episode (\d+)")


class _EpisodeStarts(logging.Handler):
    """Calls back with ``N`` for every ``"Recording episode N"`` record it sees."""

    def __init__(self, callback: Callable[[int], None]) -> None:
        super().__init__(logging.INFO)
        self.callback = callback

    def emit(self, record: logging.LogRecord) -> None:
        match = _EPISODE_ANNOUNCEMENT.fullmatch(str(record.msg))
        if match is not None and record.name == "root":
            self.callback(int(match[1]))


def on_lerobot_episode_start(callback: Callable[[int], None]) -> Callable[[], None]:
    """Call ``callback(index)`` whenever a LeRobot recording loop starts dataset episode
    ``index`` (``lerobot-record``, ``lerobot-rollout --strategy.type=episodic``; a re-recorded
    episode is announced again with the same index). Returns a function that stops listening.

    LeRobot's tools log at INFO from the root logger (``init_logging``), where the announcement
    arrives; a program running LeRobot's loops with the root logger above INFO is not told.

    Example:
        >>> from lerobot.utils.utils import log_say
        >>> root, starts = logging.getLogger(), []
        >>> level = root.level
        >>> root.setLevel(logging.INFO)  # as LeRobot's tools log
        >>> stop = on_lerobot_episode_start(starts.append)
        >>> log_say("Recording episode 3", play_sounds=False)
        >>> stop()
        >>> log_say("Recording episode 4", play_sounds=False)
        >>> root.setLevel(level)
        >>> starts
        [3]
    """
    require("lerobot")
    handler = _EpisodeStarts(callback)
    root = logging.getLogger()
    root.addHandler(handler)
    return lambda: root.removeHandler(handler)
