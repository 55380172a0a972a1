"""Structured logs: one JSON object per line: time, level, logger, message, and the entries of
``extra={"fields": {...}}``."""

from __future__ import annotations

import json
import logging
import sys
import time

from service.server.settings import LogFormat, LogLevel


class JsonFormatter(logging.Formatter):
    def format(self, record: logging.LogRecord) -> str:
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(record.created))
        entry = {
            "time": f"{stamp}.{int(record.msecs):03d}Z",
            "level": record.levelname.lower(),
            "logger": record.name,
            "message": record.getMessage(),
        }
        entry.update(getattr(record, "fields", {}))
        if record.exc_info:
            entry["exception"] = self.formatException(record.exc_info)
        return json.dumps(entry, default=str)


def configure(level: LogLevel, fmt: LogFormat) -> None:
    """Root logger to stderr in ``fmt``; uvicorn's loggers propagate to it (run it with log_config=None)."""
    handler = logging.StreamHandler(sys.stderr)
    if fmt == "json":
        handler.setFormatter(JsonFormatter())
    else:
        handler.setFormatter(logging.Formatter("%(levelname)s:     %(name)s: %(message)s"))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level.upper())
    # Our access log has the route, status and timing; uvicorn's would say the same twice.
    logging.getLogger("uvicorn.access").disabled = True
