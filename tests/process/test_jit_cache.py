"""``seed_jit_cache``: the image's compiled-kernel seed is copied into an empty writable cache, and
never over a cache that already holds something or where a setting is missing."""

from __future__ import annotations

from pathlib import Path

from service.process.jit_cache import seed_jit_cache


def _seed(tmp_path: Path) -> Path:
    seed = tmp_path / "seed" / "opt" / "venv" / "service" / "geometry"
    seed.mkdir(parents=True)
    (seed / "closest_kernel.select-72.py311.nbi").write_bytes(b"index")
    return tmp_path / "seed"


def test_an_empty_cache_gets_the_seed(tmp_path: Path):
    seed, cache = _seed(tmp_path), tmp_path / "tmp" / "numba-cache"
    env = {"ULNEF_JIT_CACHE_SEED": str(seed), "NUMBA_CACHE_DIR": str(cache)}
    assert seed_jit_cache(env)
    copied = cache / "opt" / "venv" / "service" / "geometry" / "closest_kernel.select-72.py311.nbi"
    assert copied.read_bytes() == b"index"
    cache.joinpath("extra").write_text("compiled since")
    assert not seed_jit_cache(env)  # not empty any more: left as it is


def test_nothing_happens_without_both_settings_or_a_seed(tmp_path: Path):
    seed, cache = _seed(tmp_path), tmp_path / "cache"
    assert not seed_jit_cache({"NUMBA_CACHE_DIR": str(cache)})
    assert not seed_jit_cache({"ULNEF_JIT_CACHE_SEED": str(seed)})
    assert not seed_jit_cache({"ULNEF_JIT_CACHE_SEED": str(tmp_path / "none"), "NUMBA_CACHE_DIR": str(cache)})
    assert not cache.exists()
