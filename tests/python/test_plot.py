"""nte-ref plot: the figure's content read back from its data (panels, series, time axis, truth
lines, +-3 sigma bands) for the reference's and nte-run's estimate files and a phantom record
with its truth, and the one-line refusals with exit status 2."""
import csv
import subprocess
from pathlib import Path

import numpy as np
import pytest

from reference_py.tools import plotting
from reference_py.tools.cli import main
from reference_py.params import get_preset

NTE_RUN = Path(__file__).resolve().parents[2] / "build" / "host" / "bin" / "nte-run"


def _column(path, name):
    return np.array([float(r[name]) for r in csv.DictReader(open(path))])


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """A short simulated insertion (paper-10mms, 10 mm, 0.5 s dwell) and its reference estimate."""
    d = tmp_path_factory.mktemp("plot_sim")
    assert main(["simulate", "--preset", "paper-10mms", "--depth", "10", "--dwell", "0.5",
                 "--seed", "2", "--out", str(d / "sim.csv")]) == 0
    assert main(["estimate", str(d / "sim.csv"), "--model", "2", "--out",
                 str(d / "ref.csv")]) == 0
    return d


@pytest.fixture(scope="module")
def c_est(sim):
    """The same estimate by the C twin (float32)."""
    if not NTE_RUN.exists():
        pytest.skip(f"{NTE_RUN} missing: build the firmware first (cmake --build build/host)")
    out = sim / "c.csv"
    r = subprocess.run([str(NTE_RUN), str(sim / "sim.csv"), "--model", "2", "--out", str(out)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def phantom(tmp_path_factory):
    """A small phantom record (skin-on-muscle, 50 Hz, 12 mm stroke, 1 s dwell), its truth and a
    Model III estimate (with the contact front end; estimate --plot draws it too)."""
    d = tmp_path_factory.mktemp("plot_phantom")
    assert main(["phantom", "skin-on-muscle", "--seed", "3", "--rate", "50", "--stroke", "12",
                 "--dwell", "1", "--out", str(d / "rec.csv")]) == 0
    assert main(["estimate", str(d / "rec.csv"), "--model", "3", "--out",
                 str(d / "m3.csv"), "--plot", str(d / "m3.png")]) == 0
    return d


def test_estimate_plot_draws_model3_with_the_front_end(phantom):
    assert (phantom / "m3.png").stat().st_size > 20000


@pytest.fixture
def drawn(monkeypatch):
    """Every figure nte-ref plot saves, kept for inspection (it is still written)."""
    figures = []
    real = plotting.save_figure

    def keep(fig, path, dpi=100.0):
        figures.append(fig)
        real(fig, path, dpi)

    monkeypatch.setattr(plotting, "save_figure", keep)
    return figures


def _axes(fig):
    return {ax.get_label(): ax for ax in fig.axes}


def _series(ax):
    return [ln for ln in ax.get_lines() if ln.get_gid() == "series"]


def _by_label(ax, label):
    (line,) = [ln for ln in ax.get_lines() if ln.get_label() == label]
    return line


def _band_bounds(ax):
    """(lowest, highest) y of each +-3 sigma band of the axes."""
    bands = [c for c in ax.collections if c.get_gid() == "band"]
    return [(float(np.min(c.get_paths()[0].vertices[:, 1])),
             float(np.max(c.get_paths()[0].vertices[:, 1]))) for c in bands]


def _check_time_axis(ax, t):
    for line in _series(ax):
        assert np.array_equal(np.asarray(line.get_xdata(), dtype=float), t)
    lo, hi = ax.get_xlim()
    assert lo <= t[0] and hi >= t[-1]
    assert ax.get_xlabel() == "time (s)" or ax.get_label() == "force_time"


def _check_bands(fig, path, names, k=0):
    """The band of the k-th file on each parameter spans its estimate +- 3 sd."""
    ax = _axes(fig)
    for n in names:
        est, sd = _column(path, n), _column(path, n + "_sd")
        lo, hi = _band_bounds(ax[f"param:{n}"])[k]
        assert lo == pytest.approx(np.min(est - 3 * sd), rel=1e-9, abs=1e-15)
        assert hi == pytest.approx(np.max(est + 3 * sd), rel=1e-9, abs=1e-15)
        assert ax[f"param:{n}"].get_ylabel() == n


def test_reference_estimate_with_input_and_preset_truth(sim, tmp_path, drawn, capsys):
    png = tmp_path / "ref.png"
    assert main(["plot", str(sim / "ref.csv"), "--input", str(sim / "sim.csv"),
                 "--truth-preset", "paper-10mms", "--out", str(png)]) == 0
    assert png.stat().st_size > 20000
    (fig,) = drawn
    ax = _axes(fig)
    names = ("sigma0", "sigma1", "sigma2", "f1", "beta")
    assert set(ax) == {"force_time", "error_time", "force_depth", "error_depth",
                       *(f"param:{n}" for n in names)}
    t = _column(sim / "sim.csv", "t_s")
    assert np.array_equal(t, _column(sim / "ref.csv", "t_s"))
    # force against time: measured, true, one prediction
    assert [ln.get_label() for ln in _series(ax["force_time"])] == \
        ["measured", "true force", "Model II prediction"]
    _check_time_axis(ax["force_time"], t)
    _check_time_axis(ax["error_time"], t)
    assert ax["force_time"].get_ylabel() == "force (N)"
    true = _by_label(ax["force_time"], "true force")
    assert np.array_equal(np.asarray(true.get_ydata()), _column(sim / "sim.csv", "force_true_n"))
    pred = _by_label(ax["force_time"], "Model II prediction")
    assert np.array_equal(np.asarray(pred.get_ydata()), _column(sim / "ref.csv", "force_hat_n"))
    # the error is prediction - true force, one series
    (err,) = _series(ax["error_time"])
    assert ax["error_time"].get_ylabel() == "prediction − true force (N)"
    assert np.allclose(err.get_ydata(), _column(sim / "ref.csv", "force_hat_n")
                       - _column(sim / "sim.csv", "force_true_n"), rtol=0, atol=1e-15)
    # against depth: the same series on the input's depth
    assert ax["force_depth"].get_xlabel() == "depth (mm)"
    assert len(_series(ax["force_depth"])) == 3 and len(_series(ax["error_depth"])) == 1
    for line in _series(ax["force_depth"]):
        assert np.array_equal(np.asarray(line.get_xdata()), _column(sim / "sim.csv", "depth_mm"))
    # the dwell (from the input's motion) is shaded, the reversal marked
    assert [p.get_label() for p in ax["force_time"].patches] == ["dwell"]
    assert any(ln.get_label() == "reversal" for ln in ax["force_time"].get_lines())
    # parameters: time axis, +-3 sigma bands, the preset's value as the truth line
    _check_bands(fig, sim / "ref.csv", names)
    preset = get_preset("paper-10mms").params
    for n in names:
        a = ax[f"param:{n}"]
        assert len(_series(a)) == 1
        _check_time_axis(a, t)
        (truth,) = [ln for ln in a.get_lines() if ln.get_gid() == "truth"]
        assert truth.get_ydata()[0] == getattr(preset, n)
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("Model II: innovation RMS / noise: insertion ")
    assert out[-1] == f"wrote {png} (1 estimate file(s), input {sim / 'sim.csv'}, truth preset " \
                      f"paper-10mms)"


def test_nte_run_estimate_overlaid_on_the_reference(sim, c_est, tmp_path, drawn):
    png = tmp_path / "both.png"
    assert main(["plot", str(c_est), str(sim / "ref.csv"), "--label", "nte-run", "--label",
                 "reference", "--input", str(sim / "sim.csv"), "--out", str(png)]) == 0
    (fig,) = drawn
    ax = _axes(fig)
    t = _column(c_est, "t_s")
    assert [ln.get_label() for ln in _series(ax["force_time"])] == \
        ["measured", "true force", "nte-run prediction", "reference prediction"]
    assert [ln.get_label() for ln in _series(ax["error_time"])] == ["nte-run", "reference"]
    _check_time_axis(ax["force_time"], t)
    c_pred = _by_label(ax["force_time"], "nte-run prediction")
    assert np.array_equal(np.asarray(c_pred.get_ydata()), _column(c_est, "force_hat_n"))
    for n in ("sigma0", "beta"):
        assert [ln.get_label() for ln in _series(ax[f"param:{n}"])] == ["nte-run", "reference"]
        assert len(_band_bounds(ax[f"param:{n}"])) == 2
    _check_bands(fig, c_est, ("sigma0", "sigma1", "sigma2", "f1", "beta"), 0)
    _check_bands(fig, sim / "ref.csv", ("sigma0", "sigma1", "sigma2", "f1", "beta"), 1)


def test_without_input_time_panels_and_innovation(sim, c_est, tmp_path, drawn):
    assert main(["plot", str(c_est), "--out", str(tmp_path / "c.svg")]) == 0
    (fig,) = drawn
    ax = _axes(fig)
    assert "force_depth" not in ax and "error_depth" not in ax
    assert [ln.get_label() for ln in _series(ax["force_time"])] == ["Model II prediction"]
    (inn,) = _series(ax["error_time"])
    assert ax["error_time"].get_ylabel().startswith("innovation")
    assert np.array_equal(np.asarray(inn.get_ydata()), _column(c_est, "innovation_n"))
    _check_time_axis(ax["error_time"], _column(c_est, "t_s"))
    assert (tmp_path / "c.svg").read_text().lstrip().startswith("<?xml")


def test_phantom_truth(phantom, tmp_path, drawn, capsys):
    import json
    rec, est, truth = phantom / "rec.csv", phantom / "m3.csv", phantom / "rec.truth.json"
    assert main(["plot", str(est), "--input", str(rec), "--truth", str(truth), "--out",
                 str(tmp_path / "p.png")]) == 0
    (fig,) = drawn
    ax = _axes(fig)
    tj = json.loads(truth.read_text())
    ft = ax["force_time"]
    assert [ln.get_label() for ln in _series(ft)] == \
        ["measured", "true force", "Model III prediction"]
    assert np.array_equal(np.asarray(_by_label(ft, "true force").get_ydata()),
                          _column(rec, "force_true_n"))
    # the prediction is on the measured force's scale: force_hat_n plus the tare
    assert np.allclose(_by_label(ft, "Model III prediction").get_ydata(),
                       _column(est, "force_hat_n") + _column(est, "tare_n"), rtol=0, atol=1e-12)
    # the truth's dwell, reversal and ruptures
    (dwell,) = ft.patches
    cyc = tj["cycles"][0]
    assert dwell.get_x() == pytest.approx(cyc["insertion_end_s"])
    assert dwell.get_x() + dwell.get_width() == pytest.approx(cyc["retraction_start_s"])
    marks = [ln for ln in ft.get_lines() if ln.get_gid() == "marker"]
    assert sorted(ln.get_xdata()[0] for ln in marks) == pytest.approx(
        sorted([cyc["retraction_start_s"]] + [r["time_s"] for r in tj["ruptures"]]))
    # the phantom's Maxwell shares as lines on Model III's strengths
    for name, k in (("g_fast", 0), ("g_slow", 1)):
        (line,) = [ln for ln in ax[f"param:{name}"].get_lines() if ln.get_gid() == "truth"]
        assert line.get_ydata()[0] == tj["spec"]["tissue"]["relax_g"][k]
    _check_bands(fig, est, ("sigma0", "beta", "g_fast", "g_slow"))
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("Model III: innovation RMS / noise: insertion ")
    assert ", dwell " in out[0] and ", retraction " in out[0]
    assert out[1] == "noise: 12 mN (the truth's)"


def test_nte_run_model3_surface_nan(phantom, tmp_path, drawn):
    """nte-run's Model III file (surface_mm is nan until the surface is found) beside the
    reference's: both read, both predictions on the measured force's scale."""
    if not NTE_RUN.exists():
        pytest.skip(f"{NTE_RUN} missing: build the firmware first (cmake --build build/host)")
    c3 = tmp_path / "c3.csv"
    r = subprocess.run([str(NTE_RUN), str(phantom / "rec.csv"), "--model", "3", "--out",
                        str(c3)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "nan" in c3.read_text().splitlines()[1]
    assert main(["plot", str(c3), str(phantom / "m3.csv"), "--label", "C", "--label", "ref",
                 "--input", str(phantom / "rec.csv"), "--truth",
                 str(phantom / "rec.truth.json"), "--out", str(tmp_path / "c3.png")]) == 0
    (fig,) = drawn
    ft = _axes(fig)["force_time"]
    assert [ln.get_label() for ln in _series(ft)] == \
        ["measured", "true force", "C prediction", "ref prediction"]
    assert np.allclose(_by_label(ft, "C prediction").get_ydata(),
                       _column(c3, "force_hat_n") + _column(c3, "tare_n"), rtol=0, atol=1e-6)
    _check_time_axis(ft, _column(phantom / "rec.csv", "t_s"))
    _check_bands(fig, c3, ("sigma0", "g_fast", "g_slow"), 0)


def _refused(capsys, args, tmp_path):
    """Run nte-ref; expect exit status 2, one line on stderr, nothing on stdout, no figure."""
    try:
        rc = main(args)
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr()
    assert rc == 2
    assert err.out == ""
    lines = err.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("nte-ref"), err.err
    assert "Traceback" not in err.err
    assert not any(p.suffix in (".png", ".svg") for p in tmp_path.iterdir())
    return lines[0]


def test_refusals(sim, phantom, tmp_path, capsys):
    fig = str(tmp_path / "f.png")
    ref, inp = str(sim / "ref.csv"), str(sim / "sim.csv")
    # a missing file
    line = _refused(capsys, ["plot", str(tmp_path / "none.csv"), "--out", fig], tmp_path)
    assert line == f"nte-ref: error: {tmp_path / 'none.csv'}: cannot read: No such file or " \
                   f"directory"
    # wrong columns: an insertion given as the estimate
    line = _refused(capsys, ["plot", inp, "--out", fig], tmp_path)
    assert line.startswith(f"nte-ref: error: {inp}:1: column 'force_hat_n': missing from the "
                           f"header")
    # an estimate without parameter columns
    bare = tmp_path / "bare.csv"
    bare.write_text("t_s,force_hat_n,innovation_n,status\n0,0,0,1\n0.01,0,0,0\n")
    line = _refused(capsys, ["plot", str(bare), "--out", fig], tmp_path)
    assert "no parameter columns" in line
    # the input of another record (another length)
    line = _refused(capsys, ["plot", ref, "--input", str(phantom / "rec.csv"), "--out", fig],
                    tmp_path)
    n = len(_column(ref, "t_s"))
    assert line == (f"nte-ref: error: {ref}: {n} rows, but the input {phantom / 'rec.csv'} has "
                    f"{len(_column(phantom / 'rec.csv', 't_s'))} samples: not an estimate of "
                    f"that input (one row per input sample)")
    # same length, other times
    rows = open(inp).read().splitlines()
    shifted = tmp_path / "shifted.csv"
    shifted.write_text("\n".join([rows[0]] + [",".join([repr(float(r.split(",")[0]) + 1.0)]
                                                       + r.split(",")[1:]) for r in rows[1:]])
                       + "\n")
    line = _refused(capsys, ["plot", ref, "--input", str(shifted), "--out", fig], tmp_path)
    assert line.startswith(f"nte-ref: error: {ref}:2: column 't_s': ")
    # the truth of another record
    line = _refused(capsys, ["plot", ref, "--truth", str(phantom / "rec.truth.json"), "--out",
                             fig], tmp_path)
    assert "not the truth of this record" in line
    # a truth that is no JSON, one that is no truth
    line = _refused(capsys, ["plot", ref, "--truth", inp, "--out", fig], tmp_path)
    assert line == f"nte-ref: error: {inp}: not valid JSON"
    other = tmp_path / "other.json"
    other.write_text('{"a": 1}')
    assert "not a truth file" in _refused(capsys, ["plot", ref, "--truth", str(other), "--out",
                                                   fig], tmp_path)
    # flags: labels, format, preset, both truths
    assert "argument --label: 2 label(s) for 1 estimate file(s)" in _refused(
        capsys, ["plot", ref, "--label", "a", "--label", "b", "--out", fig], tmp_path)
    assert "argument --out" in _refused(capsys, ["plot", ref, "--out", str(tmp_path / "f.txt")],
                                        tmp_path)
    assert "argument --truth-preset: " in _refused(
        capsys, ["plot", ref, "--truth-preset", "nope", "--out", fig], tmp_path)
    assert "not allowed with argument" in _refused(
        capsys, ["plot", ref, "--truth", str(other), "--truth-preset", "paper-10mms", "--out",
                 fig], tmp_path)
    assert "required: --out" in _refused(capsys, ["plot", ref], tmp_path)


def test_refusals_from_the_console_script(sim, tmp_path):
    """The installed command: exit 2 and one line on stderr (no traceback)."""
    import shutil
    import sys
    exe = Path(sys.executable).parent / "nte-ref"
    if not exe.exists():
        exe = shutil.which("nte-ref")
        if exe is None:
            pytest.skip("nte-ref not installed")
    r = subprocess.run([str(exe), "plot", str(sim / "sim.csv"), "--out",
                        str(tmp_path / "f.png")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and len(r.stderr.splitlines()) == 1 and r.stdout == ""
    assert not (tmp_path / "f.png").exists()
