"""The reader's direction and sign rules (units_check.check_units) over the repository's generators:

    .venv/bin/python tests/python/units_direction_scan.py [--held]

Every correct record must pass: the phantom's five presets (seeds 1-8) and `lab` (2100-2129),
two cycles and 30 s holds, the measured-like generator's forms (seeds 1-59: as generated, a
stage that backs off, stick-slip, 50 and 200 Hz, 50 mN of noise, a tear over 1 mm, weak
membranes, no membrane) and the blind generator's cases (every kind, three each); so must
the same records cut to start at 20-80 % of their samples (inside the tissue, mid-retraction,
or in the air after the exit), by any rule.  Records whose stage counts down from 120 mm
must be named, with the sensor inverted too.  Prints the five counts (about 1 min on one
core).  ``--held``: the same on records no rule was drawn on (:func:`held`)."""
from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

import discrepancy_generator as dg
from config_loop_figures import write_record
from discrepancy_measured_like import make_trial, phantom_trial

from reference_py.sim.phantom import simulate_phantom
from reference_py.tools.csvio import Units, UnitsError, read_trial

PRESETS = ("skin-incision", "skin-on-muscle", "muscle", "skin", "artery-filled")
FORMS = [{}, {"unload_mm": 0.5}, {"stick_slip": True}, {"rate_hz": 50.0}, {"rate_hz": 200.0},
         {"noise": 0.05}, {"release_mm": 1.0}, {"rupture_scale": 0.3}, {"n_layers": 0}]
CUTS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)
#: the words of the direction rules' refusals (the force rising or falling first)
NAMED = "while the depth decreases"


def _refusal(path: Path, t: np.ndarray, x: np.ndarray, f: np.ndarray,
             v: np.ndarray | None = None) -> str | None:
    """The reader's refusal of the record, None if it reads it."""
    if v is None:
        write_record(path, t, x, f)
    else:
        path.write_text("t_s,depth_mm,force_n,velocity_mm_s\n" + "".join(
            "%.17g,%.17g,%.17g,%.17g\n" % r for r in zip(t, x, f, v)))
    try:
        read_trial(path, units=Units())
    except UnitsError as exc:
        return str(exc)
    return None


def _named(path: Path, t: np.ndarray, x: np.ndarray, f: np.ndarray,
           v: np.ndarray | None = None) -> bool:
    """Whether the reader refuses the record with a direction rule."""
    return NAMED in (_refusal(path, t, x, f, v) or "")


def correct_records() -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]]:
    out: list = []
    for name in PRESETS:
        for s in range(1, 9):
            tr = phantom_trial(name, s)[0]
            out.append((f"{name}-{s}", tr.t_s, tr.depth_mm, tr.force_n, tr.velocity_mm_s))
    for s in range(2100, 2130):
        tr = phantom_trial("lab", s)[0]
        out.append((f"lab-{s}", tr.t_s, tr.depth_mm, tr.force_n, tr.velocity_mm_s))
    for s in (3, 5, 8):
        ph = simulate_phantom("muscle", seed=s, speeds_mm_s=(2.0, 4.0))
        out.append((f"two-cycles-{s}", ph.t_s, ph.depth_mm, ph.force_n, ph.velocity_mm_s))
        ph = simulate_phantom("skin", seed=s, dwell_s=40.0)
        k = ph.t_s < ph.t_s[0] + 30.0
        out.append((f"hold-{s}", ph.t_s[k], ph.depth_mm[k], ph.force_n[k], ph.velocity_mm_s[k]))
    for s in range(1, 60):
        for kw in FORMS:
            tr = make_trial(s, **kw)[0]     # type: ignore[arg-type]
            out.append((f"measured-like-{s}-{kw}", tr.t_s, tr.depth_mm, tr.force_n, None))
    for kind in dg.kinds():
        for k in range(3):
            for i, tr in enumerate(dg.make_case(kind, k).trials):
                out.append((f"{kind}-{k}-{i}", tr.t_s, tr.depth_mm, tr.force_n,
                            tr.velocity_mm_s))
    return out


def main() -> int:
    d = Path(tempfile.mkdtemp())
    f = d / "record.csv"
    records = correct_records()
    refused = [r[0] for r in records if _refusal(f, *r[1:]) is not None]
    n_correct = len(records)
    cut, cut_any, n_cut = [], [], 0
    sources = [(f"{p}-{s}", phantom_trial(p, s)[0]) for p in PRESETS[1:] for s in range(1, 6)]
    sources += [(f"lab-{s}", phantom_trial("lab", s)[0]) for s in range(2101, 2106)]
    sources += [(f"measured-like-{s}", make_trial(s)[0]) for s in range(1, 30)]
    for name, tr in sources:
        for frac in CUTS:
            k = int(frac * len(tr.t_s))
            n_cut += 1
            said = _refusal(f, tr.t_s[k:], tr.depth_mm[k:], tr.force_n[k:])
            if said is not None and NAMED in said:
                cut.append(f"{name} from {frac:g}")
            elif said is not None:
                cut_any.append(f"{name} from {frac:g}")
    down = [(f"measured-like-{s}", make_trial(s)[0]) for s in range(1, 40)]
    down += [(f"{p}-{s}", phantom_trial(p, s)[0]) for p in PRESETS for s in range(1, 6)]
    named = sum(_named(f, tr.t_s, 120.0 - tr.depth_mm, tr.force_n) for _, tr in down)
    both = sum(_named(f, tr.t_s, 120.0 - tr.depth_mm, -tr.force_n) for _, tr in down)
    print(f"correct records refused: {len(refused)} of {n_correct} {refused or ''}")
    print(f"correct records cut to start at 20-80 %, refused: {len(cut)} of {n_cut} {cut or ''}")
    print(f"... refused by another rule (the force's sign judged from a tissue's force "
          f"taken for the tare): {len(cut_any)} of {n_cut} {cut_any or ''}")
    print(f"stages counting down from 120 mm, named: {named} of {len(down)}")
    print(f"... with the sensor inverted too, named: {both} of {len(down)}")
    return 0 if not refused and not cut and not cut_any and named == both == len(down) else 1


#: ``--held``: records no rule was drawn on (README "Files in other units")
HELD_CUTS = (0.25, 0.45, 0.55, 0.65, 0.75)


def held() -> int:
    """The rules on records they were not drawn on: measured-like seeds 490-504 in every form,
    `lab` 2152-2159, the phantom's presets at seeds 401-402 and the blind cases 5-6 - as they
    are, cut at HELD_CUTS, and (the generator's forms as generated, every other record) their
    stage counted down from 120 mm with the sensor inverted too.  Prints the counts and the
    records refused or missed (about 1 min)."""
    f = Path(tempfile.mkdtemp()) / "record.csv"
    recs = [(f"measured-like-{s}-{kw}", make_trial(s, **kw)[0])  # type: ignore[arg-type]
            for s in range(490, 505) for kw in FORMS]
    recs += [(f"lab-{s}", phantom_trial("lab", s)[0]) for s in range(2152, 2160)]
    recs += [(f"{p}-{s}", phantom_trial(p, s)[0]) for p in PRESETS for s in (401, 402)]
    recs += [(f"{kind}-{k}-{i}", tr) for kind in dg.kinds() for k in (5, 6)
             for i, tr in enumerate(dg.make_case(kind, k).trials)]
    refused = [n for n, tr in recs if _refusal(f, tr.t_s, tr.depth_mm, tr.force_n) is not None]
    cut = [f"{n} from {c:g}" for n, tr in recs for c in HELD_CUTS
           if _refusal(f, tr.t_s[int(c * len(tr.t_s)):], tr.depth_mm[int(c * len(tr.t_s)):],
                       tr.force_n[int(c * len(tr.t_s)):]) is not None]
    inverted = [(n, tr) for n, tr in recs if not n.startswith("measured-like") or n.endswith("{}")]
    missed = [n for n, tr in inverted
              if "both the depth and the force" not in
              (_refusal(f, tr.t_s, 120.0 - tr.depth_mm, -tr.force_n) or "")]
    print(f"held-out correct records refused: {len(refused)} of {len(recs)} {refused or ''}")
    print(f"... cut to start at {', '.join(f'{100 * c:g}' for c in HELD_CUTS)} %, refused: "
          f"{len(cut)} of {len(recs) * len(HELD_CUTS)} {cut or ''}")
    print(f"... counted down from 120 mm with the sensor inverted, both named: "
          f"{len(inverted) - len(missed)} of {len(inverted)} (missed: {missed or 'none'})")
    return 0 if not refused else 1


if __name__ == "__main__":
    sys.exit(held() if sys.argv[1:] == ["--held"] else main())
