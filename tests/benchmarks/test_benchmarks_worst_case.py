"""benchmarks.worst_case prints one row per stack and body, refused stacks marked."""

from __future__ import annotations

from benchmarks import worst_case


def test_the_table_has_a_row_per_stack_and_body(capsys, monkeypatch):
    monkeypatch.setattr(worst_case, "STACKS", (("tshirt", "jacket"), ("skirt", "pants")))
    monkeypatch.setattr(worst_case, "BODIES", (("woman 150 cm 90 kg", 1.0, 150.0, 90.0),))
    worst_case.main([])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ")][1:]
    assert rows[0].startswith("| tshirt < jacket | woman 150 cm 90 kg |")
    assert rows[1] == "| skirt < pants | (refused) | - | - | - | - |"
