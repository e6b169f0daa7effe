"""``studies/headroom/headroom_tuned.py``: the told variants are built on ``mpc_tuned``."""

from __future__ import annotations

from pathlib import Path

from conftest import ROOT, load_script


def test_headroom_tuned_tells_mpc_tuned_not_mpc(tmp_path: Path) -> None:
    # On bench_mild the links are ideal, so mpc_tuned told the links is mpc_tuned bit for bit
    # when it keeps mpc_tuned's estimator settings (with mpc's it costs what mpc does, another
    # number); told its dynamics or v0 it differs.
    study = load_script(ROOT / "studies" / "headroom" / "headroom_tuned.py")
    argv = [
        "--scenarios",
        "bench_mild",
        "--num-seeds",
        "1",
        "--max-steps",
        "40",
        "--out",
        str(tmp_path),
    ]
    cost = {cell.policy: cell.metrics["cost"].tolist() for cell in study.main(argv)}
    assert list(cost) == ["oracle", "mpc_tuned", *study.TOLD]
    assert cost["mpc_tuned_told_links"] == cost["mpc_tuned"]
    assert cost["mpc_tuned_told_dynamics"] != cost["mpc_tuned"]
    assert cost["mpc_tuned_told_v0"] != cost["mpc_tuned"]
    summary = (tmp_path / "summary.md").read_text()
    assert "python studies/headroom/headroom_tuned.py --scenarios bench_mild" in summary
    assert "## Verdict against mpc_tuned" in summary
