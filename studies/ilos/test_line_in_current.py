"""``studies/ilos/line_in_current.py``: the windows it prints are the run's cross-track error."""

from __future__ import annotations

from conftest import ROOT, load_script


def test_plain_los_holds_its_offset_and_the_output_names_every_window(capsys) -> None:
    script = load_script(ROOT / "studies/ilos/line_in_current.py")
    maxima = script.window_maxima(0.0, seconds=300.0, window=100.0)
    assert len(maxima) == 3 and maxima[0] >= 0.5  # it starts 0.5 m off
    assert maxima[-1] > 0.5  # plain LOS in a cross current: metres off, not converging
    script.main(["--sigmas", "0", "--seconds", "200", "--window", "100"])
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("max |y_e| (mm) per 100 s window") and len(lines[1].split()) == 5
