"""nte-run reads a file as `nte-ref estimate` does: one table of cases for both readers.

The Python reader (reference_py/tools/csvio.py read_trial, with the csv module) is the
specification; firmware/host/csv_in.c is its twin (README: "It reads the input as nte-ref
estimate does").  Every case of the Python reader's own tables (test_safe_writer.READER_CASES,
test_cli.BAD_CASES) and of the table below -- a BOM, quoted cells and "" inside quotes, a
quoted cell across lines and to the end of the file, CRLF and a lone CR, comments, blank and
white-space lines (skipped), semicolons and tabs between cells with a decimal comma, text
that is not UTF-8, a NUL, Unicode spaces around a number, the number
grammar's edges, dropouts (an empty cell, nan, NA or n/a in the depth, force or velocity: the
row left out, and the note that says so word for word), more columns than the C reader once
held, the csv module's cell limit -- goes
through the reference and through nte-run and nte-run-double (--no-units-check: the reader
alone; test_run_units.py holds the units check): both refuse with the same message (one line
but where a quoted name holds a line break), or both
read it, and then nte-run-double writes the reference's float64 estimates byte for byte (the
same times, depths and forces were read).  A seeded random table of a few hundred files
built from the characters that matter to a CSV reader does the same.

Documented limits of the C reader, left out of the random table: a NUL inside a header name
(the C message stops at it), and a message longer than nte-run's 4 KiB buffer.

Requires build/host/bin/nte-run{,-double} (``make build``).
"""
from __future__ import annotations

import random
from pathlib import Path

import pytest

from reference_py.tools.cli import main
from reference_py.tools.csvio import CsvError, Units, left_out_note, read_trial
from run_records import NEEDS_C, PROGS, c_run, reference
from test_cli import BAD_CASES
from test_safe_writer import READER_CASES

pytestmark = NEEDS_C

H = b"t_s,depth_mm,force_n\n"
LIMIT = 131072      # the csv module's cell limit, characters

EXTRA: list[tuple[str, bytes]] = [
    ("bom, quotes, comment", b'\xef\xbb\xbf# rig\n"t_s", depth_mm ,"force_n"\n0,"0.0",0.01\n'
                             b'0.01,0.1,"0.02"\n0.02,0.3,0.03\n'),
    ("bom only", b"\xef\xbb\xbf\n" + H),
    ("bom on line 2", H + b"\xef\xbb\xbf0,0,0\n"),
    ("crlf", b"t_s,depth_mm,force_n\r\n0,0,0\r\n0.01,0.1,0\r\n"),
    ("lone cr", b"t_s,depth_mm,force_n\r0,0,0\r"),
    ("cr inside a cell", H + b"0,1\r2,0\n"),
    ("no final newline", H + b"0,0,0\n0.01,0.1,0"),
    ("trailing blank line", H + b"0,0,0\n\n"),
    ("white-space line", H + b"0,0,0\n  \t\n"),
    ("quoted empty line", H + b'0,0,0\n""\n'),
    ("comment between samples", H + b"0,0,0\n# note\n0.01,0.1,0\n"),
    ("indented comment", H + b"0,0,0\n #x\n"),
    ("doubled quote", H + b'0,"1""",0\n'),
    ("text after a closing quote", H + b'0,"1"5,0\n0.1,1,0\n'),
    ("quote inside a cell", H + b'0,1"5,0\n'),
    ("space before a quote", H + b'0, "1",0\n'),
    ("quoted cell across lines", H + b'0,"1\n2",0\n'),
    ("quoted name across lines", b't_s,"depth\n_mm",force_n\n0,1,0\n'),
    ("comment inside quotes", H + b'0,"1\n# c\n",0\n'),
    ("end of file in quotes", H + b'0,1,"0'),
    ("end of file after a quote", H + b'0,1,"'),
    ("not UTF-8", H + b"0,0,0\n0.1,\xff,0\n"),
    ("not UTF-8 in a comment", H + b"# \xc3\n0,0,0\n"),
    ("surrogate", H + b"0,\xed\xa0\x80,0\n"),
    ("overlong", H + b"0,\xc0\xaf,0\n"),
    ("NUL in a cell", H + b"0,0\x00,0\n"),
    ("no-break space around a number", H + "0,\u00a01\u3000,0\n".encode()),
    ("information separator", H + b"0,\x1c1,0\n0.1,1,0\n"),
    ("format character", H + "0,1\ufeff,0\n".encode()),
    ("quote in a bad cell", H + b"0,a'b,0\n"),
    ("both quotes", H + b"0,a'b\"\"c,0\n"),
    ("backslash", H + b"0,a\\b,0\n"),
    ("emoji", H + "0,\U0001f600,0\n".encode()),
    ("Arabic-Indic digit", H + "0,\u0663,0\n".encode()),
    ("nan with payload", H + b"0,nan(1),0\n"),
    ("Infinity", H + b"0,-Infinity,0\n"),
    ("infinit", H + b"0,infinit,0\n"),
    ("number edges", H + b"0,1.,0\n0.5,.5,+1e+2\n1,-0.0,1E-3\n"),
    ("exponent without digits", H + b"0,1e,0\n"),
    ("lone dot", H + b"0,.,0\n"),
    ("underflow", H + b"0,1e-999,0\n0.5,4.9e-324,0\n"),
    ("time repr", H + b"1e16,0,0\n1e-5,0,0\n"),
    ("time repr, negative zero", H + b"1e22,0,0\n-0.0,0,0\n"),
    ("time repr, subnormal", H + b"5e-324,0,0\n0,0,0\n"),
    ("velocity given", b"t_s,depth_mm,velocity_mm_s,force_n\n0,0,1.5,0\n0.01,0.1,2.5,0\n"),
    ("70 columns", b"t_s,depth_mm,force_n," + b",".join(b"c%d" % i for i in range(67)) + b"\n"
                   + b"0,1,2," + b",".join(b"%d" % i for i in range(67)) + b"\n"),
    ("70 columns, header only", b"t_s,depth_mm,force_n,"
                                + b",".join(b"c%d" % i for i in range(67)) + b"\n"),
    ("a cell at the limit", H + b"0,0." + b"0" * (LIMIT - 3) + b"1,0\n"),
    ("a name of two-byte characters at the limit",
     b"t_s,depth_mm,force_n," + "\u00e9".encode() * LIMIT + b"\n0,0,0,0\n"),
    ("a cell over the limit", H + b"0,1" + b"0" * LIMIT + b",0\n"),
    ("unit in a name", b"t_ms,depth_m,force_mN\n0,0,0\n"),
    ("only comments", b"# a\n# b\n"),
    ("blank first line", b"\n" + H),
    ("blank lines between samples", H + b"\n0,0,0\n \n\r\n0.01,0.1,0\n\n"),
    ("semicolons, decimal commas", b"t_s;depth_mm;force_n\n0;0,5;-0,01\n0,01;,75;1,e-3\n"),
    ("tabs, decimal points", b"t_s\tdepth_mm\tforce_n\r\n0\t0.5\t0\r\n0.01\t1\t2\r\n"),
    ("tabs after blank lines", b"\n \n# c\nt_s\tdepth_mm\tforce_n\n0\t1,5\t0\n"),
    ("semicolon inside a quoted name", b'"t;s",t_s,depth_mm,force_n\n1,0,0,0\n'),
    ("comma inside a quoted name", b'"a,b";t_s;depth_mm;force_n\n1;0;0;0\n'),
    ("comma and semicolon: the comma", b"t_s,depth_mm,force_n;x\n0,0;5,0\n"),
    ("quoted empty first line", b'""\nt_s;depth_mm;force_n\n0;0;0\n'),
    ("decimal comma in a comma file", H + b'0,"0,5",0\n'),
    ("two decimal commas", b"t_s;depth_mm;force_n\n0;0,5,5;0\n"),
    ("decimal comma without digits", b"t_s;depth_mm;force_n\n0;,;0\n"),
    ("decimal comma in the exponent", b"t_s;depth_mm;force_n\n0;1e1,5;0\n"),
    ("rows of the other separator", b"t_s\tdepth_mm\tforce_n\n0,0,0\n"),
    ("a spreadsheet's empty rows", H + b"0,0,0\n,,\n , ,\t\n\"\",,\n0.01,0.1,0\n,,\n,,\n"),
    ("empty cells before the header", b",,\n;;\n" + H + b"0,0,0\n"),
    ("a tab-only row in a tab file", b"t_s\tdepth_mm\tforce_n\n0\t0\t0\n\t\t\n"),
    ("one empty cell among numbers", H + b"0,0,0\n0.01,,0\n"),
    ("dropouts of every spelling", H + b"0,0,0\n0.01,,0\n0.02,0.2,NaN\n0.03,NA,n/a\n"
                                   b"0.04,0.4,-nan\n0.05,0.5,+NaN\n0.06,N/A,1\n0.07,0.7,0\n"),
    ("a dropout's time not compared", H + b"0,0,0\n0,,0\n0.01,0.1,0\n"),
    ("a dropout in a quoted cell", H + b'0,0,0\n0.01,0.1,""\n0.02,0.2," nan "\n0.03,0.3,0\n'),
    ("a given velocity's dropout", b"t_s,depth_mm,velocity_mm_s,force_n\n0,0,1,0\n0.1,1,,0\n"
                                   b"0.2,2,1,0\n"),
    ("a dropout with a decimal comma", b"t_s;depth_mm;force_n\n0;0,5;0\n0,1;;0\n0,2;1,5;0\n"),
    ("one dropout, no sample", H + b"0,,0\n"),
    ("a dropout's bad time", H + b"0,0,0\nx,,0\n"),
    ("nan-like words", H + b"0,0,0\n0.1,nana,0\n"),
    ("a repeated time", H + b"0,0,0\n0.01,0.1,0.1\n0.01,0.1,0.1\n0.01,0.2,0.3\n0.02,0.3,0\n"),
    ("repeats and dropouts", H + b"0,0,0\n0,,0\n0,0.1,0\n" + b"".join(
        b"0.%02d,0.%02d,0\n0.%02d,0.%02d,1\n" % (k, k, k, k) for k in range(1, 9))),
    ("a repeat in microseconds", H + b"0.000001,0,0\n0.0000010,0,0\n1e-6,0,0\n"),
    ("a time that goes back", H + b"0,0,0\n0.01,0,0\n0.01,0,0\n0.005,0,0\n"),
    ("a comma in a semicolon file's name", b"t_s;depth_mm;force_n;Temp, C\n0;0,5;0;21,5\n"
                                           b"0,01;0,6;0,1;21,5\n"),
    ("a comma in a tab file's name", b"t_s\tnote, free\tdepth_mm\tforce_n\n0\t1\t0,5\t0\n"),
    ("a comma in a quoted name", b'"t_s";"Temp, C";"depth_mm";"force_n"\n0;1;0,5;0\n'),
    ("tabs after commas", b"t_s,\tdepth_mm,\tforce_n\n0,\t0.5,\t0\n"),
    ("no separator keeps the names", b"t_s;depth, mm;force_n\n0;0;0\n"),
    ("a semicolon in a comma file's name", b"t_s,depth_mm,force_n,a;b\n0,0.5,0,1\n"),
    # a logger's preamble before the header: skipped when the header comes before the samples
    ("a preamble", b'"Test date:","2026-11-30"\n"Rate (Hz):",100\nSpecimen,gel\n\n' + H
                   + b"0,0,0\n0.01,0.1,0\n"),
    ("a preamble and a units row", b"Rig 3\n" + H + b"s,mm,N\n0,0,0\n"),
    ("a preamble line of one number", b"100\n" + H + b"0,0,0\n"),
    ("a preamble line of two numbers", b"100,200\n" + H + b"0,0,0\n"),
    ("a preamble line of numbers and nan", b"100,nan\n" + H + b"0,0,0\n"),
    ("a preamble line of missing words", b"NA,n/a\n" + H + b"0,0,0\n"),
    ("a preamble with a decimal comma", b"Rate;100,5\nt_s;depth_mm;force_n\n0;0,5;0\n"),
    ("a preamble without a separator, semicolons", b"Rig 3\n# c\nt_s;depth_mm;force_n\n"
                                                   b"s;mm;N\n0;0,5;0\n0,01;0,6;0\n"),
    ("a preamble of commas, tabs", b"Rig,3\nt_s\tdepth_mm\tforce_n\n0\t0,5\t0\n"),
    ("a preamble, no line holds the names", b"Rig;3\nx,y,z\n0,0,0\n"),
    ("a preamble, not UTF-8 after the header", b"Rig 3\n" + H + b"0,\xff,0\n"),
    ("a preamble, not UTF-8 before the header", b"Rig 3\n\xff\n" + H + b"0,0,0\n"),
    ("a wrong header, not UTF-8 later", b"x,y,z\n0,0,0\n\xff\n"),
    ("a preamble, no header", b"Rig 3\nx,y,z\n0,0,0\n"),
    ("a preamble, the named header later", b"Rig 3\nTime [s],Position [mm],Force [N]\n"
                                           b"0,0,0\n"),
    ("a preamble, two named headers", b"Time [ms],Position [mm],Force [N]\n"
                                      b"Time [s],Position [mm],Force [N]\n0,0,0\n"),
    ("a preamble, no sample", b"Rig 3\nx,y,z\n"),
    ("a preamble, the header after the samples", b"Rig 3\n0,0,0\n" + H),
    # a units row (units_row): no sample; held to the units the columns are read in
    ("a units row", H + b"(s),(mm),(N)\n0,0,0\n0.01,0.1,0\n"),
    ("a units row, bare and bracketed, another column's text",
     b"t_s,depth_mm,force_n,temp\ns,[ mm ], N ,(\xc2\xb0C)\n0,0,0,21\n"),
    ("a units row with empty cells", H + b",mm,\n0,0,0\n"),
    ("a units row in ms", H + b"(ms),(mm),(N)\n0,0,0\n"),
    ("a units row in kN", H + b"s,mm,kN\n0,0,0\n"),
    ("a units row in micro-seconds", H + "(\u00b5s),mm,N\n0,0,0\n".encode()),
    ("a units row of another quantity", H + b"(mm),(mm),(N)\n0,0,0\n"),
    ("a units row with a number", H + b"s,mm,1\n"),
    ("a units row with an unknown unit", H + b"s,mm,kip\n0,0,0\n"),
    ("a units row after a sample", H + b"0,0,0\ns,mm,N\n"),
    ("a units row twice", H + b"s,mm,N\ns,mm,N\n0,0,0\n"),
    ("a units row alone", H + b"s,mm,N\n"),
    ("a units row, semicolons", b"t_s;depth_mm;force_n\n[s];[mm];[N]\n0;0,5;0\n"),
    ("a units row of empty brackets", H + b"(),mm,N\n0,0,0\n"),
    ("a units row with a load cell's volts", H + b"(s),(mm),(V)\n0,0,0\n"),
    ("a units row of volts only", H + b"(V),(V),(V)\n0,0,0\n"),
    ("a units row with a bracket in another column", H[:-1] + b",temp\n,,,(degC)\n0,0,0,1\n"),
    # the columns not read are not looked at (csvio.read_table's ``read``)
    ("text in a column not read", H[:-1] + b",state\n0,0,0,INSERT\n0.01,0.1,0,HOLD\n"),
    ("a clock and a note in columns not read",
     b"t_s,wall,depth_mm,note,force_n\n0,12:00:00,0,\"start, ok\",0\n0.01,12:00:01,0.1,,0\n"),
    ("a row with nothing in the columns read",
     H[:-1] + b",temp\n0,0,0,21\n,,,21.5\n0.01,0.1,0,21\n"),
    ("a row with a time alone", H[:-1] + b",temp\n0,0,0,21\n0.005,,,21.5\n0.01,0.1,0,21\n"),
    ("text in a column not read, a dropout",
     H[:-1] + b",state\n0,0,0,IN\n0.01,,0,IN\n0.02,0.1,0,IN\n"),
    ("text in the velocity column", b"t_s,depth_mm,velocity_mm_s,force_n\n0,0,x,0\n"),
    ("text in the truth column", H[:-1] + b",force_true_n\n0,0,0,x\n"),
    ("nothing read first, then a units row", H[:-1] + b",temp\n,,,21\ns,mm,N,C\n0,0,0,21\n"),
    # a preamble before samples: no header (the positions advice), unless the line just
    # before them has as many cells (their header under other names)
    ("a preamble line before samples", b"Rig 3 run 7\n0,0,0\n0.01,0.1,0\n"),
    ("a header under other names before samples", b"t,d,f\n0,0,0\n"),
    ("a preamble, then a header under other names", b"Rig 3\nt,d,f\n0,0,0\n"),
    ("a header under other names, then a preamble", b"t,d,f\nRig 3\n0,0,0\n"),
    ("a units row in sec", H + b"(sec),mm,N\n0,0,0\n"),
    ("a units row in msec", H + b"msec,mm,N\n0,0,0\n"),
    ("a names row repeated under the header", H + b"Time,Depth,Force\n0,0,0\n"),
    ("names with sec", b"Time (sec),Depth (mm),Force (N)\n0,0,0\n"),
    # cells cut at runs of spaces (csvio.BLANKS): a header line with no other separator
    ("spaces between cells", b"t_s depth_mm force_n\n0 0 0\n0.01 0.1 0\n"),
    ("runs of spaces, leading and trailing, CRLF",
     b"  t_s   depth_mm  force_n  \r\n  0.00   0.00  0.00   \r\n 0.01  0.10  0.00 \t\r\n"),
    ("numpy.savetxt's digits", b"t_s depth_mm force_n\n0.000000000000000000e+00 "
                               b"0.000000000000000000e+00 1.000000000000000021e-02\n"),
    ("spaces and quoted names", b'"t_s" "depth_mm" "force_n" "temp C"\n0 0 0 21\n'),
    ("spaces and a decimal comma", b"t_s depth_mm force_n\n0 0,5 0\n"),
    ("spaces, a cell short", b"t_s depth_mm force_n\n0 0 0\n0.01 0.1\n"),
    ("spaces, a tab inside a row", b"t_s depth_mm force_n\n0\t0 0\n"),
    ("spaces, a blank line between samples", b"t_s depth_mm force_n\n0 0 0\n   \n0.01 0.1 0\n"),
    ("spaces, an empty quoted cell", b't_s depth_mm force_n\n0 "" 0\n'),
    ("a preamble, then a header with spaces", b"Rig 3\nt_s depth_mm force_n\n0 0 0\n"),
    ("a header with spaces, then commas", b"t_s depth_mm force_n\n0,0,0\n"),
    ("names with spaces that are not the names read", b"Time Depth Force\n0 0 0\n"),
    ("a header with spaces, a comma in a name", b"t_s depth_mm force_n a,b\n0 0 0 1\n"),
    # a header in a comment (the last leading comment that holds the names, where no other
    # line does), as numpy.savetxt writes it
    ("numpy.savetxt's header and cells", b"# t_s depth_mm force_n\n"
                                         b"0.000000000000000000e+00 0.000000000000000000e+00 "
                                         b"0.000000000000000000e+00\n1.000000000000000021e-02 "
                                         b"1.000000000000000056e-01 0.000000000000000000e+00\n"),
    ("a header in a comment, commas", b"#t_s,depth_mm,force_n\n0,0,0\n"),
    ("two comments that hold the names", b"# t_s,depth_mm,force_n\n# t_s;depth_mm;force_n\n"
                                         b"0;0,5;0\n"),
    ("a header in a comment and a header", b"# t_s depth_mm force_n\n" + H + b"0,0,0\n"),
    ("a header in a comment after a BOM", b"\xef\xbb\xbf# t_s,depth_mm,force_n\n0,0,0\n"),
    ("a header in a comment among comments and blank lines",
     b"# rig 3\n\n# t_s,depth_mm,force_n\n  \n# units: s, mm, N\n0,0,0\n0.01,0.1,0\n"),
    ("a header in a comment after the first sample", b"0,0,0\n# t_s,depth_mm,force_n\n"
                                                     b"0.01,0,0\n"),
    ("a header in a comment, then a preamble line", b"# t_s,depth_mm,force_n\nRig 3\n0,0,0\n"),
    ("a header in a comment, a preamble, a header", b"# t_s,depth_mm,force_n\nRig 3\n" + H
                                                    + b"0,0,0\n"),
    ("a comment's names advised on", b"# time depth force\n0 0 0\n"),
    ("a comment's names with units advised on", b"# Time [s], Depth [mm], Force [mN]\n0,0,0\n"),
    ("a comment that holds the names before one advised on",
     b"# t_s depth_mm force_n\n# time depth force\n0 0 0\n"),
    ("a comment advised on, then a header", b"# time depth force\nRig 3\n" + H + b"0,0,0\n"),
    ("a comment of one name", b"# time\n0 0 0\n"),
    ("a CR in a blank line before a preamble, then not UTF-8",
     b"\r\x1c\n11+;\r\n\xef\xbb\xbf+\n\xffx5;0\n"),
    ("a CR in a blank line, then a header", b"\r\x1c\n" + H + b"0,0,0\n"),
    ("blank lines only, one with a CR", b"\n\r\x1c\n  \n"),
    # no header at all (MATLAB's writematrix): the refusal says how to name the columns
    ("no header, a sample first", b"0,0,0\n0.01,0.1,0\n"),
    ("no header, semicolons", b"0;0,5;0\n"),
    ("no header, one column", b"5\n6\n"),
    ("a preamble, then samples without a header", b"Rig 3\n0,0,0\n"),
    ("numbers that hold a unit's advice", b"time_ms,0,0\n0,0,0\n"),
    ("a header in a comment, no sample", b"# t_s,depth_mm,force_n\n"),
    ("a header in a comment, blank lines only", b"# t_s,depth_mm,force_n\n\n  \n"),
    ("a header in a comment, an open quote", b'# "t_s,depth_mm,force_n\n0,0,0\n'),
    ("a header in a comment, not UTF-8 later", b"# t_s,depth_mm,force_n\n0,0,0\n\xff\n"),
    # clock times (clock_time): a date and time, or a time of day, read in seconds
    ("dates and times, space", H + b"2026-11-30 12:00:00.000000,0,0\n"
                               b"2026-11-30 12:00:00.010267,0.1,0\n2026-11-30 12:00:01,0.2,0\n"),
    ("dates and times, T and Z", H + b"2026-11-30T12:00:00.5Z,0,0\n2026-11-30T12:00:00.51Z,0,0\n"),
    ("dates and times, zones", H + b"2026-11-30T13:00:00+01:00,0,0\n"
                               b"2026-11-30T12:00:00.25+0000,0,0\n"
                               b"2026-11-30T06:30:00.5-05:30,0,0\n"),
    ("dates with slashes", H + b"2026/11/30 12:00:00.1,0,0\n2026/11/30 12:00:00.2,0,0\n"),
    ("dates across a month, a year, a leap day", H + b"2023-12-31 23:59:59.9,0,0\n"
                                                 b"2024-01-01 00:00:00,0,0\n"
                                                 b"2024-02-29 00:00:00,0,0\n"
                                                 b"2024-03-01 00:00:00,0,0\n"),
    ("dates before 1970, the calendar's ends", H + b"0001-01-01 00:00:00,0,0\n"
                                               b"1969-12-31 23:59:59.5,0,0\n"
                                               b"9999-12-31 23:59:59.999,0,0\n"),
    ("times of day", H + b"9:59:59.98,0,0\n9:59:59.99,0,0\n10:00:00.00,0,0\n"),
    ("times of day across midnight", H + b"23:59:59.98,0,0\n23:59:59.99,0,0\n"
                                     b"00:00:00.00,0,0\n00:00:00.01,0,0\n"),
    ("times of day, a decimal comma", b"t_s;depth_mm;force_n\n12:00:00,5;0,5;0\n"
                                      b"12:00:00,75;0,6;0\n"),
    ("a decimal comma in a comma file's clock", H + b'"12:00:00,5",0,0\n'),
    ("a clock's eighteen digits", H + b"12:00:00.123456789012345678,0,0\n"),
    ("a clock's nineteen digits", H + b"12:00:00.1234567890123456789,0,0\n"),
    ("a clock's mark without digits", H + b"12:00:00.,0,0\n"),
    ("a clock repeated", H + b"12:00:00.01,0,0\n12:00:00.01,0,0\n12:00:00.02,0,0\n"),
    ("a clock going back", H + b"12:00:00.01,0,0\n11:59:00,0,0\n"),
    ("no 29 February", H + b"2023-02-29 00:00:00,0,0\n"),
    ("no month 13", H + b"2026-13-01 00:00:00,0,0\n"),
    ("no hour 24, no second 60", H + b"24:00:00,0,0\n"),
    ("no second 60", H + b"2026-11-30 23:59:60,0,0\n"),
    ("no year 0", H + b"0000-01-01 00:00:00,0,0\n"),
    ("a zone without a date", H + b"12:00:00Z,0,0\n"),
    ("a zone of 24 h", H + b"2026-11-30 12:00:00+24:00,0,0\n"),
    ("a three-digit hour", H + b"123:00:00,0,0\n"),
    ("a day-first date", H + b"30.11.2026 12:00:00,0,0\n"),
    ("a date alone", H + b"2026-11-30,0,0\n"),
    ("a date, then a time of day", H + b"2026-11-30 12:00:00,0,0\n12:00:01,0,0\n"),
    ("a time of day, then a number", H + b"12:00:00,0,0\n43201,0,0\n"),
    ("a number, then a clock", H + b"0,0,0\n12:00:00,0,0\n"),
    ("a clock in another column", H + b"0,12:00:00,0\n"),
    ("a dropout beside a clock", H + b"12:00:00,0,0\n12:00:01,,0\n12:00:02,0.1,0\n"),
]


def _cases() -> list[tuple[str, bytes]]:
    own = [(label, text.encode() if isinstance(text, str) else text)
           for label, text, _ in READER_CASES + BAD_CASES]
    return own + EXTRA


def _python(path: Path) -> str | None:
    """The reference reader's refusal of `path`, or None when it reads it."""
    try:
        read_trial(path, units=Units(check=False))
    except CsvError as exc:
        return str(exc)
    return None


def _same_reading(path: Path, tmp: Path) -> None:
    """Both readers refuse `path` alike, or both read it and nte-run-double writes the
    reference's estimates."""
    want = _python(path)
    note = None if want is not None else left_out_note(read_trial(path, units=Units(check=False)))
    for prog in PROGS:
        c = c_run(prog, path, tmp / f"{prog}.csv", "--model", "2", "--no-units-check")
        if want is None:
            assert c.returncode == 0, (prog, c.stderr)
            # the note on the rows left out (a dropout), word for word, or none
            assert (c.stderr.startswith(f"{note}\n") if note is not None
                    else "left out" not in c.stderr), (prog, c.stderr, note)
        else:
            assert c.returncode == 2 and c.stderr == f"{prog}: error: {want}\n", (prog, c.stderr,
                                                                                  want)
    if want is None:
        ref = tmp / "ref.csv"
        assert main(["estimate", str(path), "--model", "2", "--no-units-check",
                     "--out", str(ref)]) == 0
        assert (tmp / "nte-run-double.csv").read_bytes() == ref.read_bytes()


@pytest.mark.parametrize("label,data", _cases(), ids=[c[0] for c in _cases()])
def test_one_table_for_both_readers(tmp_path, capsys, label, data):
    path = tmp_path / "in.csv"
    path.write_bytes(data)
    _same_reading(path, tmp_path)


def test_the_table_reaches_both_outcomes(tmp_path):
    """The table is not all refusals: a reader that refused everything would fail here."""
    read = 0
    for _, data in _cases():
        (tmp_path / "in.csv").write_bytes(data)
        read += _python(tmp_path / "in.csv") is None
    assert 12 <= read <= len(_cases()) - 40, read


@pytest.mark.parametrize("first", ["12:00:00.00", "2026-11-30T12:00:00.00Z"])
def test_a_clock_with_a_time_unit_is_refused_alike(tmp_path, first):
    """A clock reads in seconds by its own writing: --time-unit ms with it is refused, by both
    readers in the same words, and the file is read without it."""
    path = tmp_path / "clock.csv"
    path.write_bytes(H + f"{first},0,0\n".encode() + first.replace(".00", ".01").encode()
                     + b",0.1,0\n")
    r = reference(path, tmp_path / "ref.csv", "--model", "2", "--time-unit", "ms")
    want = "--time-unit ms: column 't_s' holds clock times, read in seconds"
    assert r.returncode == 2 and r.stderr == f"nte-ref: error: {want}\n", r.stderr
    for prog in PROGS:
        c = c_run(prog, path, tmp_path / f"{prog}.csv", "--model", "2", "--time-unit", "ms")
        assert c.returncode == 2 and c.stderr == f"{prog}: error: {want}\n", (prog, c.stderr)
        assert c_run(prog, path, tmp_path / f"{prog}.csv", "--model", "2",
                     "--no-units-check").returncode == 0


def test_a_clock_of_whole_seconds_is_too_coarse_alike(tmp_path):
    """A logger that stamps whole seconds at 100 Hz: the repeats are left out, and what is left
    (a sample a second) is refused as too coarse, not as milliseconds read as seconds."""
    path = tmp_path / "whole.csv"
    path.write_bytes(H + b"".join(b"12:00:%02d,%.2f,0.01\n" % (k // 100, k * 0.01)
                                  for k in range(600)))
    r = reference(path, tmp_path / "ref.csv", "--model", "2")
    assert r.returncode == 2, r.stderr
    want = r.stderr.removeprefix("nte-ref: error: ")
    assert want.endswith("median time step 1 s (longer than the 0.5 s gap limit): too coarse "
                         "for the estimator\n"), want
    for prog in PROGS:
        c = c_run(prog, path, tmp_path / f"{prog}.csv", "--model", "2")
        assert c.returncode == 2 and c.stderr == f"{prog}: error: {want}", (prog, c.stderr)


def test_missing_file_and_directory(tmp_path):
    _same_reading(tmp_path / "absent.csv", tmp_path)
    _same_reading(tmp_path, tmp_path)


ATOMS = [b"0", b"1", b"2", b"5", b"9", b".", b"e", b"-", b"+", b",", b",", b",", b'"', b'"',
         b"\n", b"\n", b"\n", b"\r\n", b"\r", b" ", b"\t", b"#", b"nan", b"inf", b"1e999",
         b"\xc2\xa0", b"\xef\xbb\xbf", b"\xff", b"'", b"\\", b"x", b"\xe2\x80\x83", b"\xc3\xa9",
         b"\x1c", b";", b";", b"NA", b"NaN", b"n/a"]
HEADS = [H, b'"t_s",depth_mm, force_n\r\n', b"\xef\xbb\xbf# c\nt_s,depth_mm,velocity_mm_s,force_n\n",
         b"t_s,depth_mm\n", b"", b"t_s;depth_mm;force_n\n", b'\n"t_s"\tdepth_mm\t"force_n"\n',
         b"  t_s depth_mm   force_n \n", b"# t_s depth_mm force_n\n",
         b"#t_s,depth_mm,force_n\n", b"# Time [s] depth force\n"]


@pytest.mark.parametrize("seed", [1, 2])
def test_random_files_read_alike(tmp_path, capsys, seed):
    """150 files a seed: a header, then good rows and runs of CSV-relevant characters."""
    rng = random.Random(seed)
    for _ in range(150):
        data = rng.choice(HEADS)
        t = 0
        for _ in range(rng.randint(0, 4)):
            if rng.random() < 0.6:
                t += rng.choice([1, 1, 0, -1])
                sep = rng.choice([b",", b",", b";", b"\t", b" ", b"  "])
                data += sep.join([b"%d" % t, rng.choice([b"1", b"2.5", b" 3 ", b'"4"', b"1e2",
                                                          b"2,5", b'"0,5"', b""]),
                                  rng.choice([b"0", b"-1", b".5", b",5", b"nan", b""])]) + b"\n"
            else:
                data += b"".join(rng.choice(ATOMS) for _ in range(rng.randint(1, 12)))
        path = tmp_path / "in.csv"
        path.write_bytes(data)
        _same_reading(path, tmp_path)
