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
    ("t_s,depth_mm,force_n\n0,0,0\n0.01,0,inf\n", ":3: column 'force_n'"),
    ("t_s,depth_mm,force_n\n0,0,0\n-0.01,0,0\n", ":3: column 't_s'"),
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
    f = tmp_path / "x.xlsx"
    f.write_text("t_s,depth_mm,force_n\n0,0,0\n")
    assert main([str(f), "--out", str(tmp_path / "o")]) == 2
    f = tmp_path / "x.txt"                    # read as CSV: refused for what it holds
    f.write_text("")
    assert main([str(f), "--out", str(tmp_path / "o")]) == 2


def test_dropouts_leave_their_rows_out_and_are_said(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """A measured file whose logger wrote NaN or nothing where a sample was lost, or a sample
    twice, is analysed (it was refused, aborting the whole run); the rows left out are said
    on stderr, each line of the note with the tool's name."""
    files = _good(tmp_path)
    f = Path(files[0])
    lines = f.read_text().splitlines()
    header = lines[0].split(",")
    fi, di = header.index("force_n"), header.index("depth_mm")
    for k, word in ((40, "NaN"), (41, ""), (90, "NA")):
        cells = lines[k].split(",")
        cells[fi if k != 90 else di] = word
        lines[k] = ",".join(cells)
    lines.insert(61, lines[60])                   # a sample written twice: line 62 repeats 61
    f.write_text("\n".join(lines) + "\n")
    out = tmp_path / "rep"
    assert main(files + ["--out", str(out), "--no-figures"]) == 0
    err = capsys.readouterr().err
    assert (f"nte-discrepancy: {f}: 3 of {len(lines) - 1} rows left out, a value missing in "
            f"column 'depth_mm' or 'force_n'") in err
    assert (f"\nnte-discrepancy: {f}: 1 of {len(lines) - 1} rows left out, the time equal to "
            f"the previous sample's (a repeat: line 62)\n") in err
    rep = json.loads((out / "report.json").read_text())
    assert not rep["skipped"] and rep["named"]


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


@pytest.mark.parametrize("text,why", [
    ("t_s,depth_mm,force_n\n0,0,0\n0.01,0,1e300\n", "range"),      # refused by the reader's
    ("t_s,depth_mm,force_n\n0,0,0\n0.01,-2e4,0\n", "range"),       # unit checks already
    ("", "no header line"),
    ("# only a comment\n", "no header line"),
])
def test_bad_values_exit_2_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    text: str, why: str) -> None:
    f = tmp_path / "bad.csv"
    f.write_text(text)
    out = tmp_path / "o"
    assert main([str(f), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert why in err and err.count("\n") == 1 and not out.exists()


def test_spreadsheet_csv_with_bom_and_quoted_cells(tmp_path: Path) -> None:
    """A spreadsheet export (UTF-8 byte-order mark, quoted header and cells, CRLF) reads exactly
    as the plain file."""
    from reference_py.discrepancy.io import read_trial
    tr = make_case(("dwell_relaxation",), 5).trials[0]
    plain, sheet = tmp_path / "plain.csv", tmp_path / "sheet.csv"
    write_csv(plain, tr)
    with open(sheet, "w", encoding="utf-8-sig", newline="") as fh:
        fh.write('"t_s","depth_mm","force_n"\r\n')
        for a, b, c in zip(tr.t_s, tr.depth_mm, tr.force_n):
            fh.write(f'"{float(a)!r}","{float(b)!r}","{float(c)!r}"\r\n')
    assert sheet.read_bytes()[:3] == b"\xef\xbb\xbf"
    got, ref = read_trial(sheet), read_trial(plain)
    for name in ("t_s", "depth_mm", "force_n"):
        assert np.array_equal(getattr(got, name), getattr(ref, name))


@pytest.mark.parametrize("suffix,separator", [(".csv", ";"), (".tsv", "\t"), (".txt", "\t")])
def test_exports_with_a_decimal_comma_or_tabs(tmp_path: Path, suffix: str, separator: str
                                              ) -> None:
    """A spreadsheet set to a decimal comma (';' between cells, '2,5') and a logger's
    tab-separated export (.tsv, .txt) read exactly as the plain file."""
    from reference_py.discrepancy.io import read_trial
    tr = make_case(("dwell_relaxation",), 5).trials[0]
    plain, other = tmp_path / "plain.csv", tmp_path / f"other{suffix}"
    write_csv(plain, tr)
    rows = zip(tr.t_s, tr.depth_mm, tr.force_n)
    other.write_text(separator.join(("t_s", "depth_mm", "force_n")) + "\n" + "".join(
        separator.join(repr(float(x)).replace(".", ",") for x in row) + "\n" for row in rows)
        + "\n")
    got, ref = read_trial(other), read_trial(plain)
    for name in ("t_s", "depth_mm", "force_n"):
        assert np.array_equal(getattr(got, name), getattr(ref, name))


@pytest.mark.parametrize("suffix", [".txt", ".dat"])
def test_a_numpy_savetxt_file_reads_as_the_plain_file(tmp_path: Path, suffix: str) -> None:
    """A trial saved by numpy.savetxt's defaults (spaces, '%.18e', the header in a comment), as
    a researcher's script writes it, reads exactly as the plain file."""
    from reference_py.discrepancy.io import read_trial
    tr = make_case(("dwell_relaxation",), 5).trials[0]
    plain, saved = tmp_path / "plain.csv", tmp_path / f"saved{suffix}"
    write_csv(plain, tr)
    np.savetxt(saved, np.column_stack((tr.t_s, tr.depth_mm, tr.force_n)),
               header="t_s depth_mm force_n")
    got, ref = read_trial(saved), read_trial(plain)
    for name in ("t_s", "depth_mm", "force_n"):
        assert np.array_equal(getattr(got, name), getattr(ref, name))


def test_candump_log_decoded_with_the_dbc(tmp_path: Path) -> None:
    """A candump log of the bench's Depth and Force frames, written with python-can through the
    project's DBC, reads back as the trial (to the frames' scaling)."""
    can = pytest.importorskip("can")
    from reference_py.bus.dbc import NteDatabase
    from reference_py.discrepancy.io import read_trial
    tr = make_case(("dwell_relaxation",), 5).trials[0]
    tx = NteDatabase().sender()
    log = tmp_path / "run.log"
    with can.CanutilsLogWriter(str(log)) as w:
        for t, d, fval in zip(tr.t_s, tr.depth_mm, tr.force_n):
            st = t % 6.5535
            w.on_message_received(tx.message("Depth", {"Depth": d, "Velocity": 0.0,
                                                       "SensorTime": st}, 1000.0 + t))
            w.on_message_received(tx.message("Force", {"Force": fval, "SensorTime": st},
                                             1000.0 + t + 1e-4))
    got = read_trial(log)
    n = len(got.t_s)
    assert n == len(tr.t_s) - 1          # the last Force frame comes after the last Depth frame
    assert np.max(np.abs(got.force_n - tr.force_n[:n])) <= 0.6e-4    # DBC scaling 1e-4 N
    assert np.allclose(got.t_s, tr.t_s[:n] - tr.t_s[0], atol=1e-5)
    assert np.max(np.abs(got.depth_mm - tr.depth_mm[:n])) <= 2e-3


def test_candump_without_force_frames_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]
                                             ) -> None:
    log = tmp_path / "empty.log"
    log.write_text("(1000.000000) vcan0 123#00\n")
    assert main([str(log), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "needs Depth and Force frames" in err and err.count("\n") == 1


def test_bad_options_exit_2_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    files = _good(tmp_path)
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    for argv, why in (([*files, "--out", str(blocker)], "exists and is not a directory"),
                      ([*files, "--out", str(blocker / "sub")], "is not a directory"),
                      ([*files, "--out", str(tmp_path / "o"), "--jobs", "0"], "--jobs"),
                      ([*files, "--out", str(tmp_path / "o"), "--force-sign", "2"],
                       "--force-sign")):
        try:
            status = main(argv)
        except SystemExit as exc:       # argparse's own refusals
            status = int(exc.code or 0)
        assert status == 2
        err = capsys.readouterr().err
        assert why in err and err.count("\n") == 1, err
        assert not (tmp_path / "o").exists()


def test_negative_sign_conventions_detected(tmp_path: Path) -> None:
    """Force and depth recorded negative on insertion: detected, flipped, said in the notes; the
    prepared trial equals the one recorded positive."""
    from reference_py.discrepancy.prep import prepare
    tr = make_case(("dwell_relaxation",), 5).trials[0]
    neg = Trial(tr.name, tr.t_s, -tr.depth_mm, -tr.force_n, None)
    p, q = prepare(neg), prepare(Trial(tr.name, tr.t_s, tr.depth_mm, tr.force_n, None))
    assert (p.force_sign, p.depth_sign) == (-1.0, -1.0) and "negative" in p.note
    assert (q.force_sign, q.depth_sign) == (1.0, 1.0) and q.note == ""
    assert p.surface_mm == pytest.approx(q.surface_mm, abs=1e-9)
    assert np.array_equal(p.force_n, q.force_n)


def test_estimator_config_written(tmp_path: Path) -> None:
    files = _good(tmp_path)
    out = tmp_path / "rep"
    assert main(files + ["--out", str(out), "--no-figures"]) == 0
    cfg = json.loads((out / "estimator_config.json").read_text())
    assert cfg["schema"] == "nte-estimator-config/1"
    assert set(cfg["params"]) >= {"sigma0", "sigma1", "sigma2", "f1", "f2", "alpha", "beta"}
    assert cfg["params"]["sigma1"] >= 0 and cfg["params"]["sigma0"] >= 0
    assert len(cfg["surface_mm"]) == len(files) == len(cfg["tare_n"])
    rep = json.loads((out / "report.json").read_text())
    assert rep["estimator_config"] == "estimator_config.json"
    for e in rep["named"]:
        assert e in ("none", "layer_puncture") or e in cfg["effects"]


def test_each_with_jobs_one_report_per_file(tmp_path: Path) -> None:
    files = _good(tmp_path)[:2]
    out = tmp_path / "each"
    assert main(files + ["--out", str(out), "--no-figures", "--each", "--jobs", "2"]) == 0
    for f in files:
        rep = json.loads((out / Path(f).stem / "report.json").read_text())
        assert rep["inputs"] == [f] and "verdict" in rep
