"""Tests of duffid.data.record: Record validation, CSV and MAT files."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from duffid.data.record import Record, RecordError
from duffid.errors import InputError

DT = 0.001


def make_record(n: int = 50, nf: int = 1, nx: int = 1, seed: int = 1) -> Record:
    """Record with awkward (non-round) float values."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT + 0.1
    f = rng.normal(size=(n, nf)) * 1e3
    x = rng.normal(size=(n, nx)) / 3.0
    return Record(t, f, x)


def write(tmp_path: Path, text: str, name: str = "data.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def csv_rows(n: int, ncols: int = 3, t0: float = 0.0) -> str:
    """n evenly sampled rows; the time is in the first of ncols columns."""
    lines = []
    for i in range(n):
        vals = [f"{t0 + i * DT:.6f}"] + [f"{0.5 * i + c:g}" for c in range(ncols - 1)]
        lines.append(",".join(vals))
    return "\n".join(lines) + "\n"


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a).view(np.int64)


# --------------------------------------------------------------------- Record
def test_record_properties_and_copies() -> None:
    t = np.arange(5) * 0.01
    f = np.ones(5)
    x = np.arange(10.0).reshape(5, 2)
    rec = Record(t, f, x)
    assert rec.f.shape == (5, 1) and rec.x.shape == (5, 2)
    assert rec.n_samples == 5 and rec.n_dof == 2 and rec.n_forces == 1
    assert rec.dt == pytest.approx(0.01) and rec.fs == pytest.approx(100.0)
    assert rec.duration == pytest.approx(0.04)
    assert rec.column_names == ["t", "f1", "x1", "x2"]
    assert rec.source == "array input"
    assert rec.t.dtype == np.float64 and not rec.t.flags.writeable
    assert not rec.f.flags.writeable and not rec.x.flags.writeable
    x[0, 0] = 99.0  # the record holds a copy
    assert rec.x[0, 0] == 0.0
    with pytest.raises(ValueError):
        rec.x[0, 0] = 1.0


@pytest.mark.parametrize(
    ("nf", "nx", "names"),
    [
        (1, 1, ["t", "f", "x"]),
        (1, 3, ["t", "f1", "x1", "x2", "x3"]),
        (2, 2, ["t", "f1", "f2", "x1", "x2"]),
    ],
)
def test_column_names(nf: int, nx: int, names: list[str]) -> None:
    assert make_record(nf=nf, nx=nx).column_names == names


def test_record_equality_ignores_source() -> None:
    a = make_record()
    b = Record(a.t, a.f, a.x, source="elsewhere.csv")
    assert a == b
    assert a != Record(a.t, a.f, a.x * 2.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        (
            {"x": [0.0, 1.0, np.nan, 2.0]},
            r"^array input, sample index 2, column 'x': value 'nan' is not finite",
        ),
        (
            {"f": np.array([[0.0], [1.0], [2.0], [np.inf]]), "x": np.zeros((4, 2))},
            r"^array input, sample index 3, column 'f1': value 'inf' is not finite",
        ),
        (
            {"t": [0.0, 0.1, 0.1, 0.2]},
            r"^array input, sample index 2: time 0\.1 does not increase \(previous 0\.1\)",
        ),
        (
            {"t": [0.0, 0.1, 0.2, 0.35]},
            r"^array input, sample index 3: uneven sampling, step 0\.15 differs from dt 0\.1",
        ),
        ({"x": [1.0, 2.0, 3.0]}, r"^array input: x has 3 samples but t has 4"),
        ({"t": np.zeros((4, 1))}, r"^array input: t must be 1-D"),
        ({"x": np.zeros((4, 1, 1))}, r"^array input: x must be 1-D or 2-D"),
        ({"x": np.zeros((4, 0))}, r"^array input: x has no columns"),
        ({"f": np.zeros((4, 2))}, r"^array input: 2 force columns but only 1 displacement"),
        ({"x": ["a", "b", "c", "d"]}, r"^array input: x must be a real numeric array"),
        ({"f": np.ones(4, dtype=complex)}, r"^array input: f must be a real numeric array"),
    ],
)
def test_record_validation(kwargs: dict, match: str) -> None:
    args = {"t": [0.0, 0.1, 0.2, 0.3], "f": [0.0, 1.0, 2.0, 3.0], "x": [1.0, 2.0, 3.0, 4.0]}
    args.update(kwargs)
    with pytest.raises(RecordError, match=match):
        Record(**args)


def test_record_needs_two_samples() -> None:
    with pytest.raises(RecordError, match=r"^array input: a record needs at least 2 samples, found 1"):
        Record([0.0], [1.0], [2.0])


def test_sampling_rtol_field() -> None:
    t = [0.0, 1.0, 2.0, 3.0001]
    with pytest.raises(RecordError, match="uneven sampling"):
        Record(t, np.zeros(4), np.zeros(4))
    rec = Record(t, np.zeros(4), np.zeros(4), sampling_rtol=1e-3)
    assert rec.sampling_rtol == 1e-3
    with pytest.raises(ValueError, match="sampling_rtol"):
        Record(t, np.zeros(4), np.zeros(4), sampling_rtol=-1.0)


def test_require_samples() -> None:
    rec = Record(np.arange(10.0), np.zeros(10), np.zeros(10), source="run3.csv")
    rec.require_samples(10, "the window")
    with pytest.raises(
        RecordError,
        match=r"^run3\.csv: identification window needs at least 11 samples, the record has 10$",
    ):
        rec.require_samples(11, "identification window")


def test_slice() -> None:
    rec = make_record(n=100)  # t = 0.1 + k * 0.001
    part = rec.slice(0.1 + 10 * DT, 0.1 + 19 * DT)
    assert part.n_samples == 10
    np.testing.assert_array_equal(part.t, rec.t[10:20])
    np.testing.assert_array_equal(part.x, rec.x[10:20])
    np.testing.assert_array_equal(part.f, rec.f[10:20])
    assert rec.slice(stop=0.1 + 4 * DT).n_samples == 5
    assert rec.slice(start=0.1 + 95 * DT).n_samples == 5
    assert rec.slice() == rec
    with pytest.raises(RecordError, match=r"^array input: slice \[5, 6\] selects 0 sample"):
        rec.slice(5, 6)
    with pytest.raises(RecordError, match="after stop"):
        rec.slice(0.15, 0.12)


# ------------------------------------------------------------------------ CSV
def test_csv_round_trip_one_dof_bit_exact(tmp_path: Path) -> None:
    rec = make_record(n=40)
    path = tmp_path / "one.csv"
    rec.to_csv(path)
    assert path.read_text().splitlines()[0] == "t,f,x"
    back = Record.read_csv(path)
    assert back.source == str(path)
    assert back == rec
    for a, b in ((back.t, rec.t), (back.f, rec.f), (back.x, rec.x)):
        np.testing.assert_array_equal(bits(a), bits(b))


def test_csv_round_trip_two_dof_one_force_bit_exact(tmp_path: Path) -> None:
    rec = make_record(n=30, nf=1, nx=2, seed=5)
    path = tmp_path / "two.csv"
    rec.to_csv(str(path))
    assert path.read_text().splitlines()[0] == "t,f1,x1,x2"
    back = Record.read_csv(str(path))
    assert (back.n_forces, back.n_dof) == (1, 2)
    for a, b in ((back.t, rec.t), (back.f, rec.f), (back.x, rec.x)):
        np.testing.assert_array_equal(bits(a), bits(b))


def test_csv_columns_any_order_comments_whitespace(tmp_path: Path) -> None:
    text = (
        "# rig 4, 2024-05-01\n"
        "#   units: s, N, m\n"
        " t , x2, f1 ,x1\n"
        "0.000, 20, 1, 10\n"
        " 0.001 ,21,2,11 \n"
        "0.002,22,3,12\n"
        "\n"
        "   \n"
    )
    rec = Record.read_csv(write(tmp_path, text))
    np.testing.assert_array_equal(rec.t, [0.0, 0.001, 0.002])
    np.testing.assert_array_equal(rec.f[:, 0], [1, 2, 3])
    np.testing.assert_array_equal(rec.x, [[10, 20], [11, 21], [12, 22]])


def test_csv_numbered_single_dof_and_windows_newlines(tmp_path: Path) -> None:
    path = tmp_path / "crlf.csv"
    path.write_bytes(b"\xef\xbb\xbft,f1,x1\r\n0,1,2\r\n1,3,4\r\n")
    rec = Record.read_csv(path)
    np.testing.assert_array_equal(rec.x[:, 0], [2.0, 4.0])
    assert rec.column_names == ["t", "f", "x"]


def test_csv_sampling_rtol_argument(tmp_path: Path) -> None:
    path = write(tmp_path, "t,f,x\n0,0,0\n1,0,0\n2.0001,0,0\n")
    with pytest.raises(RecordError, match="uneven sampling"):
        Record.read_csv(path)
    assert Record.read_csv(path, sampling_rtol=1e-3).n_samples == 3


HEADER = "t,f,x\n"


@pytest.mark.parametrize(
    ("text", "match"),
    [
        # non-finite values
        (HEADER + "0,1,2\n0.001,1,2\n0.002,1,nan\n", r", line 4, column 'x': value 'nan' is not finite$"),
        (HEADER + "0,1,2\n0.001,-Inf,2\n", r", line 3, column 'f': value '-Inf' is not finite$"),
        # header problems
        ("t,f1,x1,x3\n" + csv_rows(3, 4), r", line 1 \(header\): missing column 'x2' \(found t, f1, x1, x3\)$"),
        ("t,f\n" + csv_rows(3, 2), r", line 1 \(header\): missing column 'x' \(found t, f\)$"),
        ("t,x1,x2\n" + csv_rows(3, 3), r", line 1 \(header\): missing column 'f1' \(found t, x1, x2\)$"),
        ("t,x\n" + csv_rows(3, 2), r", line 1 \(header\): missing column 'f' \(found t, x\)$"),
        ("t,f,x,temp,y\n" + csv_rows(3, 5), r", line 1 \(header\): unknown columns 'temp', 'y' \(found t, f, x, temp, y;"),
        ("t,f,x,x0\n" + csv_rows(3, 4), r", line 1 \(header\): unknown column 'x0'"),
        ("f,t,x\n" + csv_rows(3), r", line 1 \(header\): first column must be 't', found 'f'"),
        ("t,f,x,\n0,1,2,\n", r", line 1 \(header\): column 4 has an empty name \(found t, f, x, ''\) \(every line ends "
                              r"with the delimiter\? remove it\)$"),
        ("t;f;x\n0;1;2\n", r", line 1 \(header\): first column must be 't', found 't;f;x'; the line is separated by "
                            r"';', not commas: is that the delimiter\?"),
        ("t,f,x\n0,1,2\n0.001,\"1,5\",2\n", r", line 3, column 'f': value '1,5' is not a number: a decimal comma\? "
                                           r"give the decimal mark ','$"),
        ("t,f,x1,x2\n" + csv_rows(3, 4), r", line 1 \(header\): mixes unnumbered 'f' with numbered columns"),
        ("t,f1,f2,x1\n" + csv_rows(3, 4), r", line 1 \(header\): 2 force columns but only 1 displacement"),
        ("t,f,x,f\n" + csv_rows(3, 4), r", line 1 \(header\): duplicate column 'f'"),
        ("t,f,,x\n" + csv_rows(3, 4), r", line 1 \(header\): column 3 has an empty name"),
        # rows
        (HEADER + "0,1,2\n0.001,1\n", r", line 3: 2 fields, the header has 3 columns$"),
        (HEADER + "0,1,2\n0.001,1,2,3\n", r", line 3: 4 fields, the header has 3 columns$"),
        (HEADER + "0,1,2\n0.001,abc,2\n", r", line 3, column 'f': value 'abc' is not a number$"),
        (HEADER + "0,1,2\n0.001,1_0,2\n", r", line 3, column 'f': value '1_0' is not a number$"),
        (HEADER + "0,1,2\n0.001,0x10,2\n", r", line 3, column 'f': value '0x10' is not a number$"),
        (HEADER + "0,1,2\n0.001,1,\n", r", line 3, column 'x': empty value$"),
        (HEADER + "0,1,2\n\n0.001,1,2\n", r", line 3: blank line inside the data \(data continues on line 4\)$"),
        (HEADER + "0,1,2\n# note\n0.001,1,2\n", r", line 3: comment lines are only allowed before the header$"),
        # sizes
        ("", r": empty file, expected a header line"),
        ("# only a comment\n\n", r": empty file, expected a header line"),
        (HEADER, r": no data rows \(header only\); a record needs at least 2 samples$"),
        (HEADER + "0,1,2\n", r": only 1 data row; a record needs at least 2 samples$"),
        # time axis
        (
            "t,f,x\n" + "".join(f"{i / 1000:g},0,0\n" for i in range(12)) + "0.011,0,0\n",
            r", line 14: time 0\.011 does not increase \(previous 0\.011\)$",
        ),
        (HEADER + "0,0,0\n0.002,0,0\n0.001,0,0\n", r", line 4: time 0\.001 does not increase \(previous 0\.002\)$"),
        (
            "t,f,x\n" + "".join(f"{i / 1000:g},0,0\n" for i in range(38)) + "0.0385,0,0\n",
            r", line 40: uneven sampling, step 0\.0015 differs from dt 0\.001 by more than the "
            r"tolerance \(rtol 1e-06\); duffid never resamples: resample before identification$",
        ),
    ],
)
def test_csv_errors(tmp_path: Path, text: str, match: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(RecordError, match="^" + re.escape(str(path)) + match):
        Record.read_csv(path)


def test_csv_decimal_comma(tmp_path: Path) -> None:
    """A logger or spreadsheet that writes 1,5: the same record with decimal=","; the decimal
    mark cannot be the delimiter too."""
    plain = write(tmp_path, "t,f,x\n0,1.5,2e-3\n0.001,-2.25,1.5e-3\n0.002,0,1\n")
    comma = tmp_path / "comma.csv"
    comma.write_text("t;f;x\n0;1,5;2e-3\n0,001;-2,25;1,5e-3\n0,002;0;1\n")
    assert Record.read_csv(comma, delimiter=";", decimal=",") == Record.read_csv(plain)
    # every field of the first data row with a decimal comma: data, not a units row
    every = tmp_path / "every.csv"
    every.write_text("t;f;x\n0,000;1,5;2,0e-3\n0,001;-2,25;1,5e-3\n0,002;0,0;1,0\n")
    assert Record.read_csv(every, delimiter=";", decimal=",") == Record.read_csv(plain)
    with pytest.raises(InputError, match="decimal mark and the delimiter are both ','"):
        Record.read_csv(plain, decimal=",")
    with pytest.raises(InputError, match="decimal mark must be"):
        Record.read_csv(plain, decimal=";")


def test_csv_declared_delimiter(tmp_path: Path) -> None:
    """Excel's ``sep=;`` first line declares the delimiter; a different one given is an error
    naming the line."""
    plain = write(tmp_path, "t,f,x\n0,1.5,2e-3\n0.001,-2.25,1.5e-3\n")
    excel = tmp_path / "excel.csv"
    excel.write_text("sep=;\nt;f;x\n0;1,5;2e-3\n0,001;-2,25;1,5e-3\n")
    assert Record.read_csv(excel, decimal=",") == Record.read_csv(plain)
    with pytest.raises(RecordError, match=r"excel.csv, line 1: the file declares the delimiter ';' \(sep=\)"):
        Record.read_csv(excel, delimiter="\t", decimal=",")
    with pytest.raises(RecordError, match=r"line 3, column 'f': value '1,5' is not a number: a decimal comma"):
        Record.read_csv(excel)


def test_csv_missing_file_and_bad_encoding(tmp_path: Path) -> None:
    missing = tmp_path / "nope.csv"
    with pytest.raises(RecordError, match="^" + re.escape(str(missing)) + ": cannot read file"):
        Record.read_csv(missing)
    binary = tmp_path / "bin.csv"
    binary.write_bytes(b"t,f,x\n0,1,\xff\n")
    with pytest.raises(RecordError, match="^" + re.escape(str(binary)) + ": not a UTF-8 text file"):
        Record.read_csv(binary)


# ------------------------------------------------------------------------ MAT
def test_mat_round_trip_single_names(tmp_path: Path) -> None:
    rec = make_record(n=25, nf=2, nx=3)
    path = tmp_path / "rig"  # no extension appended
    rec.to_mat(path, t="time", f="force", x="disp")
    assert path.exists()
    raw = scipy.io.loadmat(path, appendmat=False)
    assert raw["time"].shape == (25, 1) and raw["force"].shape == (25, 2)
    assert raw["disp"].shape == (25, 3)
    back = Record.read_mat(path, t="time", f="force", x="disp")
    assert back == rec and back.source == str(path)
    np.testing.assert_array_equal(bits(back.x), bits(rec.x))


def test_mat_round_trip_name_lists(tmp_path: Path) -> None:
    rec = make_record(n=20, nf=1, nx=2)
    path = tmp_path / "rig.mat"
    rec.to_mat(path, t="tt", f=["u1"], x=["q1", "q2"])
    raw = scipy.io.loadmat(path)
    assert raw["q2"].shape == (20, 1)
    np.testing.assert_array_equal(raw["q2"][:, 0], rec.x[:, 1])
    back = Record.read_mat(path, t="tt", f=["u1"], x=["q1", "q2"])
    assert back == rec
    # the same file read with a reversed name list swaps the columns
    swapped = Record.read_mat(path, t="tt", f="u1", x=["q2", "q1"])
    np.testing.assert_array_equal(swapped.x, rec.x[:, ::-1])


def test_mat_to_mat_bad_names(tmp_path: Path) -> None:
    rec = make_record(nx=2)
    with pytest.raises(ValueError, match="not a valid MATLAB variable name"):
        rec.to_mat(tmp_path / "a.mat", t="_t")
    with pytest.raises(ValueError, match="used twice"):
        rec.to_mat(tmp_path / "a.mat", f="x1", x=["x1", "x2"])
    with pytest.raises(ValueError, match="x: 1 names given for 2 columns"):
        rec.to_mat(tmp_path / "a.mat", x=["x1"])


def test_read_mat_with_fs_and_row_vectors(tmp_path: Path) -> None:
    path = tmp_path / "scope.mat"
    n = 64
    force = np.sin(np.arange(n) / 5.0)
    disp = np.cos(np.arange(n) / 7.0)
    scipy.io.savemat(path, {"F": force.reshape(1, -1), "X": disp.reshape(-1, 1)})
    rec = Record.read_mat(path, x="X", f="F", fs=500.0)
    np.testing.assert_array_equal(rec.t, np.arange(n) / 500.0)
    np.testing.assert_array_equal(rec.f[:, 0], force)
    np.testing.assert_array_equal(rec.x[:, 0], disp)
    assert rec.dt == pytest.approx(1 / 500.0)


def test_read_mat_integer_data(tmp_path: Path) -> None:
    path = tmp_path / "adc.mat"
    scipy.io.savemat(path, {"f": np.arange(5, dtype=np.int16), "x": np.arange(5, dtype=np.int32)})
    rec = Record.read_mat(path, x="x", f="f", fs=1.0)
    assert rec.x.dtype == np.float64
    np.testing.assert_array_equal(rec.x[:, 0], np.arange(5.0))


@pytest.fixture
def mat_file(tmp_path: Path) -> Path:
    path = tmp_path / "bench.mat"
    t = np.arange(10) * 0.01
    x = np.vstack([np.arange(10.0), np.arange(10.0) ** 2]).T
    x_nan = x.copy()
    x_nan[6, 1] = np.nan
    t_bad = t.copy()
    t_bad[4] = t_bad[3]
    scipy.io.savemat(
        path,
        {
            "t": t,
            "t_bad": t_bad,
            "t_short": t[:8],
            "f": np.ones(10),
            "x": x,
            "x_nan": x_nan,
            "xT": x.T,
            "label": "not numeric",
            "z": np.ones(10) * (1 + 2j),
            "cell": np.array([[1.0], "a"], dtype=object),
        },
    )
    return path


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"x": "disp", "f": "f", "t": "t"}, r": variable 'disp' not found \(variables present: cell, f, label, t, t_bad, t_short, x, xT, x_nan, z\)$"),
        ({"x": ["x", "q"], "f": "f", "t": "t"}, r": variable 'q' not found \(variables present: cell,"),
        ({"x": "x", "f": "f", "t": "t_short"}, r": variables have different lengths: t_short 8 \(shape 1x8\), f 10 \(shape 1x10\), x 10 \(shape 10x2\)"),
        ({"x": "xT", "f": "f", "t": "t"}, r": variables have different lengths: t 10 \(shape 1x10\), f 10 \(shape 1x10\), xT 2 \(shape 2x10\); samples must run along the rows"),
        ({"x": "x", "f": "f"}, r": no time given: name the time variable \(t=NAME; duffid: --t-var NAME or --columns t=NAME,...\) or give the sampling rate \(fs; duffid: --fs HZ\)$"),
        ({"x": "x", "f": "f", "t": "t", "fs": 100.0}, r": give either the time variable t='t' or the sampling rate fs=100\.0, not both$"),
        ({"x": "x", "f": "f", "fs": -1.0}, r": sampling rate fs must be finite and > 0"),
        ({"x": "label", "f": "f", "t": "t"}, r", variable 'label': not a real numeric array \(dtype <U11\)$"),
        ({"x": "z", "f": "f", "t": "t"}, r", variable 'z': not a real numeric array \(dtype complex\)$"),
        ({"x": "cell", "f": "f", "t": "t"}, r", variable 'cell': not a real numeric array \(dtype object\)$"),
        ({"x": ["x"], "f": "f", "t": "t"}, r", variable 'x': expected a vector \(one column per name in x=\['x'\]\), got shape 10x2$"),
        ({"x": "x", "f": "f", "t": "x"}, r", variable 'x': expected a vector \(time stamps\), got shape 10x2$"),
        ({"x": "x_nan", "f": "f", "t": "t"}, r", row 7, variable 'x_nan' column 2: value 'nan' is not finite$"),
        ({"x": "x", "f": "f", "t": "t_bad"}, r", row 5, variable 't_bad': time 0\.03 does not increase \(previous 0\.03\)$"),
        ({"x": "f", "f": "x", "t": "t"}, r": 2 force columns but only 1 displacement columns"),
    ],
)
def test_read_mat_errors(mat_file: Path, kwargs: dict, match: str) -> None:
    with pytest.raises(RecordError, match="^" + re.escape(str(mat_file)) + match):
        Record.read_mat(mat_file, **kwargs)


def test_read_mat_v73_file(tmp_path: Path) -> None:
    # A MATLAB v7.3 file starts with a 128-byte MAT header announcing version 0x0200.
    path = tmp_path / "big.mat"
    text = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    header = text.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM"
    path.write_bytes(header + b"\x00" * 384)
    with pytest.raises(
        RecordError,
        match="^" + re.escape(str(path)) + r": the file is a MATLAB v7\.3 \(HDF5\) file.*'-v7'",
    ):
        Record.read_mat(path, x="x", f="f", fs=1.0)


def test_read_mat_not_a_mat_file(tmp_path: Path) -> None:
    path = write(tmp_path, "t,f,x\n0,0,0\n", name="oops.mat")
    with pytest.raises(RecordError, match="^" + re.escape(str(path)) + r": not a readable MATLAB \.mat file"):
        Record.read_mat(path, x="x", f="f", fs=1.0)
    missing = tmp_path / "missing.mat"
    with pytest.raises(RecordError, match="^" + re.escape(str(missing)) + ": cannot read file"):
        Record.read_mat(missing, x="x", f="f", fs=1.0)
