"""API keys and per-key rate limits of the outfit endpoints (off unless ``ULNEF_API_KEYS_FILE`` is set).

The keys file holds the sha256 hex digest of each key, one a line (``#`` comments and blank lines
allowed), so the keys themselves are never stored by the service: ``printf %s "$KEY" | sha256sum``.
A client sends ``Authorization: Bearer <key>``; a key is known by its id, the first 12 hex chars of
its digest (logged and put in signed GLB URLs; it reveals nothing usable about the key).

The rate limit is a token bucket per key id and per replica (``rate_per_minute`` refilling, ``burst``
deep): N replicas allow N times the rate, which the Kubernetes example sizes for.
"""

from __future__ import annotations

import hashlib
import math
import re
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

DIGEST = re.compile(r"^[0-9a-f]{64}$")
KEY_ID_CHARS = 12


class KeysFileError(ValueError):
    """The keys file cannot be read or has a line that is not a sha256 hex digest."""


def key_id(digest: str) -> str:
    return digest[:KEY_ID_CHARS]


def read_digests(path: Path) -> frozenset[str]:
    """Digests in ``path``; raises ``KeysFileError`` naming the first bad line."""
    try:
        lines = Path(path).read_text().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise KeysFileError(f"API keys file {path}: {e}") from None
    digests = set()
    for number, line in enumerate(lines, 1):
        text = line.split("#", 1)[0].strip().lower()
        if not text:
            continue
        if not DIGEST.match(text):
            raise KeysFileError(f"API keys file {path}, line {number}: not a sha256 hex digest (64 hex)")
        digests.add(text)
    if not digests:
        raise KeysFileError(f"API keys file {path}: no key digests")
    return frozenset(digests)


@dataclass(frozen=True)
class ApiKeys:
    """The accepted keys, by digest."""

    digests: frozenset[str]

    def identify(self, authorization: str | None) -> str | None:
        """Key id of a valid ``Bearer <key>`` header, else None."""
        if not authorization:
            return None
        scheme, _, key = authorization.partition(" ")
        if scheme.lower() != "bearer" or not key.strip():
            return None
        digest = hashlib.sha256(key.strip().encode()).hexdigest()
        return key_id(digest) if digest in self.digests else None

    def knows(self, kid: str) -> bool:
        return any(key_id(d) == kid for d in self.digests)


@dataclass
class RateLimiter:
    """Token buckets by key id: ``take`` spends one token, or says how many seconds until one is back."""

    rate_per_minute: float
    burst: int
    clock: object = time.monotonic
    _buckets: dict[str, tuple[float, float]] = field(default_factory=dict)  # id -> (tokens, at)
    _lock: threading.Lock = field(default_factory=threading.Lock)

    def take(self, kid: str) -> float | None:
        """None when allowed; otherwise the whole seconds to wait (for ``Retry-After``)."""
        rate = self.rate_per_minute / 60.0
        with self._lock:
            now = self.clock()
            tokens, at = self._buckets.get(kid, (float(self.burst), now))
            tokens = min(float(self.burst), tokens + (now - at) * rate)
            if tokens >= 1.0:
                self._buckets[kid] = (tokens - 1.0, now)
                return None
            self._buckets[kid] = (tokens, now)
            return float(max(1, math.ceil((1.0 - tokens) / rate)))
