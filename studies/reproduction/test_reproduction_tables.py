"""``studies/reproduction/reproduction_tables.py``: the claims table and the ablation rows."""

from __future__ import annotations

from conftest import ROOT, load_script


def test_reproduction_tables() -> None:
    tables = load_script(ROOT / "studies" / "reproduction" / "reproduction_tables.py")
    claims = tables.main(["claims", "--max-steps", "20"]).splitlines()
    assert len(claims) == 2 + 5 and "formula:" in claims[3]
    rows = tables.ablation_rows(max_steps=10)
    assert [(r[0], r[2]) for r in rows] == [
        (s, p) for s in tables.ABLATION_SCENARIOS for p in tables.ABLATION_POLICIES
    ]
    assert {r[1] for r in rows if r[0].endswith("_fine")} == {"plain"}
    assert {r[1] for r in rows if not r[0].endswith("_fine")} == {"gamma_scaled"}
