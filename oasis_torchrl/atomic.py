"""Write a file or a folder whole or not at all.

The content goes to a hidden ``.<name>.partial`` beside the target and is moved into place only
when the writing finished, so a run stopped half way (a kill, a Ctrl-C, an error) never leaves
something a later run or a reader would take for finished: a checkpoint, a shipped policy, a
round's recorded episodes, a Ray worker's shard part. :func:`written_whole` does it for one
block; :func:`fresh_partial` and :func:`publish` for writing that spans calls.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


def partial_path(path: Path) -> Path:
    """Where :func:`written_whole` writes ``path`` until it is finished.

    Example:
        >>> partial_path(Path("runs/ppo/latest.pt"))
        PosixPath('runs/ppo/.latest.pt.partial')
    """
    return path.with_name(f".{path.name}.partial")


def is_partial(path: Path) -> bool:
    """Whether ``path`` is an unfinished write: a run stopped before it moved it into place.

    Example:
        >>> is_partial(partial_path(Path("shards/worker-001-part-0003")))
        True
        >>> is_partial(Path("shards/worker-001-part-0003"))
        False
    """
    return path.name.startswith(".") and path.name.endswith(".partial")


def _remove(path: Path) -> None:
    if path.is_dir():
        shutil.rmtree(path)
    else:
        path.unlink(missing_ok=True)


def fresh_partial(path: str | Path) -> Path:
    """The partial path to write ``path``'s content to, with what an earlier run killed half way
    left there removed; :func:`publish` moves it into place.

    Example:
        >>> import tempfile
        >>> target = Path(tempfile.mkdtemp()) / "worker-000-part-0000"
        >>> fresh_partial(target).mkdir()
        >>> publish(target)
        >>> target.is_dir(), partial_path(target).exists()
        (True, False)
    """
    path = Path(path)
    partial = partial_path(path)
    _remove(partial)
    path.parent.mkdir(parents=True, exist_ok=True)
    return partial


def publish(path: str | Path) -> None:
    """Move ``path``'s finished partial (see :func:`fresh_partial`) into place."""
    path = Path(path)
    os.replace(partial_path(path), path)


@contextmanager
def written_whole(path: str | Path) -> Iterator[Path]:
    """Yield the partial path to write ``path``'s content to; move it to ``path`` when the block
    ends without an error, remove it when it ends with one.

    A partial left by an earlier run killed half way is removed first. A file replaces the one
    at ``path``; a folder replaces only a missing or empty one (``os.replace``'s rule).

    Example:
        >>> import tempfile
        >>> target = Path(tempfile.mkdtemp()) / "episodes"
        >>> with written_whole(target) as partial:
        ...     partial.mkdir()
        ...     _ = (partial / "episode_0.txt").write_text("drove 12 m")
        >>> [file.name for file in target.iterdir()], partial.exists()
        (['episode_0.txt'], False)
    """
    partial = fresh_partial(path)
    try:
        yield partial
    except BaseException:
        _remove(partial)
        raise
    publish(path)
