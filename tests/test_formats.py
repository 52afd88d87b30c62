"""The formats test rigs write (TDMS, UFF 58/58b, HDF5, MATLAB v7.3, WAV, SEP-005), each written by
its own library from one simulated record: every one is read into the same record as the CSV
and identifies the same parameters (API and CLI); every error names the file, channel, unit,
rate, start or length concerned."""
from __future__ import annotations

import json
import subprocess
import sys
import wave
from pathlib import Path

import numpy as np
import pytest
import scipy.io.wavfile

from duffid import Duffing1, Record, RecordError, Step, identify, measure, simulate
from duffid.cli import main
from duffid.data.formats import list_channels
from duffid.errors import InputError

nptdms = pytest.importorskip("nptdms")
pyuff = pytest.importorskip("pyuff")
h5py = pytest.importorskip("h5py")


@pytest.fixture(scope="module")
def record():
    return measure(simulate(Duffing1(), Step(10.0, 0.1), 1.0, 1e-3), pulses_per_cm=None, snr_db=50, seed=1)


# ---------------------------------------------------------------------- writers, each with its library
def write_tdms(path, record, *, force=None, disp=None, extra=()):
    """Group 'Data': force in N, displacement in mm, as LabVIEW waveforms (wf_increment, wf_start_offset)."""
    props = {"wf_increment": record.dt, "wf_start_offset": 0.0}
    channels = [nptdms.ChannelObject("Data", "force", record.f[:, 0], {**props, "unit_string": "N", **(force or {})}),
                nptdms.ChannelObject("Data", "disp", record.x[:, 0] * 1e3,
                                     {**props, "unit_string": "mm", **(disp or {})})]
    with nptdms.TdmsWriter(path) as writer:
        writer.write_segment([nptdms.GroupObject("Data"), *channels, *extra])
    return path


def _set58(record, data, name, binary, unit, spec, exponents, func_type=1):
    return {
        "type": 58, "binary": binary, "id1": name, "func_type": func_type, "rsp_node": 1, "rsp_dir": 1,
        "ref_node": 1, "ref_dir": 1, "ord_data_type": 4, "num_pts": len(data), "abscissa_spacing": 1,
        "abscissa_min": 0.0, "abscissa_inc": record.dt, "abscissa_spec_data_type": 17,
        "abscissa_axis_units_lab": "s", "ordinate_spec_data_type": spec, "ordinate_len_unit_exp": exponents[0],
        "ordinate_force_unit_exp": exponents[1], "ordinate_axis_units_lab": unit,
        "orddenom_spec_data_type": 0, "z_axis_spec_data_type": 0, "rsp_ent_name": "rig", "ref_ent_name": "rig",
        "data": np.asarray(data, dtype=float), "x": record.t}


def write_uff(path, record, *, binary=0, sets=None):
    """Data set 58 (or 58b): force 'load cell' in N, displacement 'laser' in m."""
    # pyuff 2.5.8's mode "overwrite" truncates a binary set's header (it reopens the file with "wb" for
    # the data): add to a new file instead
    Path(path).unlink(missing_ok=True)
    uff = pyuff.UFF(str(path))
    uff.write_sets(sets if sets is not None else [
        _set58(record, record.f[:, 0], "load cell", binary, "N", 13, (0, 1)),
        _set58(record, record.x[:, 0], "laser", binary, "m", 8, (1, 0))], mode="add")
    return path


def write_hdf5(path, record):
    """Group 'run' with a rate attribute; force in N, displacement in µm."""
    with h5py.File(path, "w") as fh:
        run = fh.create_group("run")
        run.attrs["fs"] = record.fs
        run.create_dataset("force", data=record.f[:, 0]).attrs["unit"] = "N"
        run.create_dataset("displacement", data=record.x[:, 0] * 1e6).attrs["unit"] = "µm"
    return path


def write_mat73(path, record):
    """A MATLAB v7.3 file as MATLAB writes it: HDF5 after a 512-byte header, column vectors stored
    transposed, a MATLAB_class on every variable."""
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name, data in (("t", record.t), ("f", record.f[:, 0]), ("x", record.x[:, 0])):
            fh.create_dataset(name, data=data.reshape(1, -1)).attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Fri Nov 27 06:00:00 2026 HDF5 schema 1.00 .")
    return path


#: The full scales of the WAV channels: force [N], displacement [m].
FULL_SCALE = (12.0, 0.02)


def write_wav(path, record, kind):
    """Channel 1 force, channel 2 displacement: float32, or integer PCM of full scale FULL_SCALE."""
    data = np.column_stack([record.f[:, 0], record.x[:, 0]])
    rate = int(round(record.fs))
    if kind == "float32":
        scipy.io.wavfile.write(path, rate, data.astype(np.float32))
        return path
    bits = int(kind[3:])
    counts = np.round(data / np.array(FULL_SCALE) * 2.0 ** (bits - 1)).astype(np.int64)
    if bits == 24:  # scipy writes no 24-bit PCM: the standard library's wave does
        frames = b"".join(int(v).to_bytes(3, "little", signed=True) for v in counts.reshape(-1))
        with wave.open(str(path), "wb") as fh:
            fh.setnchannels(2)
            fh.setsampwidth(3)
            fh.setframerate(rate)
            fh.writeframes(frames)
    else:
        scipy.io.wavfile.write(path, rate, counts.astype(np.int16 if bits == 16 else np.int32))
    return path


WAV_SCALE = {"f": FULL_SCALE[0], "x": FULL_SCALE[1]}
WAV_COLUMNS = {"f": 1, "x": 2}


@pytest.fixture(scope="module")
def files(tmp_path_factory, record):
    d = tmp_path_factory.mktemp("formats")
    out = {"csv": d / "rec.csv", "tdms": write_tdms(d / "rec.tdms", record), "uff": write_uff(d / "rec.uff", record),
           "uff58b": write_uff(d / "rec_b.unv", record, binary=1), "hdf5": write_hdf5(d / "rec.h5", record),
           "mat73": write_mat73(d / "rec.mat", record)}
    record.to_csv(out["csv"])
    for kind in ("float32", "pcm16", "pcm24", "pcm32"):
        out[f"wav-{kind}"] = write_wav(d / f"rec_{kind}.wav", record, kind)
    return out


#: How each file is read: Record.read keyword arguments, and the CLI flags saying the same.
READ = {
    "csv": ({}, []), "tdms": ({}, []), "uff": ({}, []), "uff58b": ({}, []), "hdf5": ({}, []),
    "mat73": ({"columns": {"t": "t", "f": "f", "x": "x"}}, ["--t-var", "t"]),
    "wav-float32": ({"columns": WAV_COLUMNS}, ["--columns", "f=1,x=2"]),
    **{f"wav-{k}": ({"columns": WAV_COLUMNS, "scale": WAV_SCALE}, ["--columns", "f=1,x=2", "--scale",
                                                                    f"f={FULL_SCALE[0]},x={FULL_SCALE[1]}"])
       for k in ("pcm16", "pcm24", "pcm32")},
}


def _quantisation(kind: str) -> np.ndarray:
    """Largest error of integer PCM [N, m]: half a step of the full scale (0 for float formats)."""
    if not kind.startswith("wav-pcm"):
        return np.zeros(2)
    return np.array(FULL_SCALE) / 2.0 ** (int(kind[7:]) - 1) / 2


@pytest.mark.parametrize("kind", sorted(READ))
def test_every_format_reads_the_record_of_the_csv(files, record, kind):
    got = Record.read(files[kind], **READ[kind][0])
    assert got.n_samples == record.n_samples and got.source == str(files[kind])
    np.testing.assert_allclose(got.t, record.t, rtol=0, atol=1e-12)
    q_f, q_x = _quantisation(kind)
    # float32 samples: 2^-24 relative; ASCII UFF: 12 significant digits; unit conversions: an ulp or two
    rtol = 6e-8 if kind == "wav-float32" else 1e-11 if kind == "uff" else 1e-15
    np.testing.assert_allclose(got.f, record.f, rtol=rtol, atol=q_f * (1 + 1e-9))
    np.testing.assert_allclose(got.x, record.x, rtol=rtol, atol=q_x * (1 + 1e-9))


@pytest.fixture(scope="module")
def reference(record):
    return identify(record, Duffing1())


def _tolerance(kind: str, reference, record) -> dict[str, float]:
    """How far a parameter from ``kind`` may be from the CSV's, relative.

    Float formats differ from the CSV by rounding (1e-12; float32 WAV 6e-8) and the identification
    moves by about that much. Integer PCM adds a uniform error of up to half a step: white noise of
    RMS q/sqrt(12), q the step. The record already carries measurement noise (50 dB: RMS 0.3 % of
    the signal) whose effect on each parameter is its stated standard error u; noise of RMS s_q on
    top moves a parameter by about u * s_q / s_noise. Allow 3 times that (measured: 16-bit moves the
    parameters by 1.3e-5 against a bound of 4e-5 to 3e-4; 24-bit by 5e-8 against 1e-6), and never
    less than 1e-8, the float64 formats' bound.
    """
    if not kind.startswith("wav-pcm"):
        return {name: 1e-7 if kind == "wav-float32" else 1e-8 for name in reference.parameters}
    q = 2 * _quantisation(kind)
    noise = 10 ** (-50 / 20) * np.array([np.std(record.f), np.std(record.x)])
    ratio = float(np.max(q / np.sqrt(12) / noise))
    u = reference.assessment.uncertainty
    return {name: max(1e-8, 3 * ratio * u[name]) for name in reference.parameters}


def _assert_same(parameters: dict[str, float], reference, record, kind: str) -> None:
    tol = _tolerance(kind, reference, record)
    for name, value in reference.parameters.items():
        got = parameters[name]
        if np.isnan(value):
            assert got is None or np.isnan(got), (kind, name, got)
        else:
            assert got == pytest.approx(value, rel=tol[name]), (kind, name)


@pytest.mark.parametrize("kind", sorted(READ))
def test_identify_from_every_format_gives_the_csv_parameters(files, reference, record, kind):
    result = identify(Record.read(files[kind], **READ[kind][0]), Duffing1())
    _assert_same(result.parameters, reference, record, kind)
    assert result.assessment.status == reference.assessment.status


@pytest.mark.parametrize("kind", sorted(READ))
def test_cli_identify_from_every_format_gives_the_csv_parameters(capsys, files, reference, record, kind):
    assert main(["identify", str(files[kind]), "--json", *READ[kind][1]]) == 0
    data = json.loads(capsys.readouterr().out)
    _assert_same({k: np.nan if v is None else v for k, v in data["raw_parameters"].items()}
                 if "raw_parameters" in data else data["parameters"], reference, record, kind)


def test_sep005_round_trip(record):
    channels = record.to_sep005()
    assert [c["name"] for c in channels] == ["f", "x"] and channels[1]["unit_str"] == "m"
    assert channels[0]["fs"] == pytest.approx(1000.0)
    back = Record.from_sep005(channels)
    np.testing.assert_array_equal(back.f, record.f)
    np.testing.assert_array_equal(back.x, record.x)
    np.testing.assert_allclose(back.t, record.t, rtol=0, atol=1e-12)
    shifted = Record(record.t + 2.0, record.f, record.x).to_sep005()
    assert "time" in shifted[0] and "fs" not in shifted[0]
    assert Record.from_sep005(shifted).t[0] == 2.0


def test_sep005_units_are_converted_and_selected_by_name(record):
    channels = [{"name": "acc", "data": record.x[:, 0], "unit_str": "g", "fs": 1000.0},
                {"name": "hammer", "data": record.f[:, 0] / 1e3, "unit_str": "kN", "fs": 1000.0},
                {"name": "laser", "data": record.x[:, 0] * 1e3, "unit_str": "mm", "fs": 1000.0}]
    got = Record.from_sep005(channels, columns={"f": "hammer", "x": "laser"})
    np.testing.assert_allclose(got.f, record.f, rtol=1e-15)
    np.testing.assert_allclose(got.x, record.x, rtol=1e-15)


@pytest.mark.parametrize("channels, message", [
    ([{"name": "f", "data": [1.0, 2.0], "unit_str": "N"}], r"channel 'f': neither 'fs' nor 'time' is given"),
    ([{"data": [1.0, 2.0]}], r"SEP-005 channels, channel 1: a SEP-005 channel is a dict with 'data', 'name'"),
    ({"name": "f"}, r"SEP-005 data are a list of channel dicts"),
    ([{"name": "f", "data": [1.0, 2.0, 3.0], "unit_str": "N", "time": [0.0, 1.0, 3.0]},
      {"name": "x", "data": [1.0, 2.0, 3.0], "unit_str": "m", "time": [0.0, 1.0, 3.0]}],
     r"channel 'f' time: uneven sampling"),
])
def test_sep005_errors(channels, message):
    with pytest.raises(RecordError, match=message):
        Record.from_sep005(channels)


# ---------------------------------------------------------------------- selection and units
def test_tdms_channels_and_units_are_listed(files, record):
    channels = list_channels(files["tdms"])
    assert [(c.name, c.unit, c.quantity, c.length) for c in channels] == [
        ("Data/force", "N", "force", record.n_samples), ("Data/disp", "mm", "displacement", record.n_samples)]
    assert channels[0].rate == pytest.approx(1000.0)


def test_selection_by_group_channel_and_dataset_path(files, record):
    a = Record.read(files["tdms"], columns={"f": "Data/force", "x": "Data/disp"})
    b = Record.read(files["hdf5"], columns={"f": "/run/force", "x": "run/displacement"})
    np.testing.assert_allclose(a.x, record.x, rtol=1e-12)
    np.testing.assert_allclose(b.x, record.x, rtol=1e-12)


def test_scale_overrides_the_unit(files, record):
    got = Record.read(files["tdms"], scale={"x": 1e-3 / 2})
    np.testing.assert_allclose(got.x, record.x / 2, rtol=1e-12)


def _tdms(tmp_path, record, name="r.tdms", **kwargs):
    return write_tdms(tmp_path / name, record, **kwargs)


@pytest.mark.parametrize("kwargs, columns, message", [
    ({"disp": {"wf_increment": 2e-3}}, None,
     r"r\.tdms: channel 'Data/force' is sampled at 1000 Hz but 'Data/disp' at 500 Hz; duffid never resamples"),
    ({"disp": {"wf_start_offset": 0.25}}, None,
     r"r\.tdms: channel 'Data/force' starts at 0 s but 'Data/disp' at 0\.25 s; duffid never shifts or clips"),
    ({"disp": {"unit_string": "furlong"}}, {"f": "Data/force", "x": "Data/disp"},
     r"r\.tdms, channel 'Data/disp': unit 'furlong' is not one duffid knows .*--scale x=FACTOR"),
    ({"disp": {"unit_string": "furlong"}}, None,
     r"r\.tdms: cannot tell which channel .*; unknown unit: 'Data/disp' in 'furlong'.*\[furlong, 1000 Hz"),
    ({"disp": {"unit_string": "kN"}}, {"f": "Data/force", "x": "Data/disp"},
     r"r\.tdms, channel 'Data/disp': unit 'kN' measures force, not the displacement that x needs \(in m\)"),
    ({"force": {"unit_string": "mV"}}, {"f": "Data/force", "x": "Data/disp"},
     r"channel 'Data/force': unit 'mV' is a sensor voltage; give its sensitivity as --scale f=FACTOR \(N per mV"),
    ({"disp": {"unit_string": "g"}}, None,
     r"channel 'Data/disp' measures acceleration \(g\): velocity \(v\) and acceleration \(a\) channels are "
     r"identified by duffid identify"),
    ({"disp": {"unit_string": "m/s"}}, {"f": "Data/force", "v": "Data/disp"},
     r"r\.tdms: v selects a velocity channel and no displacement: velocity \(v\) and acceleration"),
    ({}, {"f": "Data/force", "x": "Data/disp", "a": "Data/force"},
     r"r\.tdms: a selects an acceleration channel, which duffid would not use.*drop a from the selection"),
    ({}, {"f": "Data/force", "x": "Data/displacement"},
     r"r\.tdms: no channel 'Data/displacement' for x \(channels: 1: 'Data/force' \[N, 1000 Hz, 1001 samples\]; "
     r"2: 'Data/disp' \[mm, 1000 Hz, 1001 samples\]\)"),
    ({"disp": {"wf_start_time": np.datetime64("2026-11-29T10:00:00.0005")},
      "force": {"wf_start_time": np.datetime64("2026-11-29T10:00:00")}}, None,
     r"r\.tdms: channel 'Data/force' starts at 0 s but 'Data/disp' at 0\.0005 s; duffid never shifts or clips"),
    ({"force": {"unit_string": "V"}}, None,
     r"r\.tdms: channel 'Data/force' is in 'V' but 'Data/disp' is in 'mm', not a charge \(C\): a force in volts is a "
     r"sensor's output; give its sensitivity as --scale f=FACTOR \(N per V\)"),
    ({"disp": {"wf_increment": "0.5 ms"}}, None,
     r"r\.tdms, channel 'Data/disp': its wf_increment '0\.5 ms' is not a number of seconds"),
    ({"disp": {"wf_increment": -1e-3}}, None, r"r\.tdms, channel 'Data/disp': its wf_increment -0\.001 is not a positive step"),
    ({"force": {"wf_start_offset": "n/a"}}, None,
     r"r\.tdms, channel 'Data/force': its wf_start_offset 'n/a' is not a number of seconds"),
    ({}, {"f": "Data/force", "x": 3}, r"r\.tdms: no channel 3 for x: the file has 2"),
    ({}, {"f": "Data/force", "x": "Data/force"}, r"channel 'Data/force' is selected for two roles \(f, x\)"),
])
def test_tdms_errors_name_channels_units_rates_and_starts(tmp_path, record, kwargs, columns, message):
    path = _tdms(tmp_path, record, **kwargs)
    with pytest.raises(RecordError, match=message):
        Record.read(path, columns=columns)


def test_volts_are_the_circuits_source_only_with_a_charge(tmp_path, record):
    got = Record.read(_tdms(tmp_path, record, force={"unit_string": "V"}, disp={"unit_string": "mC"}))
    np.testing.assert_allclose(got.x, record.x, rtol=1e-12)  # mC -> C: the values written are x * 1e3
    path = tmp_path / "volts.csv"
    path.write_text("time,u,x\ns,V,m\n" + "".join(f"{t:.17g},{f:.17g},{x:.17g}\n" for t, f, x in
                                                zip(record.t, record.f[:, 0], record.x[:, 0])))
    columns = {"t": "time", "f": "u", "x": "x"}
    with pytest.raises(RecordError, match=r"volts\.csv: channel 'u' is in 'V' but 'x' is in 'm', not a charge"):
        Record.read(path, columns=columns)
    assert Record.read(path, columns=columns, scale={"f": 2.0}).f[3, 0] == 2.0 * record.f[3, 0]


def test_a_csv_header_names_its_roles_for_inspect_and_identify(tmp_path, record, capsys):
    path = tmp_path / "acc.csv"
    path.write_text("t,f,a\n" + "".join(f"{t:.17g},{f:.17g},{x:.17g}\n" for t, f, x in
                                         zip(record.t, record.f[:, 0], record.x[:, 0])))
    got = Record.read(path, motion=True)  # duffid identify's reading: the header's a
    assert got.motion == "a" and got.x[7, 0] == record.x[7, 0]
    with pytest.raises(RecordError, match=r"unknown column 'a'"):
        Record.read(path)  # a displacement's user
    assert main(["inspect", str(path)]) == 0
    assert "without --columns: t=t, f=f, a=a (an acceleration: duffid identify only)" in capsys.readouterr().out
    named = tmp_path / "named.csv"
    named.write_text(path.read_text().replace("t,f,a", "time,force,acc", 1))
    assert main(["inspect", str(named)]) == 0
    assert "without --columns: a CSV file is read by its header t,f,x" in capsys.readouterr().out


def test_a_datasets_own_rate_overrides_its_files_step(tmp_path, record):
    path = tmp_path / "override.h5"
    with h5py.File(path, "w") as fh:
        fh.attrs["dt"] = 2 * record.dt  # the file's default, which these datasets override
        for name, data, unit in (("force", record.f[:, 0], "N"), ("disp", record.x[:, 0], "m")):
            fh.create_dataset(name, data=data).attrs.update({"unit": unit, "fs": 1 / record.dt})
    assert Record.read(path).dt == pytest.approx(record.dt, rel=1e-12)


def test_a_mat_file_is_read_by_its_variable_names_as_inspect_lists_them(tmp_path, record, capsys):
    path = tmp_path / "rig.mat"
    scipy.io.savemat(path, {"t": record.t[:, None], "f": record.f, "x": record.x})
    assert main(["inspect", str(path)]) == 0
    assert "without --columns: t=t, f=f, x=x" in capsys.readouterr().out
    assert main(["identify", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["samples"] == record.n_samples


def test_a_gap_is_named_by_channel_and_sample(tmp_path, record):
    path = tmp_path / "gap.h5"
    x = record.x[:, 0].copy()
    x[[41, 99]] = np.nan
    with h5py.File(path, "w") as fh:
        fh.attrs["fs"] = 1 / record.dt
        fh.create_dataset("force", data=record.f[:, 0]).attrs["unit"] = "N"
        fh.create_dataset("run/disp", data=x).attrs["unit"] = "m"
    with pytest.raises(RecordError, match=r"gap\.h5, channel 'run/disp': sample 42 of 1001 is nan \(2 such samples\); "
                                          r"duffid never drops or fills samples"):
        Record.read(path)


def test_channels_that_started_together_by_their_time_stamps_are_read(tmp_path, record):
    stamp = {"wf_start_time": np.datetime64("2026-11-29T10:00:00")}
    got = Record.read(_tdms(tmp_path, record, force=stamp, disp=stamp))
    np.testing.assert_allclose(got.x, record.x, rtol=1e-12)
    assert got.t[0] == 0.0


def test_a_unit_in_the_channel_name_is_the_channel_unit(tmp_path, record):
    """Channels named 'force (kN)' and 'disp [mm]' without unit metadata: converted (TDMS, HDF5),
    or refused until scaled (CSV), never read as SI."""
    props = {"wf_increment": record.dt}
    path = tmp_path / "named.tdms"
    with nptdms.TdmsWriter(path) as writer:
        writer.write_segment([nptdms.GroupObject("Data"),
                              nptdms.ChannelObject("Data", "force (kN)", record.f[:, 0] / 1e3, props),
                              nptdms.ChannelObject("Data", "disp [mm]", record.x[:, 0] * 1e3, props)])
    got = Record.read(path)
    np.testing.assert_allclose(got.f, record.f, rtol=1e-12)
    np.testing.assert_allclose(got.x, record.x, rtol=1e-12)
    assert [c.unit for c in list_channels(path)] == ["kN", "mm"]
    path = tmp_path / "named.h5"
    with h5py.File(path, "w") as fh:
        fh.attrs["dt"] = record.dt
        fh.create_dataset("force (N)", data=record.f[:, 0])
        fh.create_dataset("disp (um)", data=record.x[:, 0] * 1e6)
        fh.create_dataset("accel (X)", data=record.x[:, 0])  # an axis label, not a unit
    assert {c.name: c.unit for c in list_channels(path)} == {"force (N)": "N", "disp (um)": "um",
                                                           "accel (X)": None}
    np.testing.assert_allclose(Record.read(path, columns={"f": "force (N)", "x": "disp (um)"}).x, record.x,
                               rtol=1e-12)
    path = tmp_path / "named.csv"
    np.savetxt(path, np.column_stack([record.t, record.f[:, 0] / 1e3, record.x[:, 0]]), delimiter=",",
               header="time (s),force (kN),disp (m)", comments="")
    columns = {"t": "time (s)", "f": "force (kN)", "x": "disp (m)"}
    with pytest.raises(RecordError, match=r"column 'force \(kN\)' \(f\) is in 'kN' \(in its name\): duffid needs "
                                          r"SI units \(N or V\); scale it into N \(multiply f by 1000\)"):
        Record.read(path, columns=columns)
    np.testing.assert_allclose(Record.read(path, columns=columns, scale={"f": 1e3}).f, record.f, rtol=1e-9)


def test_hdf5_packed_datasets_need_a_scale_and_latin1_units_are_read(tmp_path, record):
    path = tmp_path / "packed.h5"
    counts = np.round(record.x[:, 0] / 0.05 * 32767).astype(np.int16)
    with h5py.File(path, "w") as fh:
        fh.attrs["fs"] = 1 / record.dt
        fh.create_dataset("force", data=record.f[:, 0]).attrs["unit"] = "N"
        fh.create_dataset("disp", data=counts).attrs.update({"unit": "m", "scale_factor": 0.05 / 32767})
        fh.create_dataset("shifted", data=counts).attrs.update({"unit": "m", "scale_factor": 1.0, "add_offset": 0.5})
    with pytest.raises(RecordError, match=r"packed\.h5, channel 'disp': is stored packed \(scale_factor 1\.52.*\), "
                                          r"which duffid does not apply: give the SI value of one stored unit; give "
                                          r"--scale x=FACTOR"):
        Record.read(path, columns={"f": "force", "x": "disp"})
    got = Record.read(path, columns={"f": "force", "x": "disp"}, scale={"x": 0.05 / 32767})
    np.testing.assert_allclose(got.x[:, 0], counts * (0.05 / 32767), rtol=1e-12)
    with pytest.raises(RecordError, match=r"channel 'shifted': is stored packed \(scale_factor 1\.0, add_offset 0\.5\); "
                                          r"duffid does not unpack values"):
        Record.read(path, columns={"f": "force", "x": "shifted"}, scale={"x": 1.0})
    path = tmp_path / "latin1.h5"
    with h5py.File(path, "w") as fh:
        fh.attrs["fs"] = 1 / record.dt
        fh.create_dataset("force", data=record.f[:, 0]).attrs["unit"] = np.bytes_(b"N")
        fh.create_dataset("disp", data=record.x[:, 0] * 1e6).attrs["unit"] = np.bytes_(b"\xb5m")
    np.testing.assert_allclose(Record.read(path).x, record.x, rtol=1e-12)


def test_a_third_channel_needs_a_selection_and_the_error_lists_units(tmp_path, record):
    extra = [nptdms.ChannelObject("Data", "temperature", np.full(record.n_samples, 21.5),
                                  {"unit_string": "degC", "wf_increment": record.dt})]
    path = _tdms(tmp_path, record, extra=extra)
    with pytest.raises(RecordError, match=r"cannot tell which channel is the force and which the displacement.*"
                                          r"3: 'Data/temperature' \[degC, 1000 Hz, 1001 samples\]"):
        Record.read(path)
    got = Record.read(path, columns={"f": "Data/force", "x": "Data/disp"})
    np.testing.assert_allclose(got.x, record.x, rtol=1e-12)


def test_hdf5_lengths_and_attributes(tmp_path, record):
    path = tmp_path / "short.h5"
    with h5py.File(path, "w") as fh:
        fh.attrs["dt"] = record.dt
        fh.create_dataset("force", data=record.f[:, 0]).attrs["unit"] = "N"
        fh.create_dataset("disp", data=record.x[:-1, 0]).attrs["unit"] = "m"
    with pytest.raises(RecordError, match=r"short\.h5: channel 'force' has 1001 samples but 'disp' has 1000; "
                                          r"duffid never clips"):
        Record.read(path)
    path = tmp_path / "norate.h5"
    with h5py.File(path, "w") as fh:
        fh.create_dataset("force", data=record.f[:, 0]).attrs["unit"] = "N"
        fh.create_dataset("disp", data=record.x[:, 0]).attrs["unit"] = "m"
    with pytest.raises(RecordError, match=r"norate\.h5: no sampling rate: channels 'force', 'disp' carry none; "
                                          r"give the sampling rate \(--fs\) or a time channel \(t=\)"):
        Record.read(path)
    assert Record.read(path, fs=1000.0).x[5, 0] == record.x[5, 0]


def test_hdf5_time_dataset_selected_as_t(tmp_path, record):
    path = tmp_path / "timed.h5"
    with h5py.File(path, "w") as fh:
        fh.create_dataset("t", data=record.t).attrs["unit"] = "s"
        fh.create_dataset("f", data=record.f[:, 0]).attrs["unit"] = "N"
        fh.create_dataset("x", data=record.x[:, 0]).attrs["unit"] = "m"
    assert Record.read(path) == record  # a lone time channel plays t when the others carry no rate
    assert Record.read(path, columns={"t": "t", "f": "f", "x": "x"}) == record


def test_wav_integer_pcm_requires_a_scale(files):
    with pytest.raises(RecordError, match=r"rec_pcm24\.wav, channel '1': integer PCM, in fractions of full scale: "
                                          r"its SI value at full scale is required; give --scale f=FACTOR"):
        Record.read(files["wav-pcm24"], columns=WAV_COLUMNS)
    with pytest.raises(RecordError, match=r"rec_pcm16\.wav: cannot tell which channel is the force"):
        Record.read(files["wav-pcm16"])


def test_uff_function_type_and_exponents_are_checked(tmp_path, record):
    frf = _set58(record, record.f[:, 0], "H1", 0, "N", 13, (0, 1), func_type=4)
    laser = _set58(record, record.x[:, 0], "laser", 0, "m", 8, (1, 0))
    path = write_uff(tmp_path / "frf.uff", record, sets=[frf, laser])
    with pytest.raises(RecordError, match=r"frf\.uff, channel 'H1': data set 1 is a frequency response function "
                                          r"\(function type 4\); duffid reads time responses \(type 1\)"):
        Record.read(path, columns={"f": "H1", "x": "laser"})
    bad = _set58(record, record.x[:, 0], "laser", 0, "m", 8, (0, 1))
    cell = _set58(record, record.f[:, 0], "load cell", 0, "N", 13, (0, 1))
    path = write_uff(tmp_path / "exp.uff", record, sets=[cell, bad])
    with pytest.raises(RecordError, match=r"exp\.uff, channel 'laser': data set 2 names the unit 'm' \(displacement\) "
                                          r"but its ordinate's length and force exponents are 0 and 1"):
        Record.read(path, columns={"f": 1, "x": 2})


def test_format_from_extension_or_argument(tmp_path, files, record):
    odd = tmp_path / "rec.bin"
    odd.write_bytes(Path(files["tdms"]).read_bytes())
    with pytest.raises(RecordError, match=r"rec\.bin: cannot tell the format from the extension '\.bin'; give it "
                                          r"\(--format\): csv \(\.csv"):
        Record.read(odd)
    np.testing.assert_allclose(Record.read(odd, format="tdms").x, record.x, rtol=1e-12)
    with pytest.raises(InputError, match=r"unknown file format 'xls'"):
        Record.read(odd, format="xls")
    with pytest.raises(RecordError, match=r"rec\.bin: not a readable HDF5 file"):
        Record.read(odd, format="hdf5")


def test_read_mat_reads_v73_files(files, record):
    got = Record.read_mat(files["mat73"], x="x", f="f", t="t")
    assert got == record


def test_missing_reader_library_is_one_line(files):
    code = ("import sys; sys.modules['nptdms'] = None\n"
            "from duffid.cli import main\n"
            f"sys.exit(main(['identify', {str(files['tdms'])!r}]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 2
    assert done.stderr.strip() == ("duffid identify: error: reading TDMS files needs npTDMS, an optional dependency: "
                                   "pip install 'duffid[files]'")


# ---------------------------------------------------------------------- CLI
def test_inspect_lists_channels_units_rates_lengths(capsys, files):
    assert main(["inspect", str(files["tdms"])]) == 0
    out = capsys.readouterr().out
    assert "2 channels" in out and "Data/force" in out and "mm" in out and "displacement" in out
    assert "1000" in out and "without --columns: f=Data/force, x=Data/disp" in out
    assert main(["inspect", str(files["wav-pcm16"]), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert [c["name"] for c in data["channels"]] == ["1", "2"] and data["default_columns"] == {}
    assert "integer PCM" in data["channels"][0]["note"]
    assert main(["inspect", str(files["uff"])]) == 0
    assert "load cell" in capsys.readouterr().out
    assert main(["inspect", str(files["wav-pcm24"])]) == 0
    assert "PCM 24-bit" in capsys.readouterr().out


def test_cli_errors_are_one_line_in_the_cli_voice(capsys, files, tmp_path):
    assert main(["identify", str(files["wav-pcm16"]), "--columns", "f=1,x=2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("duffid identify: error: ") and "give --scale f=FACTOR" in err and err.count("\n") == 1
    assert main(["identify", str(files["tdms"]), "--columns", "f=Data/force,a=Data/disp"]) == 2
    assert "acceleration" in capsys.readouterr().err
    assert main(["inspect", str(tmp_path / "none.tdms")]) == 2
    assert "none.tdms: no such file" in capsys.readouterr().err
    odd = tmp_path / "rec.dat2"
    odd.write_bytes(Path(files["hdf5"]).read_bytes())
    assert main(["identify", str(odd), "--format", "hdf5", "--json"]) == 0
    capsys.readouterr()


# ---------------------------------------------------------------------- large files
_MEMORY = """
import sys
from duffid import Record
def status(key):  # this process's own memory: ru_maxrss would inherit the parent's peak across exec
    for line in open('/proc/self/status'):
        if line.startswith(key):
            return int(line.split()[1]) * 1024
before = status('VmRSS')
record = Record.read(sys.argv[1])
print(record.n_samples, status('VmHWM') - before)
"""


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["tdms", "hdf5"])
def test_a_10m_sample_file_needs_at_most_three_times_its_data(tmp_path, kind):
    n = 10_000_000
    rng = np.random.default_rng(1)
    path = tmp_path / f"big.{'tdms' if kind == 'tdms' else 'h5'}"
    f = rng.standard_normal(n)
    x = rng.standard_normal(n) * 1e-3
    if kind == "tdms":
        props = {"wf_increment": 1e-4}
        with nptdms.TdmsWriter(path) as writer:
            writer.write_segment([nptdms.ChannelObject("g", "force", f, {**props, "unit_string": "N"}),
                                  nptdms.ChannelObject("g", "disp", x, {**props, "unit_string": "m"})])
    else:
        with h5py.File(path, "w") as fh:
            fh.attrs["fs"] = 1e4
            fh.create_dataset("force", data=f).attrs["unit"] = "N"
            fh.create_dataset("disp", data=x).attrs["unit"] = "m"
    del f, x
    data_size = 2 * n * 8
    done = subprocess.run([sys.executable, "-c", _MEMORY, str(path)], capture_output=True, text=True, check=True)
    samples, used = (int(v) for v in done.stdout.split())
    assert samples == n
    assert used <= 3 * data_size, f"reading took {used / 1e6:.0f} MB for {data_size / 1e6:.0f} MB of data"


# ---------------------------------------------------------------------- more selections and checks
def test_csv_refuses_velocity_and_acceleration_roles(files):
    with pytest.raises(RecordError, match=r"rec\.csv: a selects an acceleration channel and no displacement: "
                                          r"velocity \(v\) and acceleration \(a\) channels are identified by "
                                          r"duffid identify"):
        Record.read(files["csv"], columns={"t": "t", "f": "f", "a": "x"})


def test_motion_records_read_velocities_and_accelerations_in_si(tmp_path, record, files, capsys):
    """With motion=True (duffid identify), v= or a= take the displacement's place; units convert
    (g to m/s^2), the record says what it measures, and a displacement's user refuses it."""
    path = _tdms(tmp_path, record, disp={"unit_string": "g"})
    got = Record.read(path, columns={"f": "Data/force", "a": "Data/disp"}, motion=True)
    assert got.motion == "a" and got.column_names == ["t", "f", "a"]
    np.testing.assert_allclose(got.x, record.x * 1e3 * 9.80665, rtol=1e-12)  # the helper writes mm
    assert Record.read(path, motion=True).motion == "a"  # one force, one acceleration: found by unit
    assert main(["inspect", str(path)]) == 0
    assert "without --columns: f=Data/force, a=Data/disp (an acceleration: duffid identify only)" in \
        capsys.readouterr().out
    assert got.slice(0.1, 0.5).motion == "a" and got.scaled({"a": 2.0}).motion == "a"
    with pytest.raises(RecordError, match=r"the record measures accelerations \(a\), not displacements: the "
                                          r"nonlinearity index needs a displacement"):
        got.require_displacement("the nonlinearity index")
    csv = Record.read(files["csv"], columns={"t": "t", "f": "f", "v": "x"}, motion=True)
    assert csv.motion == "v"
    with pytest.raises(RecordError, match=r"mixes displacements and velocities; give one kind of motion"):
        Record.read(files["csv"], columns={"t": "t", "f": "f", "x": "x", "v": "x"}, motion=True)
    with pytest.raises(Exception, match="motion must be one of x, v, a"):
        Record(record.t, record.f, record.x, motion="j")


def test_scale_reads_a_unit_duffid_does_not_know(tmp_path, record):
    path = _tdms(tmp_path, record, disp={"unit_string": "furlong"})
    got = Record.read(path, columns={"f": "Data/force", "x": "Data/disp"}, scale={"x": 1e-3})
    np.testing.assert_allclose(got.x, record.x, rtol=1e-12)


def test_a_time_channel_that_disagrees_with_the_rate_is_refused(tmp_path, record):
    extra = [nptdms.ChannelObject("Data", "time", record.t * 2, {"unit_string": "s"})]
    path = _tdms(tmp_path, record, extra=extra)
    with pytest.raises(RecordError, match=r"the time channel 'Data/time' steps by 0\.002 s but channel 'Data/force' "
                                          r"is sampled at 1000 Hz"):
        Record.read(path, columns={"t": "Data/time", "f": "Data/force", "x": "Data/disp"})
    got = Record.read(path)  # the waveforms carry their rate: the time channel is not needed
    np.testing.assert_allclose(got.t, record.t, atol=1e-12)


def test_readers_hand_over_their_arrays_without_a_copy(record):
    t = np.array(record.t)
    t.setflags(write=False)
    kept = Record(t, record.f, record.x)
    assert kept.t is t  # read-only and owned: adopted
    writable = np.array(record.t)
    assert Record(writable, record.f, record.x).t is not writable  # the caller could change it: copied


def test_cli_nonlinearity_reads_every_format(capsys, files):
    assert main(["nonlinearity", str(files["hdf5"]), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["source"] == str(files["hdf5"])


@pytest.mark.parametrize("unit, quantity, factor", [
    ("g", "acceleration", 9.80665), ("mm/s^2", "acceleration", 1e-3), ("mm/s²", "acceleration", 1e-3),
    ("m/s2", "acceleration", 1.0), ("m/s/s", "acceleration", 1.0), ("mm", "displacement", 1e-3),
    ("µm", "displacement", 1e-6), ("μm", "displacement", 1e-6), ("um", "displacement", 1e-6),
    ("kN", "force", 1e3), ("N", "force", 1.0), ("mV", "voltage", 1e-3), ("V", "voltage", 1.0),
    ("mm/s", "velocity", 1e-3), (" m ", "displacement", 1.0),
])
def test_the_unit_table(unit, quantity, factor):
    from duffid.data.units import lookup

    found = lookup(unit)
    assert found is not None and found.quantity == quantity and found.factor == factor


def test_units_are_checked_against_the_role():
    from duffid.data.units import si_factor

    assert si_factor("V", "f", "here") == 1.0  # the circuit's source voltage, as in CSV files
    assert si_factor("mV", "f", "here", 0.5) == 0.5  # a load cell's 2 mV/N
    with pytest.raises(RecordError, match=r"here: unit 'V' is a sensor voltage; give its sensitivity as --scale "
                                          r"x=FACTOR \(m per V, i\.e\. 1 / the sensitivity in V/m\)"):
        si_factor("V", "x", "here")
    assert si_factor(None, "x", "here") == 1.0 and si_factor("", "x", "here") == 1.0


def test_an_upper_case_g_is_standard_gravity():
    """Accelerometer software writes ``G`` as often as ``g`` (it was refused as unknown)."""
    from duffid.data.units import STANDARD_GRAVITY, lookup

    assert lookup("G") == lookup("g") and lookup("G").factor == STANDARD_GRAVITY
