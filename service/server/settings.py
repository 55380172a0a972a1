"""Service configuration from ``ULNEF_*`` environment variables (pydantic-settings)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, SecretStr
from pydantic_settings import BaseSettings, SettingsConfigDict

LogLevel = Literal["critical", "error", "warning", "info", "debug"]
LogFormat = Literal["json", "text"]


class Settings(BaseSettings):
    """One place for everything the service reads from its environment.

    Every field is ``ULNEF_<NAME>`` in the environment, e.g. ``ULNEF_REQUEST_TIMEOUT_S=10``.
    """

    model_config = SettingsConfigDict(env_prefix="ULNEF_")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)
    models_dir: Path | None = Field(
        default=None,
        description="Directory holding the committed models; None means the repository's `models/`.",
    )
    cors_origins: list[str] = Field(
        default_factory=list,
        description="Allowed CORS origins, as JSON: ULNEF_CORS_ORIGINS='[\"https://shop\"]'. Empty: no CORS.",
    )
    log_level: LogLevel = "info"
    log_format: LogFormat = Field(default="json", description="`json`: one JSON object per log line.")
    configure_logging: bool = Field(default=True, description="Set up the root logger when the app starts.")

    # Integrity and readiness.
    verify_models: bool = Field(
        default=True, description="Check every model file against models/manifest.json before loading."
    )
    self_test_garments: list[str] = Field(
        default_factory=lambda: ["shorts"], description="Outfit made once at start-up before /readyz is true."
    )
    self_test_untangle: bool = Field(default=True, description="Whether the self-test outfit is untangled.")
    onnx_threads: int = Field(default=2, ge=1, le=64, description="onnxruntime threads per session.")

    # Limits: what keeps a burst from exhausting memory or hanging clients.
    workers: int = Field(default=1, ge=1, le=64, description="Outfits computed at the same time.")
    queue_size: int = Field(
        default=8, ge=0, le=10_000, description="Outfits waiting for a worker; beyond it: 503 + Retry-After."
    )
    request_timeout_s: float = Field(
        default=30.0, gt=0, le=3600, description="Time budget of one outfit request, queueing included."
    )
    max_body_bytes: int = Field(default=16_384, ge=256, description="Largest accepted request body.")
    max_connections: int | None = Field(
        default=1000, ge=1,
        description="Last-resort bound on open connections: beyond it uvicorn answers every request a "
        "plain 503 (no Retry-After), so keep it far above what the queue turns away cleanly.",
    )  # fmt: skip
    cache_entries: int = Field(default=64, ge=0, description="Recent outfits kept (LRU); 0 disables.")
    cache_bytes: int = Field(default=256 * 2**20, ge=0, description="Byte budget of the outfit cache.")

    garments_dir: Path | None = Field(
        default=None,
        description="Imported garments (`ulnef garments import`), served beside the bundled ones.",
    )

    admin_token: SecretStr | None = Field(
        default=None,
        description="Bearer token of POST /v1/admin/reload (pick up new imports); unset: no admin endpoint.",
    )

    # Access control of the outfit endpoints (service.server.access); off by default.
    api_keys_file: Path | None = Field(
        default=None,
        description="File of sha256 hex digests of the accepted API keys, one a line; unset: no keys needed.",
    )
    url_secret_file: Path | None = Field(
        default=None,
        description="File holding the secret that signs GLB URLs (same on every replica), so a viewer "
        "without an Authorization header can GET them; unset: GLB GETs need the key too.",
    )
    rate_limit_per_minute: float = Field(
        default=120.0, gt=0, description="Outfit requests a key may send a minute."
    )
    rate_limit_burst: int = Field(default=30, ge=1, description="Requests a key may send at once.")
    metrics_token: SecretStr | None = Field(
        default=None, description="Bearer token of GET /metrics; unset: /metrics is open."
    )

    def catalog_dir(self) -> Path | None:
        """Bundled catalog directory, or None to let ``service.pipeline.catalog`` use
        ``service.process.paths.models_dir()``."""
        return self.models_dir / "garments" if self.models_dir is not None else None

    def resolved_models_dir(self) -> Path:
        from service.process.paths import models_dir

        return self.models_dir if self.models_dir is not None else models_dir()
