"""API-key checks of the embedded A2V server. Keys are compared in constant time, never logged."""

from __future__ import annotations

import hashlib
import hmac
import logging
from collections.abc import Sequence

from oasis_torchrl.proto import common_pb2
from oasis_torchrl.sim.errors import RequestError

logger = logging.getLogger(__name__)


def key_digest(key: str) -> bytes:
    """SHA-256 of an API key: what the server stores and binds sessions to.

    Example:
        >>> len(key_digest("secret"))
        32
    """
    return hashlib.sha256(key.encode("utf-8")).digest()


def key_fingerprint(digest: bytes) -> str:
    """Short, non-reversible tag of a key digest, the only form of a key that is ever logged.

    Example:
        >>> key_fingerprint(key_digest("secret"))
        '2bb80d53'
    """
    return digest.hex()[:8]


class ApiKeyAuthority:
    """Decides whether an API key may use the server.

    Args:
        keys: The accepted keys.
        allow_any_key: Accept any non-empty key (for local use; logs a warning).

    Example:
        >>> authority = ApiKeyAuthority(["secret"])
        >>> authority.authenticate("secret") == key_digest("secret")
        True
        >>> authority.authenticate("guess")
        Traceback (most recent call last):
        ...
        oasis_torchrl.sim.errors.RequestError: API key rejected
    """

    def __init__(self, keys: Sequence[str], *, allow_any_key: bool = False) -> None:
        if not keys and not allow_any_key:
            raise ValueError(
                "no API key configured: pass api_keys, set OASIS_SERVER_API_KEYS, or set "
                "allow_any_key=True to accept any key"
            )
        if allow_any_key:
            logger.warning("the server accepts ANY non-empty API key (allow_any_key=True)")
        self._digests = tuple(key_digest(key) for key in keys)
        self._allow_any_key = allow_any_key

    def authenticate(self, key: str | None) -> bytes:
        """The digest identifying ``key``; raises ``INVALID_API_KEY`` if missing or unknown."""
        if not key:
            raise RequestError(
                common_pb2.ERROR_CODE_INVALID_API_KEY,
                "missing API key: send it as x-api-key metadata (and in InitializeRequest.api_key)",
            )
        digest = key_digest(key)
        # Compare against every key so the time taken does not reveal which one matched.
        matches = [hmac.compare_digest(digest, known) for known in self._digests]
        if not (any(matches) or self._allow_any_key):
            raise RequestError(common_pb2.ERROR_CODE_INVALID_API_KEY, "API key rejected")
        return digest
