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


def test_a_cache_holding_only_the_folders_numba_made_at_import_gets_the_seed(tmp_path: Path):
    # numba makes a kernel module's cache folder when the module is imported (before any kernel
    # runs, before the command line's seeding): folders without files are still an empty cache.
    seed, cache = _seed(tmp_path), tmp_path / "numba-cache"
    (cache / "opt" / "venv" / "service" / "geometry").mkdir(parents=True)
    (cache / "pipeline_0123").mkdir()
    env = {"ULNEF_JIT_CACHE_SEED": str(seed), "NUMBA_CACHE_DIR": str(cache)}
    assert seed_jit_cache(env)
    assert (cache / "opt" / "venv" / "service" / "geometry" / "closest_kernel.select-72.py311.nbi").is_file()


def test_the_cli_seeds_the_cache_before_any_kernel_runs_though_numba_made_its_folders(tmp_path: Path):
    """The real order: ``ulnef`` imports the kernel modules (numba makes their cache folders), then
    seeds; a kernel then finds the seed's index."""
    import os
    import subprocess
    import sys

    seed, cache = tmp_path / "seed", tmp_path / "cache"
    compile_env = dict(os.environ, NUMBA_CACHE_DIR=str(seed))
    call = "from service.geometry.mesh import face_normals; face_normals(np.eye(3), np.array([[0, 1, 2]]))"
    subprocess.run([sys.executable, "-c", "import numpy as np; " + call], env=compile_env, check=True)
    assert any(p.suffix == ".nbi" for p in seed.rglob("*"))
    run_env = dict(
        os.environ, NUMBA_CACHE_DIR=str(cache), ULNEF_JIT_CACHE_SEED=str(seed), NUMBA_DEBUG_CACHE="1"
    )
    probe = "import numpy as np, service.cli as cli; cli.seed_jit_cache(); " + call
    out = subprocess.run(
        [sys.executable, "-c", probe], env=run_env, check=True, capture_output=True, text=True
    ).stdout
    assert "data loaded" in out and "data saved" not in out  # the seed's compiled kernel, not a new one
