"""benchmarks.untangler_size prints one row per operator directory, from its config and its calls."""

from __future__ import annotations

import pytest

pytest.importorskip("onnxruntime")


def test_a_row_per_directory_with_the_width_and_the_errors_of_the_stored_evaluation(capsys):
    from benchmarks import untangler_size
    from service.pipeline.untangle_onnx import NeuralUntangler, default_directory

    untangler_size.main([str(default_directory()), "--repeats", "1"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[1].startswith("| width x depth | layered | near_zero | paper |")
    cells = [c.strip() for c in lines[-1].strip("|").split("|")]
    config = NeuralUntangler(default_directory(), threads=1).config
    assert cells[0] == f"{config['config']['hidden']} x {config['config']['depth']}"
    stored = config["evaluation"]
    for name, cell in zip(("layered", "near_zero", "paper"), cells[1:4], strict=True):
        # fresh samples: within a quarter of the error the training run measured on its own
        assert (
            abs(float(cell) - stored[name]["near_surface_mean_mm"])
            <= 0.25 * stored[name]["near_surface_mean_mm"] + 0.01
        )
    assert all(float(c) > 0 for c in cells[4:])
