"""The device and the floating-point type a benchmark ran on, as every benchmark reports
them (`device`, `platform`, `device_kind`, `dtype`), and `--dtype` for the scripts that
take it. `run_all.py` keeps each device's figures under its `device` name."""

import os
import platform

import jax

DTYPES = ("float64", "float32")


def add_dtype_option(parser):
    """`--dtype float64|float32` (default float64: the papers' accuracy)."""
    parser.add_argument(
        "--dtype",
        choices=DTYPES,
        default="float64",
        help="float64 (default) or float32 (jax_enable_x64 off: every array float32)",
    )


def use_dtype(name: str) -> None:
    """Compute in `name`: float64 turns `jax_enable_x64` on, float32 leaves it off (the
    process computes in float32 throughout, as on a GPU without float64 throughput)."""
    if name not in DTYPES:
        raise ValueError(f"dtype must be one of {DTYPES}; got {name!r}.")
    jax.config.update("jax_enable_x64", name == "float64")


def device_name(device=None) -> str:
    """`"cpu: x86_64, 2 CPUs"` or `"gpu: NVIDIA H200"`: the key of a device's figures."""
    d = device or jax.devices()[0]
    if d.platform == "cpu":
        return f"cpu: {platform.machine()}, {os.cpu_count()} CPUs"
    return f"{d.platform}: {d.device_kind}"


def device_fields(dtype: str) -> dict:
    """What every benchmark's JSON records about where and in what it ran."""
    d = jax.devices()[0]
    return {
        "device": device_name(d),
        "platform": d.platform,
        "device_kind": d.device_kind,
        "dtype": dtype,
    }
