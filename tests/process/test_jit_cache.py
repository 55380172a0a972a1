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


def test_every_kernel_is_compiled_before_the_first_test():
    """The session's ``_compiled_kernels`` (tests/conftest.py) left nothing for a test to compile."""
    from service.pipeline.kernels import kernels, uncached_kernels

    assert {name.rsplit(".", 1)[0] for name in kernels()} >= {  # the kernel modules are found
        "service.geometry.bvh_kernel", "service.geometry.mesh", "service.pipeline.lbfgs_kernel",
    }
    assert uncached_kernels() == []


def test_an_empty_cache_has_every_kernel_uncached(tmp_path: Path):
    import os
    import subprocess
    import sys

    probe = (
        "from service.pipeline.kernels import kernels, uncached_kernels; "
        "print(uncached_kernels() == sorted(kernels()))"
    )
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path))
    out = subprocess.run([sys.executable, "-c", probe], env=env, check=True, capture_output=True, text=True)
    assert out.stdout.strip() == "True"


def test_warm_kernels_compiles_in_a_child_process_only_what_the_cache_lacks(monkeypatch):
    import subprocess
    import sys

    import service.pipeline.kernels as jit_cache

    runs = []
    monkeypatch.setattr(subprocess, "run", lambda cmd, **kwargs: runs.append(cmd))
    monkeypatch.setattr(jit_cache, "uncached_kernels", lambda: [])
    assert jit_cache.warm_kernels() == [] and runs == []
    monkeypatch.setattr(jit_cache, "uncached_kernels", lambda: ["service.geometry.mesh._face_normals"])
    assert jit_cache.warm_kernels() == ["service.geometry.mesh._face_normals"]
    assert runs == [[sys.executable, "-m", "service.pipeline.kernels"]]


def test_the_warm_outfit_calls_every_kernel():
    """``compile_kernels`` (the outfit the images and the test session compile with) reaches every
    kernel: a new kernel that it misses fails here, not as a compile inside some test's time."""
    from numba.core.registry import CPUDispatcher

    from service.pipeline.kernels import compile_kernels, kernels

    found = kernels()
    inner, todo = set(), list(found.values())  # what compiled code calls (through inlined helpers too)
    while todo:
        func = todo.pop().py_func
        for name in func.__code__.co_names:
            callee = func.__globals__.get(name)
            if isinstance(callee, CPUDispatcher) and id(callee) not in inner:
                inner.add(id(callee))
                todo.append(callee)
    called_from_python = {name: kernel for name, kernel in found.items() if id(kernel) not in inner}
    assert "service.geometry.bvh_kernel.build" in called_from_python
    assert "service.geometry.bvh_kernel._partition" not in called_from_python  # build's helper
    compile_kernels()
    assert [name for name, kernel in called_from_python.items() if not kernel.signatures] == []
