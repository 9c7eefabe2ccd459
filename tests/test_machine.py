"""The machine record of every result file: what decides its floating-point bits."""

from __future__ import annotations

import sys

import pytest

from distgprl import machine, schema


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc (Linux)")
def test_the_fingerprint_names_the_openblas_kernels_and_numpy_simd_targets_in_use():
    """numpy's wheel bundles OpenBLAS, which says which kernel family it picked; numpy's
    dispatch targets are those of its build that this CPU has."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    cores = machine.openblas_cores()
    assert cores and all(core and core.isprintable() for core in cores)
    fingerprint = machine.numerics_fingerprint()
    blas, simd = fingerprint.split("_numpy-")
    assert blas == "openblas-" + "+".join(cores)
    active = [t for t in __cpu_dispatch__ if __cpu_features__.get(t)]
    assert simd == ("+".join(active) or "baseline")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc (Linux)")
def test_the_fingerprint_does_not_depend_on_what_else_was_imported():
    """OpenCV bundles its own OpenBLAS (on a SkylakeX CPU it picks Prescott); results do not
    run through it, so importing it first must not change the fingerprint (the bit-exact
    trace test looks its recording up by fingerprint, after other tests imported cv2)."""
    import subprocess

    code = "from distgprl.machine import numerics_fingerprint as f; {}print(f())"
    prints = [
        subprocess.run(
            [sys.executable, "-c", code.format(first)],
            check=True, capture_output=True, text=True, timeout=120,
        ).stdout.strip()
        for first in ("", "import cv2; ")
    ]  # fmt: skip
    assert prints[0] == prints[1] == machine.numerics_fingerprint()


def test_every_result_file_records_the_machine(tmp_path):
    path = schema.write_json(tmp_path / "x.json", {"value": 1}, kind="test")
    meta = schema.read_json(path)["meta"]
    assert meta["machine"] == machine.machine_info()
    assert set(meta["machine"]) == {"cpu", "numerics"}
    assert meta["machine"]["numerics"] == machine.numerics_fingerprint()
