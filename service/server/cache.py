"""LRU cache of recent outfits by outfit id (the canonical request and the model version).

Bounded both by entry count and by bytes, so a burst of distinct outfits cannot grow memory past
the budget. Thread-safe. An evicted outfit is gone: ``GET /v1/outfits/{id}.glb`` then answers 404
and the client POSTs the request again (the id is a hash; it cannot be turned back into a request).
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from service.pipeline.tryon import OutfitResult


class OutfitCache:
    def __init__(self, max_entries: int, max_bytes: int):
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self._items: OrderedDict[str, OutfitResult] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._items)

    @property
    def nbytes(self) -> int:
        return self._bytes

    def get(self, key: str) -> OutfitResult | None:
        with self._lock:
            item = self._items.get(key)
            if item is not None:
                self._items.move_to_end(key)
            return item

    def put(self, key: str, item: OutfitResult) -> None:
        if self.max_entries == 0 or item.nbytes > self.max_bytes:
            return
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._bytes -= old.nbytes
            self._items[key] = item
            self._bytes += item.nbytes
            while len(self._items) > self.max_entries or self._bytes > self.max_bytes:
                _, evicted = self._items.popitem(last=False)
                self._bytes -= evicted.nbytes
