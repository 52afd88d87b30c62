"""Readers refuse what they cannot read right (or read it right): a UFF units set 164, a UFF
abscissa in ms or uneven, a complex MATLAB variable, a WAV file shorter than its header; each file
written by its format's own library (or its bytes)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io
import scipy.io.wavfile

from duffid import Record, RecordError
from duffid.data.formats import list_channels

pyuff = pytest.importorskip("pyuff")
h5py = pytest.importorskip("h5py")

FS = 1000.0
N = 200
T = np.arange(N) / FS
F = np.sin(2 * np.pi * 10 * T)
X = 1e-3 * np.cos(2 * np.pi * 10 * T)


def _set58(name: str, data: np.ndarray, *, spec: int, exponents: tuple[int, int], unit: str = "NONE",
           x: np.ndarray = T, abscissa_unit: str = "s", **extra) -> dict:
    extra = {"abscissa_spacing": 1, **extra}
    return pyuff.prepare_58(
        binary=0, id1=name, func_type=1, rsp_node=1, rsp_dir=3, ref_node=1, ref_dir=3, data=np.asarray(data, float),
        x=x, abscissa_spec_data_type=17, abscissa_axis_units_lab=abscissa_unit,
        abscissa_len_unit_exp=0, abscissa_force_unit_exp=0, orddenom_spec_data_type=0,
        ordinate_spec_data_type=spec, ordinate_len_unit_exp=exponents[0], ordinate_force_unit_exp=exponents[1],
        ordinate_axis_units_lab=unit, **extra)


def _uff(path: Path, sets: list[dict]) -> str:
    pyuff.UFF(str(path)).write_sets(sets, mode="add")
    return str(path)


def _units164(code: int, length: float, force: float) -> dict:
    return pyuff.prepare_164(units_code=code, units_description="units", temp_mode=1, length=length, force=force,
                             temp=1.0, temp_offset=273.15)


@pytest.mark.parametrize("factor", [1e3, 1e-3])  # the format divides by it; some writers multiply
def test_uff_units_set_164_in_mm_and_mN_is_applied_to_unlabelled_sets(tmp_path, factor):
    path = _uff(tmp_path / "mm.uff", [_units164(5, factor, factor),
                                      _set58("force", F * 1e3, spec=13, exponents=(0, 1)),
                                      _set58("disp", X * 1e3, spec=8, exponents=(1, 0))])
    assert [c.unit for c in list_channels(path)] == ["mN", "mm"]
    got = Record.read(path)
    np.testing.assert_allclose(got.f[:, 0], F, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got.x[:, 0], X, rtol=1e-9, atol=1e-15)


def test_uff_units_set_164_that_contradicts_its_code_or_is_user_defined_is_refused(tmp_path):
    path = _uff(tmp_path / "odd.uff", [_units164(5, 1.0, 1.0), _set58("force", F, spec=13, exponents=(0, 1)),
                                       _set58("disp", X, spec=8, exponents=(1, 0))])
    with pytest.raises(RecordError, match=r"odd\.uff, channel 'force': data set 1 names no unit and the units data "
                                          r"set 164 \(units code 5 .*contradicts itself \(MM is mm and mN\)"):
        Record.read(path)
    path = _uff(tmp_path / "user.uff", [_units164(9, 2.0, 1.0), _set58("force", F, spec=13, exponents=(0, 1)),
                                        _set58("disp", X, spec=8, exponents=(1, 0))])
    with pytest.raises(RecordError, match=r"user\.uff, channel 'force': .*units code 9.* not a system duffid knows"):
        Record.read(path)


def test_uff_units_set_164_in_inches_asks_for_a_scale(tmp_path):
    path = _uff(tmp_path / "in.uff", [_units164(7, 1 / 0.0254, 1 / 4.4482216152605),
                                      _set58("force", F, spec=13, exponents=(0, 1)),
                                      _set58("disp", X, spec=8, exponents=(1, 0))])
    with pytest.raises(RecordError, match=r"in\.uff, channel 'force': unit 'lbf' is not one duffid knows.*--scale f="):
        Record.read(path, columns={"f": "force", "x": "disp"})


def test_uff_abscissa_in_ms_gives_the_rate_in_hz(tmp_path):
    path = _uff(tmp_path / "ms.uff", [_set58("force", F, spec=13, exponents=(0, 1), unit="N", x=T * 1e3,
                                             abscissa_unit="ms"),
                                      _set58("disp", X, spec=8, exponents=(1, 0), unit="m", x=T * 1e3,
                                             abscissa_unit="ms")])
    assert Record.read(path).fs == pytest.approx(FS, rel=1e-6)


def test_uff_abscissa_in_no_time_unit_is_refused(tmp_path):
    path = _uff(tmp_path / "hz.uff", [_set58("force", F, spec=13, exponents=(0, 1), unit="N", abscissa_unit="Hz"),
                                      _set58("disp", X, spec=8, exponents=(1, 0), unit="m", abscissa_unit="Hz")])
    with pytest.raises(RecordError, match=r"hz\.uff, channel 'force': data set 1 has an abscissa in 'Hz', not a time "
                                          r"unit"):
        Record.read(path)


def test_uff_uneven_abscissa_is_named(tmp_path):
    path = _uff(tmp_path / "uneven.uff", [
        _set58("force", F, spec=13, exponents=(0, 1), unit="N", abscissa_spacing=0),
        _set58("disp", X, spec=8, exponents=(1, 0), unit="m", abscissa_spacing=0)])
    with pytest.raises(RecordError, match=r"uneven\.uff, channel 'force': data set 1 has an uneven abscissa"):
        Record.read(path)


@pytest.mark.parametrize("compress", [False, True])
def test_matlab_complex_variable_is_refused(tmp_path, compress):
    path = str(tmp_path / "c.mat")
    scipy.io.savemat(path, {"t": T.reshape(-1, 1), "f": F.reshape(-1, 1), "x": (X + 1e-3j).reshape(-1, 1)},
                     do_compression=compress)
    with pytest.raises(RecordError, match=r"c\.mat, variable 'x': holds complex values"):
        Record.read(path, columns={"t": "t", "f": "f", "x": "x"})


def test_matlab_v73_complex_variable_is_listed_and_refused(tmp_path):
    path = str(tmp_path / "c73.mat")
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name, value in {"t": T, "f": F, "x": X + 1e-3j}.items():
            if np.iscomplexobj(value):
                value = np.array(list(zip(value.real, value.imag)), dtype=[("real", "f8"), ("imag", "f8")])
            fh.create_dataset(name, data=value.reshape(1, -1)).attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file".ljust(116) + b"\0" * 8 + b"\x00\x02IM")
    assert "complex" in {c.name: c.problem for c in list_channels(path)}["x"]
    with pytest.raises(RecordError, match=r"c73\.mat, channel 'x': holds complex values"):
        Record.read(path, columns={"t": "t", "f": "f", "x": "x"})


def test_wav_shorter_than_its_header_is_refused(tmp_path):
    whole, cut = tmp_path / "whole.wav", tmp_path / "cut.wav"
    scipy.io.wavfile.write(whole, int(FS), np.column_stack([F, X]).astype(np.float32))
    data = whole.read_bytes()
    cut.write_bytes(data[:len(data) - 50 * 8])  # 50 of the 200 frames (2 x float32) missing
    with pytest.raises(RecordError, match=r"cut\.wav: the WAV file is cut short: its header declares 200 frames, "
                                          r"the file holds 150"):
        Record.read(str(cut), columns={"f": "1", "x": "2"})


def test_uff_unlabelled_set_of_no_data_type_in_a_mm_file_is_refused(tmp_path):
    path = _uff(tmp_path / "general.uff", [_units164(5, 1e3, 1e3), _set58("force", F * 1e3, spec=0, exponents=(0, 1)),
                                           _set58("disp", X * 1e3, spec=8, exponents=(1, 0))])
    with pytest.raises(RecordError, match=r"general\.uff, channel 'force': data set 1 names no unit and is of "
                                          r"specific data type 0, of no unit, in a file whose units data set 164 is "
                                          r"in mm and mN"):
        Record.read(path, columns={"f": "force", "x": "disp"})
