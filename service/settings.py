"""Service configuration from ``ULNEF_*`` environment variables (pydantic-settings)."""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field
from pydantic_settings import BaseSettings, SettingsConfigDict

LogLevel = Literal["critical", "error", "warning", "info", "debug"]


class Settings(BaseSettings):
    """One place for everything the service reads from its environment."""

    model_config = SettingsConfigDict(env_prefix="ULNEF_")

    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=1, le=65535)
    models_dir: Path | None = Field(
        default=None,
        description="Directory holding the committed models; None means the repository's `models/`.",
    )
    cors_origins: list[str] = Field(
        default_factory=list,
        description="Allowed CORS origins, as JSON: ULNEF_CORS_ORIGINS='[\"https://shop\"]'.",
    )
    log_level: LogLevel = "info"

    def garments_dir(self) -> Path | None:
        """Catalog directory, or None to let ``service.catalog`` use ``service.paths.models_dir()``."""
        return self.models_dir / "garments" if self.models_dir is not None else None
