"""The C build helper's platforms: names, folders, what a missing cross compiler does."""
from __future__ import annotations

import dataclasses
import zipfile
from pathlib import Path

import pytest

from duffid import cbuild
from duffid.cbuild import HOST_PLATFORM, PLATFORMS, fmu_binary_path, resolve_platforms
from duffid.cli import main
from duffid.errors import CompilerNotFoundError, InputError


def test_folders_follow_the_fmi_standard():
    assert fmu_binary_path("X", 2, PLATFORMS["win64"]) == "binaries/win64/X.dll"
    assert fmu_binary_path("X", 3, PLATFORMS["win64"]) == "binaries/x86_64-windows/X.dll"
    assert fmu_binary_path("X", 2, PLATFORMS["linux64"]) == "binaries/linux64/X.so"
    assert fmu_binary_path("X", 3, PLATFORMS["linux64"]) == "binaries/x86_64-linux/X.so"
    assert fmu_binary_path("X", 3, PLATFORMS["aarch64-linux"]) == "binaries/aarch64-linux/X.so"
    assert fmu_binary_path("X", 2) == fmu_binary_path("X", 2, HOST_PLATFORM)


def test_an_unknown_platform_is_named():
    with pytest.raises(InputError, match="--platforms: unknown platform arm32; choose from linux64, win64"):
        resolve_platforms(["linux64", "arm32"])


def test_a_missing_cross_compiler_is_skipped_with_the_package_to_install(monkeypatch):
    missing = dataclasses.replace(PLATFORMS["win64"], compiler="no-such-mingw-gcc")
    monkeypatch.setitem(PLATFORMS, "win64", missing)
    chosen, skipped = resolve_platforms(["all"])
    assert chosen[0] == HOST_PLATFORM and missing not in chosen
    assert skipped == ["skipping win64 binaries: no-such-mingw-gcc not found or cannot compile "
                       "(install the Debian package gcc-mingw-w64-x86-64)"]
    with pytest.raises(CompilerNotFoundError, match="gcc-mingw-w64-x86-64"):
        cbuild.compile_shared_library([], "x.dll", platform=missing)


def test_build_fmus_says_what_it_skips(monkeypatch, tmp_path, capsys):
    missing = dataclasses.replace(PLATFORMS["aarch64-linux"], compiler="no-such-aarch64-gcc")
    monkeypatch.setitem(PLATFORMS, "aarch64-linux", missing)
    assert main(["build-fmus", "--out", str(tmp_path), "--plant", "Oscillator1DOF",
                 "--platforms", f"{HOST_PLATFORM.name},aarch64-linux"]) == 0
    captured = capsys.readouterr()
    assert "duffid build-fmus: skipping aarch64-linux binaries: no-such-aarch64-gcc" in captured.err
    with zipfile.ZipFile(tmp_path / "Oscillator1DOF.fmu") as z:
        folders = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/")}
    assert folders == {HOST_PLATFORM.fmi2}
    assert main(["build-fmus", "--out", str(tmp_path), "--platforms", "vax"]) == 2
    assert "--platforms: unknown platform vax" in capsys.readouterr().err



def test_build_fmus_builds_the_chain_estimators_asked_for(tmp_path, capsys):
    import fmpy
    import fmpy.validation

    assert main(["build-fmus", "--out", str(tmp_path), "--plant", "Oscillator1DOF", "--chain", "2",
                 "--orders", "1,2,3", "--platforms", HOST_PLATFORM.name]) == 0
    written = capsys.readouterr().out.split()
    assert [Path(p).name for p in written] == ["Oscillator1DOF.fmu", "Oscillator1DOF_fmi3.fmu",
                                               "ChainEstimator2.fmu", "ChainEstimator2_fmi3.fmu"]
    for name in ("ChainEstimator2.fmu", "ChainEstimator2_fmi3.fmu"):
        assert fmpy.validation.validate_fmu(str(tmp_path / name)) == []
        units = {v.name: v.unit for v in fmpy.read_model_description(str(tmp_path / name)).modelVariables}
        assert (units["x2"], units["f1"], units["k1_2_hat"], units["m2_hat"]) == ("m", "N", "N/m2", "kg")
    assert main(["build-fmus", "--out", str(tmp_path / "none"), "--chain", "2", "--orders", "1,x"]) == 2
    assert "--orders 1,x: give stiffness orders as integers" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()                     # refused before anything was built

@pytest.mark.skipif(cbuild.platform_compiler(PLATFORMS["win64"]) is None,
                    reason="needs the Debian package gcc-mingw-w64-x86-64")
def test_windows_binaries_are_dlls_with_the_c_runtime_linked_in(tmp_path):
    """The flags of the win64 platform give a PE DLL (the platform tests load it under wine)."""
    source = tmp_path / "f.c"
    source.write_text("#include <math.h>\n__declspec(dllexport) double f(double x) { return sin(x); }\n")
    out = tmp_path / "f.dll"
    cbuild.compile_shared_library([source], out, flags=("-shared",), platform=PLATFORMS["win64"])
    assert out.read_bytes()[:2] == b"MZ"


@pytest.mark.skipif(cbuild.platform_compiler(PLATFORMS["win64"]) is None,
                    reason="needs the Debian package gcc-mingw-w64-x86-64")
def test_your_own_modelica_model_gets_the_platforms_you_ask_for(tmp_path):
    """export_fmu (a user's model, not only the library's plants) takes the platforms too."""
    from duffid.modelica.export import export_fmu, library_path

    platforms, _ = resolve_platforms([HOST_PLATFORM.name, "win64"])
    fmu = export_fmu(library_path(), "Duffid.Examples.Oscillator1DOF", tmp_path / "Mine.fmu", 3, "cs",
                     platforms=platforms)
    with zipfile.ZipFile(fmu) as z:
        folders = {n.split("/")[1] for n in z.namelist() if n.startswith("binaries/") and n.count("/") == 2}
    assert folders == {HOST_PLATFORM.fmi3, "x86_64-windows"}
