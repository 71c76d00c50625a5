"""Generate the C constants headers from the Python reference (the specification).

    python -m firmware.tools.gen_constants            # rewrite the headers in place
    python firmware/tools/gen_constants.py --check    # exit 1 if a committed header is stale

Every real constant the reference rounds once, ``R.c(x) = dtype(x)``, is written here as the
exact hexadecimal literal of that rounded value, once per precision, so the C library holds the
same bits without a single double in its float build:

* firmware/src/nte_constants.h — the portable exp/tanh constants and the tuning profiles;
* firmware/presets/nte_presets.h — the parameter presets (double; host programs and ports);
* firmware/host/nte_units.h — the reader's rules (reference_py/tools/csvio.py and
  units_check.py, and the csv module it reads with: the comment mark, the field limit, the characters str.strip strips,
  the units FORCE_UNITS, TIME_UNITS, DEPTH_UNITS, the column names that carry a unit, the
  --columns keys and check_units's thresholds; nte-run's firmware/host/csv_in.c and
  units_check.c);
* firmware/host/nte_verdict_rules.h — the thresholds of the closing verdict
  (reference_py/tools/verdict.py; nte-run).
"""
from __future__ import annotations

import argparse
import csv
import sys
import unicodedata
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from reference_py import bank, config, contact, layers, params, rk3, robust  # noqa: E402
from reference_py.fmath import F32, F64  # noqa: E402
from reference_py.tools import csvio, units_check, verdict  # noqa: E402

LIB_HEADER = ROOT / "firmware" / "src" / "nte_constants.h"
PRESET_HEADER = ROOT / "firmware" / "presets" / "nte_presets.h"
UNITS_HEADER = ROOT / "firmware" / "host" / "nte_units.h"
VERDICT_HEADER = ROOT / "firmware" / "host" / "nte_verdict_rules.h"

#: check_units's thresholds at which tests/python/test_run_units.py probes both readers
CHECK_INLINE = {name: getattr(units_check, name) for name in (
    "FORCE_IMPLAUSIBLE_FACTOR", "NEGATIVE_DEPTH_SHARE", "INSERTING_SPEED_MM_S",
    "INSERTING_MIN_SAMPLES", "DEPARTURE_MADS")}


def hex32(v: float) -> str:
    x = float(np.float32(v))
    if x == 0.0:
        return "0.0f" if np.signbit(x) == 0 else "-0.0f"
    return x.hex() + "f"


def hex64(v: float) -> str:
    x = float(np.float64(v))
    if x == 0.0:
        return "0.0" if np.signbit(x) == 0 else "-0.0"
    return x.hex()


def c_utf8(text: str) -> str:
    """The inside of a C string literal holding ``text``'s UTF-8 bytes: ASCII as it is, every
    other byte a \\xNN escape, the literal closed and reopened after an escape so that no
    following character is read as one more hex digit."""
    out, escaped = "", False
    for b in text.encode("utf-8"):
        if b < 0x80:
            out += ('" "' if escaped else "") + chr(b)
        else:
            out += f"\\x{b:02x}"
        escaped = b >= 0x80
    return out


def pair(name: str, v32: float, v64: float) -> tuple[str, str, str]:
    return name, hex32(v32), hex64(v64)


def lib_header() -> str:
    rows: list[tuple[str, str, str]] = []
    k32, k64 = F32.exp_constants(), F64.exp_constants()
    for key in ("ln2_hi", "ln2_lo", "log2e", "xmax", "tanh_xmax"):
        rows.append(pair("NTE_K_EXP_" + key.upper(), float(k32[key]), float(k64[key])))
    deg32, deg64 = len(k32["coeffs"]) - 1, len(k64["coeffs"]) - 1
    coeff_lines = []
    for tag, coeffs, fmt in (("f32", k32["coeffs"], hex32), ("f64", k64["coeffs"], hex64)):
        body = ", ".join(fmt(float(c)) for c in coeffs)
        coeff_lines.append((tag, body))

    cfg = config.EstimatorConfig()
    fields = ("eps_mm_s", "beta0", "r_n2", "q_z", "q_u_default", "p0_z", "p0_u", "gate_sigma",
              "u_max", "var_floor_z", "var_floor_u", "v_still_mm_s", "dt_max_s", "depth_min_mm",
              "depth_max_mm", "speed_max_mm_s", "force_max_n", "presliding_mm", "tau_fast_s",
              "tau_slow_s")
    for f in fields:
        v = float(getattr(cfg, f))
        rows.append(pair("NTE_K_DEF_" + f.upper(), v, v))
    # Model III's default step bound (config.U_STEP_MAX; Models I and II: 0, no bound)
    rows.append(pair("NTE_K_M3_U_STEP_MAX", config.U_STEP_MAX[3], config.U_STEP_MAX[3]))
    for model in (1, 2):
        pc = config.paper_config(model)
        rows.append(pair(f"NTE_K_PAPER_R_N2", pc.r_n2, pc.r_n2))
        rows.append(pair(f"NTE_K_PAPER_P0_U", pc.p0_u, pc.p0_u))
        for name in params.PARAM_NAMES:
            if name in pc.q_u:
                v = float(pc.q_u[name])
                rows.append(pair(f"NTE_K_PAPER_Q_M{model}_{name.upper()}", v, v))
    # the robust estimator (reference_py/robust.py): RobustConfig's defaults, COST_HUGE and the
    # literals its refinement rounds with R.c (the sign-certainty bound, the lambda clip)
    rc = robust.RobustConfig()
    for f in ("restart_p0_u", "lm_lambda0", "converged_confidence", "converged_change"):
        v = float(getattr(rc, f))
        rows.append(pair("NTE_K_ROB_" + f.upper(), v, v))
    rows.append(pair("NTE_K_EXP_STEP_BOUND", rk3.EXP_BOUND, rk3.EXP_BOUND))
    for f, hi in {**config.UPPER_BOUNDS, **config.ROBUST_UPPER_BOUNDS}.items():
        rows.append(pair("NTE_K_RANGE_" + f.upper() + "_MAX", hi, hi))
    rows.append(pair("NTE_K_RANGE_NOMINAL_ABS_MAX", config.NOMINAL_ABS_MAX, config.NOMINAL_ABS_MAX))
    # the contact front end (reference_py/contact.py): ContactConfig's real defaults and the
    # upper bounds of its real fields (the default surface, NaN, is written by nte_config.c)
    cc = config.ContactConfig()
    for f in (*config.CONTACT_POSITIVE_BOUNDS, *config.CONTACT_NONNEGATIVE_BOUNDS):
        v = float(getattr(cc, f))
        rows.append(pair("NTE_K_CON_" + f.upper(), v, v))
    for f, hi in {**config.CONTACT_POSITIVE_BOUNDS, **config.CONTACT_NONNEGATIVE_BOUNDS}.items():
        rows.append(pair("NTE_K_RANGE_CON_" + f.upper() + "_MAX", hi, hi))
    # Model III's force unit, in units of the sensor's noise (reference_py/contact.py unit())
    rows.append(pair("NTE_K_CON_UNIT_REF", contact.NOISE_REF_N, contact.NOISE_REF_N))
    lo = contact.NOISE_REF_N / contact.UNIT_MAX
    rows.append(pair("NTE_K_CON_UNIT_FLOOR", lo, lo))
    # Model III's rupture detector (reference_py/layers.py)
    for name in ("DRIFT_SIGMA", "THRESHOLD_SIGMA", "HOLDOFF_MM", "TEAR_RATIO_MIN"):
        v = float(getattr(layers, name))
        rows.append(pair("NTE_K_LAYER_" + name, v, v))
    # the data's bound on the published force (reference_py/bank.py)
    rows.append(pair("NTE_K_BANK_DATA_BOUND", bank.DATA_BOUND, bank.DATA_BOUND))
    rows.append(pair("NTE_K_ROB_COST_HUGE", robust.COST_HUGE, robust.COST_HUGE))
    rows.append(pair("NTE_K_ROB_SURE", 0.99, 0.99))
    rows.append(pair("NTE_K_ROB_LAMBDA_MIN", 1e-7, 1e-7))
    rows.append(pair("NTE_K_ROB_LAMBDA_MAX", 1e7, 1e7))
    p = params.PRESETS["paper-10mms"].params
    for name in params.PARAM_NAMES:
        v = float(getattr(p, name))
        rows.append(pair("NTE_K_NOMINAL_" + name.upper(), v, v))
    ex = params.f1_excess(p.f1, p.f2)
    rows.append(pair("NTE_K_NOMINAL_F1_EXCESS", ex, ex))
    for name, v in params.RELAX_NOMINAL.items():
        rows.append(pair("NTE_K_NOMINAL_" + name.upper(), v, v))
    seen: set[str] = set()
    uniq = []
    for r in rows:
        if r[0] not in seen:
            seen.add(r[0])
            uniq.append(r)

    out = ["/* Generated by firmware/tools/gen_constants.py from reference_py: do not edit. */",
           "/* Every value is the reference's R.c(x): the float64 value rounded once to the */",
           "/* working precision, written as an exact hexadecimal literal. */",
           "#ifndef NTE_CONSTANTS_H", "#define NTE_CONSTANTS_H", "",
           "#if NTE_DOUBLE", f"#define NTE_K_EXP_DEGREE {deg64}",
           f"#define NTE_K_EXP_COEFFS {{ {coeff_lines[1][1]} }}"]
    out += [f"#define {n} ({v64})" for n, _, v64 in uniq]
    out += ["#else", f"#define NTE_K_EXP_DEGREE {deg32}",
            f"#define NTE_K_EXP_COEFFS {{ {coeff_lines[0][1]} }}"]
    out += [f"#define {n} ({v32})" for n, v32, _ in uniq]
    out += ["#endif", ""]
    out += range_lines()
    out += ["", "#endif /* NTE_CONSTANTS_H */", ""]
    return "\n".join(out)


def range_lines() -> list[str]:
    """The valid ranges of the configuration (reference_py/config.py's tables), which
    nte_config_check applies exactly as EstimatorConfig.validate and RobustConfig.validate do."""
    out = ["/* Valid configuration ranges (reference_py/config.py INT_RANGES, POSITIVE_FIELDS, */",
           "/* NONNEGATIVE_FIELDS, ROBUST_INT_RANGES, ROBUST_POSITIVE_FIELDS; the real */",
           "/* upper bounds are the NTE_K_RANGE_* constants above). */"]
    for prefix, table in (("NTE_RANGE_", config.INT_RANGES),
                          ("NTE_RANGE_ROB_", config.ROBUST_INT_RANGES),
                          ("NTE_RANGE_CON_", config.CONTACT_INT_RANGES)):
        for name, (lo, hi) in table.items():
            out.append(f"#define {prefix}{name.upper()}_MIN {lo}")
            out.append(f"#define {prefix}{name.upper()}_MAX {hi}")
    for macro, arg, fields in (("NTE_CONFIG_POSITIVE_FIELDS", "c", config.POSITIVE_FIELDS),
                               ("NTE_CONFIG_NONNEGATIVE_FIELDS", "c", config.NONNEGATIVE_FIELDS),
                               ("NTE_ROBUST_POSITIVE_FIELDS", "r",
                                config.ROBUST_POSITIVE_FIELDS)):
        body = ", ".join(f"({arg})->{f}" for f in fields)
        out.append(f"#define {macro}({arg}) {body}")
    # the contact front end: integer defaults, and its real fields beside their upper bounds
    # (CONTACT_POSITIVE_BOUNDS, CONTACT_NONNEGATIVE_BOUNDS; the bounds are NTE_K_RANGE_CON_*)
    cc = config.ContactConfig()
    for name in config.CONTACT_INT_RANGES:
        out.append(f"#define NTE_CON_DEF_{name.upper()} {getattr(cc, name)}")
    for macro, table in (("NTE_CONTACT_POSITIVE", config.CONTACT_POSITIVE_BOUNDS),
                         ("NTE_CONTACT_NONNEGATIVE", config.CONTACT_NONNEGATIVE_BOUNDS)):
        out.append(f"#define {macro}_FIELDS(k) " + ", ".join(f"(k)->{f}" for f in table))
        out.append(f"#define {macro}_MAX " +
                   ", ".join(f"NTE_K_RANGE_CON_{f.upper()}_MAX" for f in table))
    return out


def preset_header() -> str:
    out = ["/* Generated by firmware/tools/gen_constants.py from reference_py/params.py: */",
           "/* do not edit.  Host programs and ports (double; not the library). */",
           "#ifndef NTE_PRESETS_H", "#define NTE_PRESETS_H", "",
           "typedef struct nte_preset_t {", "    const char* name;",
           "    double values[7]; /* sigma0, sigma1, sigma2, f1, f2, alpha, beta */",
           "} nte_preset_t;", "",
           f"#define NTE_PRESET_COUNT {len(params.PRESETS)}", "",
           "static const nte_preset_t nte_presets[NTE_PRESET_COUNT] = {"]
    for name, pr in params.PRESETS.items():
        vals = ", ".join(hex64(v) for v in pr.params.as_list())
        out.append(f'    {{ "{name}", {{ {vals} }} }},')
    out += ["};", "", '#define NTE_PRESET_DEFAULT "paper-10mms"', "",
            "#endif /* NTE_PRESETS_H */", ""]
    return "\n".join(out)


def unprintable_runs() -> list[tuple[int, int]]:
    """The runs of code points U+0080..U+FFFF that Python's repr escapes (not
    str.isprintable), surrogates and unassigned code points aside: control, format, separator
    and private-use characters, whose set does not move between Python versions as the
    unassigned ones do."""
    runs: list[tuple[int, int]] = []
    for cp in range(0x80, 0x10000):
        ch = chr(cp)
        if 0xD800 <= cp < 0xE000 or unicodedata.category(ch) == "Cn" or ch.isprintable():
            continue
        if runs and runs[-1][1] == cp - 1:
            runs[-1] = (runs[-1][0], cp)
        else:
            runs.append((cp, cp))
    return runs


def units_header() -> str:
    """The reader's rules: the text it reads, its units (factor to N, s, mm) and check_units's
    thresholds (double; host)."""
    out = ["/* Generated by firmware/tools/gen_constants.py from reference_py/tools/csvio.py */",
           "/* and units_check.py: do not edit.  The host programs' reader (double). */",
           "#ifndef NTE_UNITS_H", "#define NTE_UNITS_H", "",
           "/* The text: a comment line's mark, the csv module's limit on a cell (characters) */",
           "/* and the characters Python's str.strip strips (str.isspace, code points). */",
           f"#define NTE_CSV_COMMENT '{csvio.COMMENT}'",
           f"#define NTE_CSV_FIELD_LIMIT {csv.field_size_limit()}U",
           "/* A missing value (a dropout): an empty cell or one of these words, case aside */",
           "/* in ASCII; a note lists at most LISTED of the lines left out (left_out_note). */",
           f"#define NTE_CSV_MISSING_WORD_COUNT {len(csvio.MISSING_WORDS)}",
           "#define NTE_CSV_MISSING_WORDS { "
           + ", ".join(f'"{w}"' for w in csvio.MISSING_WORDS) + " }",
           f"#define NTE_CSV_LEFT_OUT_LISTED {csvio.LEFT_OUT_LISTED}U",
           "/* The advice for a file whose first record is a sample, its columns not given */",
           f'#define NTE_CSV_NO_HEADER_ADVICE "{csvio.NO_HEADER_ADVICE}"',
           "/* The simulator's noise-free force, read with an insertion when the file has it */",
           f'#define NTE_CSV_TRUTH_COLUMN "{csvio.TRUTH_COLUMN}"']
    spaces = [c for c in range(0x110000) if chr(c).isspace()]
    out.append(f"#define NTE_TEXT_SPACE_COUNT {len(spaces)}")
    out.append("#define NTE_TEXT_SPACES { " + ", ".join(f"0x{c:x}U" for c in spaces) + " }")
    out.append("/* The characters of the Basic Multilingual Plane above U+007F that Python's repr */")
    out.append("/* escapes, unassigned ones aside (str.isprintable; first and last of each run). */")
    runs = unprintable_runs()
    out.append(f"#define NTE_TEXT_UNPRINTABLE_COUNT {len(runs)}")
    out.append("#define NTE_TEXT_UNPRINTABLE { " +
               ", ".join(f"{{ 0x{a:x}U, 0x{b:x}U }}" for a, b in runs) + " }")
    out += ["", "typedef struct nte_unit_t {", "    const char* name;",
            "    double factor; /* to the tools' unit: N, s or mm */", "} nte_unit_t;", ""]
    kinds = {}
    for kind, table in (("FORCE", csvio.FORCE_UNITS), ("TIME", csvio.TIME_UNITS),
                        ("DEPTH", csvio.DEPTH_UNITS)):
        kinds[id(table)] = kind
        out.append(f"#define NTE_{kind}_UNIT_COUNT {len(table)}")
        cells = ", ".join(f'{{ "{n}", {hex64(v)} }}' for n, v in table.items())
        out.append(f"#define NTE_{kind}_UNITS {{ {cells} }}")
    words = ", ".join(f'"{units_check.TIME_UNIT_WORDS.get(n, "")}"' for n in csvio.TIME_UNITS)
    out.append(f"#define NTE_TIME_UNIT_WORDS {{ {words} }} /* a time step's hint */")
    out += ["/* csvio.UNIT_SUFFIX_QUANTITIES: a column named WORD, a form's between, UNIT and",
            " * its after (csvio.UNIT_NAME_FORMS) holds a quantity in UNIT, read with --KIND-unit",
            " * (key, kind, its words, its table: the arrays force_units, time_units and",
            " * depth_units that the including file initialises from NTE_*_UNITS, and",
            " * *_unit_words from NTE_*_UNIT_NAME_WORDS) */"]
    for key, kind, words, t in csvio.UNIT_SUFFIX_QUANTITIES:
        cells = ", ".join(f'"{w}"' for w in words)
        out.append(f"#define NTE_{kinds[id(t)]}_UNIT_NAME_WORD_COUNT {len(words)}")
        out.append(f"#define NTE_{kinds[id(t)]}_UNIT_NAME_WORDS {{ {cells} }}")
    out.append("/* csvio.UNIT_NAME_SPELLINGS: (a unit, another spelling of it in a name; UTF-8) */")
    out.append(f"#define NTE_UNIT_NAME_SPELLING_COUNT {len(csvio.UNIT_NAME_SPELLINGS)}")
    cells = ", ".join(f'{{ "{u}", "{c_utf8(o)}" }}' for u, o in csvio.UNIT_NAME_SPELLINGS)
    out.append(f"#define NTE_UNIT_NAME_SPELLINGS {{ {cells} }}")
    out.append(f"#define NTE_UNIT_NAME_FORM_COUNT {len(csvio.UNIT_NAME_FORMS)}")
    cells = ", ".join(f'{{ "{b}", "{a}" }}' for b, a in csvio.UNIT_NAME_FORMS)
    out.append(f"#define NTE_UNIT_NAME_FORMS {{ {cells} }}")
    out.append(f"#define NTE_UNIT_QUANTITY_COUNT {len(csvio.UNIT_SUFFIX_QUANTITIES)}")
    cells = ", ".join(f'{{ "{key}", "{kind}", {kinds[id(t)].lower()}_unit_words, '
                      f'NTE_{kinds[id(t)]}_UNIT_NAME_WORD_COUNT, {kinds[id(t)].lower()}_units, '
                      f'NTE_{kinds[id(t)]}_UNIT_COUNT }}'
                      for key, kind, _, t in csvio.UNIT_SUFFIX_QUANTITIES)
    out.append(f"#define NTE_UNIT_QUANTITIES {{ {cells} }}")
    out.append("")
    out.append("/* --columns KEY=NAME: each key and the standard column it stands for */")
    out.append(f"#define NTE_COLUMN_KEY_COUNT {len(csvio.COLUMN_KEYS)}")
    cells = ", ".join(f'{{ "{k}", "{v}" }}' for k, v in csvio.COLUMN_KEYS.items())
    out.append(f"#define NTE_COLUMN_KEYS {{ {cells} }}")
    out.append(f"#define NTE_COLUMN_KEY_REQUIRED_COUNT {len(csvio.COLUMN_KEYS_REQUIRED)}")
    cells = ", ".join(f'"{k}"' for k in csvio.COLUMN_KEYS_REQUIRED)
    out.append(f"#define NTE_COLUMN_KEYS_REQUIRED {{ {cells} }}")
    out.append("")
    out.append("/* units_check.SHORT_STROKE_UNITS: (a unit, its name) a stroke under */")
    out.append("/* MIN_STROKE_MM may be in */")
    out.append(f"#define NTE_UNITS_SHORT_STROKE_COUNT {len(units_check.SHORT_STROKE_UNITS)}")
    cells = ", ".join(f'{{ "{u}", "{w}" }}' for u, w in units_check.SHORT_STROKE_UNITS)
    out.append(f"#define NTE_UNITS_SHORT_STROKE_UNITS {{ {cells} }}")
    for name in ("MIN_STROKE_MM", "STROKE_MAX_MM", "SLOW_SPEED_MM_S", "RAMP_FROM", "RAMP_TO",
                 "MAX_REJECTED_SHARE", "MAX_FORCE_OUT_SHARE", "SIGN_DEPART_SHARE"):
        out.append(f"#define NTE_UNITS_{name} ({hex64(getattr(units_check, name))})")
    out.append(f"#define NTE_UNITS_DEPTH_OFFSET_MAX_MM ({hex64(csvio.DEPTH_OFFSET_MAX_MM)})")
    out.append(f"#define NTE_UNITS_TARE_SAMPLES {int(units_check.TARE_SAMPLES)}U")
    for name, v in CHECK_INLINE.items():
        out.append(f"#define NTE_UNITS_{name} " +
                   (f"{v}U" if isinstance(v, int) else f"({hex64(v)})"))
    out += ["", "#endif /* NTE_UNITS_H */", ""]
    return "\n".join(out)


def verdict_header() -> str:
    """The verdict's thresholds (double; host) and the status bits that keep a sample out of
    it."""
    out = ["/* Generated by firmware/tools/gen_constants.py from reference_py/tools/verdict.py: */",
           "/* do not edit.  The closing verdict of nte-run (double). */",
           "#ifndef NTE_VERDICT_RULES_H", "#define NTE_VERDICT_RULES_H", "",
           f"#define NTE_VERDICT_NOT_IN_TISSUE {int(verdict.NOT_IN_TISSUE)}U",
           f"#define NTE_VERDICT_MIN_REST_SAMPLES {int(verdict.MIN_REST_SAMPLES)}U"]
    for name in ("REST_DEPTH_MM", "FOLLOWS_FACTOR", "START_WINDOW_S", "START_FACTOR"):
        out.append(f"#define NTE_VERDICT_{name} ({hex64(getattr(verdict, name))})")
    out += ["", "#endif /* NTE_VERDICT_RULES_H */", ""]
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--check", action="store_true", help="compare instead of writing")
    a = ap.parse_args()
    stale = 0
    for path, text in ((LIB_HEADER, lib_header()), (PRESET_HEADER, preset_header()),
                       (UNITS_HEADER, units_header()), (VERDICT_HEADER, verdict_header())):
        if a.check:
            if not path.exists() or path.read_text() != text:
                print(f"{path}: stale (regenerate with firmware/tools/gen_constants.py)")
                stale += 1
        else:
            path.write_text(text)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
