"""benchmarks.glb_sizes prints one row per GLB encoding, sizes falling, the decoded outfit untangled."""

from __future__ import annotations

import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("wasmtime")


def test_a_row_per_encoding_with_sizes_times_and_decoded_measures(capsys):
    from benchmarks import glb_sizes

    glb_sizes.main(["--repeats", "1", "--garments", "tshirt"])
    lines = capsys.readouterr().out.strip().splitlines()
    assert lines[1] == (
        "| variant | bytes | gzip bytes | encode ms | crossing pairs after decoding | penetration % |"
    )
    rows = [[c.strip() for c in line.strip("|").split("|")] for line in lines[3:]]
    assert [r[0] for r in rows] == ["none", "quantized", "meshopt"]
    sizes = [int(r[1].replace(",", "")) for r in rows]
    assert sizes == sorted(sizes, reverse=True)
    assert all(0 < int(r[2].replace(",", "")) <= s for r, s in zip(rows, sizes, strict=True))
    assert all(float(r[3]) > 0 for r in rows)
    assert [r[4] for r in rows] == ["0", "0", "0"]
    assert len({r[5] for r in rows}) == 1  # the same penetration in every encoding
