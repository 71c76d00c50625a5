"""Command line, input errors, skipped trials, report consistency and figures."""
import json
from pathlib import Path

import numpy as np
import pytest

from discrepancy_generator import make_case
from reference_py.discrepancy.cli import main
from reference_py.discrepancy.io import Trial, write_csv
from reference_py.discrepancy.report import render_md


def _good(tmp_path: Path, kind: tuple[str, ...] = ("dwell_relaxation",), seed: int = 5
          ) -> list[str]:
    case = make_case(kind, seed)
    files = []
    for i, tr in enumerate(case.trials):
        f = tmp_path / f"t{i}.csv"
        write_csv(f, tr)
        files.append(str(f))
    return files


def test_end_to_end_report_and_figures(tmp_path: Path) -> None:
    files = _good(tmp_path)
    out = tmp_path / "rep"
    assert main(files + ["--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert rep["named"] and rep["named"][0] in {e["name"] for e in rep["effects"]} | {"none"}
    assert rep["figures"]
    for f in rep["figures"]:
        assert (out / f).stat().st_size > 1000
    # every number in report.md is recomputed from report.json alone
    assert (out / "report.md").read_text() == render_md(rep, rep["figures"])
    for e in rep["effects"]:
        assert set(e) >= {"name", "parameters", "score", "errors_before", "errors_after"}
    # per-phase errors equal a recomputation: RMSE^2 * n summed over phases = overall
    for err in rep["errors"]:
        tot = sum(v["rmse_n"] ** 2 * v["n"] for k, v in err.items() if k != "overall")
        assert np.isclose(tot / err["overall"]["n"], err["overall"]["rmse_n"] ** 2, rtol=1e-9)


@pytest.mark.parametrize("text,where", [
    ("t_s,depth_mm\n0,0\n", ":1: column 'force_n'"),
    ("t_s,depth_mm,force_n\n0,0,0\n0.01,abc,0\n", ":3: column 'depth_mm'"),
    ("t_s,depth_mm,force_n\n0,0,0\n0.01,0,nan\n", ":3: column 'force_n'"),
    ("t_s,depth_mm,force_n\n0,0,0\n0,0,0\n", ":3: column 't_s'"),
    ("t_s,depth_mm,force_n\n0,0,0\n0.01,0\n", ":3"),
])
def test_bad_input_names_file_line_column(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          text: str, where: str) -> None:
    f = tmp_path / "bad.csv"
    f.write_text(text)
    assert main([str(f), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert str(f) + where in err


def test_unknown_and_missing_files_exit_2(tmp_path: Path) -> None:
    assert main([str(tmp_path / "nope.csv"), "--out", str(tmp_path / "o")]) == 2
    f = tmp_path / "x.txt"
    f.write_text("")
    assert main([str(f), "--out", str(tmp_path / "o")]) == 2


def test_short_trial_is_skipped_not_fatal(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                          ) -> None:
    files = _good(tmp_path, (), 11)
    short = tmp_path / "short.csv"
    write_csv(short, Trial("short", np.arange(20) * 0.01, np.zeros(20), np.zeros(20)))
    out = tmp_path / "rep"
    assert main(files + [str(short), "--out", str(out), "--no-figures"]) == 0
    rep = json.loads((out / "report.json").read_text())
    assert [s["name"] for s in rep["skipped"]] == ["short"]
    assert "skipped short" in capsys.readouterr().err
