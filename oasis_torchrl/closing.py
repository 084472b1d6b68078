"""One ``with`` block for everything that is closed: a ``with`` statement closes it at the end.

:class:`Closing` gives a class whose ``close()`` frees what it holds (a channel, a pool, a
recording, a Ray cluster, a video file) the context-manager pair: ``__enter__`` returns the
object itself and ``__exit__`` calls ``close()``, whether the block ended with an error or not.
A class whose ``with`` block also starts something overrides only ``__enter__``.
"""

from __future__ import annotations

from types import TracebackType
from typing import Self


class Closing:
    """Mixin: ``with thing:`` closes ``thing`` when the block ends; subclasses provide ``close``.

    Put it last among the base classes. It holds no state (empty ``__slots__``).

    Example:
        >>> class Channel(Closing):
        ...     def __init__(self) -> None:
        ...         self.open = True
        ...
        ...     def close(self) -> None:
        ...         self.open = False
        >>> with Channel() as channel:
        ...     channel.open
        True
        >>> channel.open
        False
    """

    __slots__ = ()

    def close(self) -> None:
        """Free what the object holds; the subclass provides it."""
        raise NotImplementedError(f"{type(self).__name__} must define close()")

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()
