"""The kernels' CPU target: recorded at build time, checked against the CPU on import."""

import platform

import pytest

from labauto.vision import kernels


def test_build_records_a_target_this_cpu_supports():
    from labauto.vision.kernels import _build

    flags = kernels.cpu_flags()
    if platform.machine().lower() in ("x86_64", "amd64"):
        assert _build.MARCH  # native unless LABAUTO_MARCH said otherwise
        assert "sse4_2" in _build.CPU_FEATURES  # every x86-64 target we build has it
    if flags is not None:
        assert set(_build.CPU_FEATURES) <= flags


def test_cpu_flags_reads_the_flags_line(tmp_path):
    cpuinfo = tmp_path / "cpuinfo"
    cpuinfo.write_text("processor\t: 0\nmodel name\t: Test CPU\nflags\t\t: fpu sse4_2 avx2\n\n")
    assert kernels.cpu_flags(str(cpuinfo)) == {"fpu", "sse4_2", "avx2"}
    assert kernels.cpu_flags(str(tmp_path / "missing")) is None


def test_check_cpu_names_each_missing_extension():
    kernels.check_cpu(("sse4_2", "avx2"), {"sse4_2", "avx2", "fpu"}, "native")
    kernels.check_cpu(("avx512f",), None, "native")  # flags unknown: no claim
    with pytest.raises(ImportError, match=r"-march=native .*avx2, avx512bw.*LABAUTO_MARCH"):
        kernels.check_cpu(("sse4_2", "avx2", "avx512bw"), {"sse4_2"}, "native")
