"""The one CSV reader (reference_py/tools/csvio.py) and the safe writer
(reference_py/tools/safe_write.py), directly and through
nte-ref: regular files only, symlinks written through, modes kept or from the umask, no parent
created, all outputs of a command or none."""
from __future__ import annotations

import os
import stat
from pathlib import Path

import numpy as np
import pytest

from reference_py.tools import safe_write
from reference_py.tools.cli import main
from reference_py.tools.csvio import CsvError, Units, left_out_note, read_table, read_trial
from reference_py.tools.safe_write import OutputError, Outputs

SIM = ["simulate", "--preset", "paper-10mms", "--depth", "5", "--dwell", "0", "--rate", "50"]


def simulate_to(path, capsys=None) -> int:
    return main(SIM + ["--out", str(path)])


def only_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


# -- refusals ---------------------------------------------------------------------------------

def test_dev_null_is_refused_not_replaced(capsys):
    assert simulate_to("/dev/null") == 2
    assert only_line(capsys) == ("nte-ref: error: --out /dev/null: is a character device, not "
                                 "a regular file; refusing to replace it")
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_fifo_is_refused(tmp_path, capsys):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    assert simulate_to(fifo) == 2
    assert f"--out {fifo}: is a FIFO, not a regular file" in only_line(capsys)
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)


def test_directory_is_refused(tmp_path, capsys):
    assert simulate_to(tmp_path) == 2
    assert f"--out {tmp_path}: is a directory, not a regular file" in only_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_missing_parent_is_named_and_not_created(capsys):
    assert simulate_to("/nonexistent/dir/x.csv") == 2
    assert only_line(capsys) == ("nte-ref: error: --out /nonexistent/dir/x.csv: directory "
                                 "/nonexistent/dir does not exist (it is not created)")
    assert not Path("/nonexistent").exists()


def test_output_under_a_file_is_refused(tmp_path, capsys):
    f = tmp_path / "file.csv"
    f.write_text("x\n")
    assert simulate_to(f / "x.csv") == 2
    assert only_line(capsys) == f"nte-ref: error: --out {f}/x.csv: {f} is not a directory"


def test_unwritable_place_is_refused_before_work(capsys):
    assert simulate_to("/sys/x.csv") == 2
    assert only_line(capsys) == ("nte-ref: error: --out /sys/x.csv: cannot write in /sys: "
                                 "Permission denied")


def test_same_file_twice_is_refused(tmp_path, capsys):
    sim = tmp_path / "s.csv"
    assert simulate_to(sim) == 0
    out = tmp_path / "e.csv"
    assert main(["estimate", str(sim), "--model", "2", "--out", str(out), "--plot",
                 str(out)]) == 2
    assert f"--plot {out}: the same file as --out {out}" in only_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]


# -- what is written --------------------------------------------------------------------------

def test_symlink_is_written_through(tmp_path):
    target = tmp_path / "real.csv"
    target.write_text("old\n")
    link = tmp_path / "link.csv"
    link.symlink_to(target)
    assert simulate_to(link) == 0
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_text().startswith("t_s,depth_mm")


def test_replaced_file_keeps_its_mode(tmp_path):
    out = tmp_path / "x.csv"
    out.write_text("old\n")
    os.chmod(out, 0o640)
    assert simulate_to(out) == 0
    assert stat.S_IMODE(os.stat(out).st_mode) == 0o640
    assert out.read_text().startswith("t_s,")


@pytest.mark.parametrize("umask,mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_new_file_honours_the_umask(tmp_path, umask, mode):
    old = os.umask(umask)
    try:
        assert simulate_to(tmp_path / "x.csv") == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(tmp_path / "x.csv").st_mode) == mode


def test_failed_plot_leaves_nothing(tmp_path, monkeypatch):
    sim = tmp_path / "s.csv"
    assert simulate_to(sim) == 0
    from reference_py.tools import plotting

    def broken(run, path, title=""):
        Path(path).write_bytes(b"half a png")
        raise RuntimeError("the plot failed")

    monkeypatch.setattr(plotting, "plot_estimate", broken)
    with pytest.raises(RuntimeError, match="the plot failed"):
        main(["estimate", str(sim), "--model", "2", "--out", str(tmp_path / "e.csv"),
              "--plot", str(tmp_path / "e.png")])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.csv"]


def test_commit_is_all_or_nothing(tmp_path, monkeypatch):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    a.write_text("old a\n")
    real_replace = os.replace

    def failing_replace(src, dst):
        if Path(dst) == b:
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(safe_write.os, "replace", failing_replace)
    with pytest.raises(OutputError, match="cannot commit the outputs: No space left on device"):
        with Outputs() as outs:
            outs.write_lines(outs.add(a), ["new a"])
            outs.write_lines(outs.add(b), ["new b"])
            outs.commit()
    assert a.read_text() == "old a\n"          # restored
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.csv"]


def test_directory_output_created_one_level_and_removed_on_failure(tmp_path):
    with pytest.raises(OutputError, match=r"directory .*/no/such does not exist"):
        Outputs().directory(tmp_path / "no" / "such" / "dir")
    d = tmp_path / "run"
    with pytest.raises(RuntimeError):
        with Outputs() as outs:
            outs.directory(d)
            outs.write_lines(outs.add(d / "x.csv"), ["x"])
            raise RuntimeError("failed in the middle")
    assert not d.exists()
    with Outputs() as outs:
        outs.directory(d)
        outs.write_lines(outs.add(d / "x.csv"), ["x"])
        outs.commit()
    assert (d / "x.csv").read_text() == "x\n"
    f = tmp_path / "f"
    f.write_text("")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        Outputs().directory(f)


# -- the reader -------------------------------------------------------------------------------

def write(tmp_path, text: str | bytes, name="in.csv") -> Path:
    p = tmp_path / name
    (p.write_bytes if isinstance(text, bytes) else p.write_text)(text)
    return p


def test_bom_quotes_comments_and_optional_velocity(tmp_path):
    p = write(tmp_path, b'\xef\xbb\xbf# recorded on the rig\n"t_s", depth_mm ,"force_n"\n'
                        b'0,"0.0",0.01\n0.01,0.1,"0.02"\n0.02,0.3,0.03\n')
    tr = read_trial(p)
    np.testing.assert_array_equal(tr.depth_mm, [0.0, 0.1, 0.3])
    assert not tr.velocity_given
    np.testing.assert_allclose(tr.velocity_mm_s, [10.0, 15.0, 20.0])
    assert tr.lines == [3, 4, 5] and tr.name == "in"
    p = write(tmp_path, "t_s,depth_mm,velocity_mm_s,force_n\n0,0,1.5,0\n0.01,0.1,2.5,0\n")
    tr = read_trial(p)
    assert tr.velocity_given and list(tr.velocity_mm_s) == [1.5, 2.5]


READER_CASES = [
    ("nan time", "t_s,depth_mm,force_n\n0,0,0\nnan,0,0\n", ":3: column 't_s': not finite: 'nan'"),
    ("inf", "t_s,depth_mm,force_n\n0,-inf,0\n", ":2: column 'depth_mm': not finite: '-inf'"),
    ("overflow", "t_s,depth_mm,force_n\n0,0,1e999\n", ":2: column 'force_n': not finite: '1e999'"),
    ("hex", "t_s,depth_mm,force_n\n0,0x10,0\n", ":2: column 'depth_mm': not a number: '0x10'"),
    ("underscore", "t_s,depth_mm,force_n\n0,1_0,0\n",
     ":2: column 'depth_mm': not a number: '1_0'"),
    ("empty time", "t_s,depth_mm,force_n\n,0,0\n", ":2: column 't_s': not a number: ''"),
    ("every row a dropout", "t_s,depth_mm,force_n\n0,,0\n0.1,1,NaN\n",
     ":2: no sample: every row after the header has a value missing in column 'depth_mm' or "
     "'force_n' (2 rows)"),
    ("a dropout's other cell not a number", "t_s,depth_mm,force_n\n0,0,0\n0.1,x,\n",
     ":3: column 'depth_mm': not a number: 'x'"),
    ("a dropout's infinite cell", "t_s,depth_mm,force_n\n0,0,0\n0.1,inf,NA\n",
     ":3: column 'depth_mm': not finite: 'inf'"),
    ("a missing time among a dropout's", "t_s,depth_mm,force_n\n,,\n0,0,0\nx,0,\n",
     ":4: column 't_s': not a number: 'x'"),
    ("duplicate", "t_s,depth_mm,force_n,t_s\n", ":1: column 't_s': duplicate column name in the header"),
    ("not increasing", "t_s,depth_mm,force_n\n0,0,0\n-0.01,0,0\n",
     ":3: column 't_s': time -0.01 does not increase (previous 0.0)"),
    ("no samples", "# only\nt_s,depth_mm,force_n\n", ":3: no samples after the header"),
    ("quoted text", 't_s,depth_mm,force_n\n0,"a,b",0\n', ":2: column 'depth_mm': not a number: 'a,b'"),
    ("NUL", "t_s,depth_mm,force_n\n0,0\x00,0\n", ":2: column 'depth_mm': not a number: '0\\x00'"),
    ("decimal comma between commas", "t_s,depth_mm,force_n\n0,\"2,5\",0\n",
     ":2: column 'depth_mm': not a number: '2,5'"),
    ("two decimal marks", "t_s;depth_mm;force_n\n0;2,5.1;0\n",
     ":2: column 'depth_mm': not a number: '2,5.1'"),
    ("separators mixed", "t_s;depth_mm;force_n\n0,0,0\n", ":2: expected 3 cells, found 1"),
]


def test_blank_lines_are_skipped_wherever_they_stand(tmp_path):
    """A logger's or an editor's trailing newline, a blank line between header and samples, a
    spreadsheet's row of empty cells: the file is read, every sample keeps its physical line."""
    p = write(tmp_path, "\n  \nt_s,depth_mm,force_n\n\n0,0,0\n \t\n0.1,0.5,0.25\n,,\n\n")
    tr = read_trial(p, units=Units(check=False))
    assert list(tr.t_s) == [0.0, 0.1] and list(tr.depth_mm) == [0.0, 0.5]
    assert tr.lines == [5, 7]


@pytest.mark.parametrize("separated", [";", "\t"])
def test_semicolon_and_tab_separated_files_read_with_either_decimal_mark(tmp_path, separated):
    """What a spreadsheet set to a decimal comma exports (';' and '2,5'), and tab-separated
    logs: the header's first line gives the separator; the numbers are the comma file's."""
    rows = [("0", "0", "0.01"), ("0,01", "0,1", "-2,5e-3"), ("0.02", ",25", "+1,")]
    text = "# rig 3\n" + separated.join(('"t_s"', "depth_mm", "force_n")) + "\r\n" + "".join(
        separated.join(r) + "\r\n" for r in rows)
    tr = read_trial(write(tmp_path, text), units=Units(check=False))
    assert list(tr.t_s) == [0.0, 0.01, 0.02]
    assert list(tr.depth_mm) == [0.0, 0.1, 0.25] and list(tr.force_n) == [0.01, -2.5e-3, 1.0]


def test_a_separator_inside_a_quoted_name_does_not_decide(tmp_path):
    p = write(tmp_path, '"t_s";"depth_mm";"force_n";"note, raw"\n0;1,5;0;2\n')
    tr = read_trial(p, units=Units(check=False))
    # semicolons (1,5 is 1.5), and four names for the row's four cells: cut at the comma, the
    # header would have five and the row be refused
    assert list(tr.depth_mm) == [1.5] and list(tr.force_n) == [0.0]
    assert list(read_table(p, read=None).columns) == ["t_s", "depth_mm", "force_n", "note, raw"]


@pytest.mark.parametrize("label,text,message", READER_CASES, ids=[c[0] for c in READER_CASES])
def test_reader_refusals(tmp_path, label, text, message):
    p = write(tmp_path, text)
    with pytest.raises(CsvError) as e:
        read_trial(p)
    assert str(e.value) == f"{p}{message}"


def test_not_utf8_is_refused_with_its_line(tmp_path):
    p = write(tmp_path, b"t_s,depth_mm,force_n\n0,0,0\n0.1,\xff,0\n")
    with pytest.raises(CsvError, match=r"in.csv:3: not UTF-8 text"):
        read_trial(p)


def test_sparse_column_empty_cells_are_absent_samples(tmp_path):
    p = write(tmp_path, "t_s,depth_mm,force_n\n0,0,\n0.001,0.01,0.5\n0.002,0.02,nan\n")
    t = read_table(p, sparse=("force_n",))
    assert np.isnan(t.columns["force_n"][0]) and t.columns["force_n"][1] == 0.5
    assert np.isnan(t.columns["force_n"][2]) and t.lines == [2, 3, 4] and t.left_out == []
    with pytest.raises(CsvError, match="column 'force_n': not a number: ''"):
        read_table(p)


DROPOUTS = ("t_s,depth_mm,force_n\n0,0,0.01\n0.01,0.1,\n0.02,0.2,NaN\n0.03,,0.04\n"
            "0.04,N/A,na\n0.04,0.4,-nan\n0.05,0.5,0.06\n0.06,0.6,0.07\n0.07,0.7,+NAN\n"
            "0.08,0.8,0.09\n")


def test_a_dropout_leaves_its_row_out(tmp_path):
    """A sensor's dropout (an empty cell, nan as MATLAB and LabVIEW write it, NA as R does, any
    case) in the depth or the force: the row is not a sample.  The rows kept keep their lines,
    the velocity is the central difference over them, the time of a left-out row is not
    compared (line 7 repeats line 6's), and the note says how many, which columns, which
    lines (at most five)."""
    p = write(tmp_path, DROPOUTS)
    tr = read_trial(p, units=Units(check=False))
    assert list(tr.t_s) == [0.0, 0.05, 0.06, 0.08] and tr.lines == [2, 8, 9, 11]
    assert tr.left_out == [3, 4, 5, 6, 7, 10]
    assert tr.left_out_columns == ["depth_mm", "force_n"]
    np.testing.assert_allclose(tr.velocity_mm_s, [10.0, 10.0, 10.0, 10.0])
    assert left_out_note(tr) == (
        f"{p}: 6 of 10 rows left out, a value missing in column 'depth_mm' or 'force_n' "
        f"(a dropout: lines 3, 4, 5, 6, 7 and 1 more)")
    full = read_trial(write(tmp_path, "t_s,depth_mm,force_n\n0,0,0\n"), units=Units(check=False))
    assert full.left_out == [] and left_out_note(full) is None


def test_a_repeated_time_leaves_its_row_out_and_a_time_going_back_is_refused(tmp_path):
    """A row whose time equals the previous sample's (a logger that wrote a sample twice, a
    time printed too coarsely for the rate) is left out -- the library rejects a sample not
    later than the last -- whatever its values; the note's second line says so, the total
    counting both kinds.  A time that goes back is still refused."""
    p = write(tmp_path, "t_s,depth_mm,force_n\n0,0,0\n0.010,0.1,0.1\n0.01,0.1,0.1\n"
                        "1e-2,0.3,0.2\n0.02,,0.4\n0.02,0.2,0.2\n0.03,0.3,0.3\n")
    tr = read_trial(p, units=Units(check=False))
    assert list(tr.t_s) == [0.0, 0.01, 0.02, 0.03] and tr.lines == [2, 3, 7, 8]
    assert tr.repeated == [4, 5] and tr.left_out == [6]
    assert list(tr.force_n) == [0.0, 0.1, 0.2, 0.3]      # the first of the repeats is kept
    np.testing.assert_allclose(tr.velocity_mm_s, [10.0, 10.0, 10.0, 10.0])
    assert left_out_note(tr) == (
        f"{p}: 1 of 7 rows left out, a value missing in column 'depth_mm' or 'force_n' "
        f"(a dropout: line 6)\n"
        f"{p}: 2 of 7 rows left out, the time equal to the previous sample's (a repeat: "
        f"lines 4, 5)")
    alone = read_trial(write(tmp_path, "t_s,depth_mm,force_n\n0,0,0\n0,0,0\n"),
                       units=Units(check=False))
    assert left_out_note(alone) == (f"{tmp_path / 'in.csv'}: 1 of 2 rows left out, the time "
                                    f"equal to the previous sample's (a repeat: line 3)")
    with pytest.raises(CsvError, match=r":5: column 't_s': time 0.005 does not increase "
                                       r"\(previous 0.01\)"):
        read_trial(write(tmp_path, "t_s,depth_mm,force_n\n0,0,0\n0.01,0,0\n0.01,0,0\n"
                                   "0.005,0,0\n"), units=Units(check=False))


def test_a_given_velocity_missing_is_a_dropout_and_predict_only_keeps_the_row(tmp_path):
    """A given velocity's dropout leaves the row out too.  With ``force_ignored``
    (--predict-only) the force may be missing (kept, NaN) or absent, and only the depth and
    the velocity leave a row out."""
    p = write(tmp_path, "t_s,depth_mm,velocity_mm_s,force_n\n0,0,1,\n0.1,1,,0\n0.2,2,1,nan\n")
    with pytest.raises(CsvError) as e:
        read_trial(p, units=Units(check=False))
    assert str(e.value) == (f"{p}:2: no sample: every row after the header has a value missing "
                            f"in column 'depth_mm' or 'force_n' or 'velocity_mm_s' (3 rows)")
    tr = read_trial(p, units=Units(check=False), force_ignored=True)
    assert tr.lines == [2, 4] and tr.left_out == [3]
    assert tr.left_out_columns == ["depth_mm", "velocity_mm_s"] and np.all(np.isnan(tr.force_n))
    alone = read_trial(write(tmp_path, "t_s,depth_mm\n0,0\n0.1,1\n"), units=Units(check=False),
                       force_ignored=True)
    assert list(alone.depth_mm) == [0.0, 1.0] and np.all(np.isnan(alone.force_n))
    with pytest.raises(CsvError, match="column 'force_n': missing from the header"):
        read_trial(write(tmp_path, "t_s,depth_mm\n0,0\n"), units=Units(check=False))


# -- nte-discrepancy writes its report through the same writer --------------------------------

@pytest.mark.parametrize("out,message", [
    ("/dev/null", "--out /dev/null: exists and is not a directory"),
    ("/nonexistent/rep", "--out /nonexistent/rep: directory /nonexistent does not exist "
                         "(it is not created)"),
    ("/sys/rep", "--out /sys/rep: cannot create the directory: ")])   # + the kernel's reason
def test_discrepancy_out_refused_before_any_work(tmp_path, capsys, out, message):
    from reference_py.discrepancy.cli import main as discrepancy
    f = tmp_path / "t.csv"
    f.write_text("t_s,depth_mm,force_n\n0,0,0\n")
    assert discrepancy([str(f), "--out", out]) == 2
    line = only_line(capsys)
    assert line == "nte-discrepancy: " + message or (
        message.endswith(": ") and line.startswith("nte-discrepancy: " + message)), line


def test_discrepancy_report_all_or_nothing(tmp_path, monkeypatch):
    """A figure that fails leaves no report directory and no file behind."""
    from reference_py.discrepancy import report

    def failing_render(rep, figs):
        raise RuntimeError("render failed")

    monkeypatch.setattr(report, "render_md", failing_render)
    monkeypatch.setattr(report, "build", lambda res, inputs: {"named": []})
    with pytest.raises(RuntimeError, match="render failed"):
        report.write(None, [], tmp_path / "rep", with_figures=False)   # type: ignore[arg-type]
    assert list(tmp_path.iterdir()) == []
