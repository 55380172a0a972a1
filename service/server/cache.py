"""LRU cache of recent outfits by outfit id (the canonical request and the model version).

Bounded both by entry count and by bytes, so a burst of distinct outfits cannot grow memory past
the budget. Thread-safe. An outfit grows when a compact encoding of it is written: ``put`` it again
and its size is counted anew. An evicted outfit is gone from this replica: its GLB URL
(``service.server.outfit_url``) makes it again; the id URL ``/v1/outfits/{id}.glb`` answers 404.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from service.pipeline.tryon import OutfitResult


class OutfitCache:
    def __init__(self, max_entries: int, max_bytes: int):
        self.max_entries = max_entries
        self.max_bytes = max_bytes
        self._items: OrderedDict[str, tuple[OutfitResult, int]] = OrderedDict()  # item, bytes counted
        self._bytes = 0
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._items)

    @property
    def nbytes(self) -> int:
        return self._bytes

    def get(self, key: str) -> OutfitResult | None:
        with self._lock:
            entry = self._items.get(key)
            if entry is None:
                return None
            self._items.move_to_end(key)
            return entry[0]

    def put(self, key: str, item: OutfitResult) -> None:
        size = item.nbytes
        with self._lock:
            old = self._items.pop(key, None)
            if old is not None:
                self._bytes -= old[1]
            if self.max_entries == 0 or size > self.max_bytes:
                return
            self._items[key] = (item, size)
            self._bytes += size
            while len(self._items) > self.max_entries or self._bytes > self.max_bytes:
                _, (_, evicted) = self._items.popitem(last=False)
                self._bytes -= evicted
