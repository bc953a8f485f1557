"""Fuzz the public geometry functions with well-posed, near-degenerate and invalid inputs.

Prints JSON: per function, dtype and kind of input, how many inputs came back
`correct` (successful and within tolerance of the truth), as a `clear_error` (a raised
error), as a `result_code` (a non-successful `visjax.RESULTS`, or NaN where the function's
docstring says NaN in gives NaN out), `silent_nonfinite` (reported successful with a NaN or
inf), or `silently_wrong` (reported successful, finite, and off the truth by more than the
tolerance). The aim: the last two are 0.

    python benchmarks/fuzz.py [--n 10000] [--dtype float64|float32] [--seed 0]

The cases are in `tests/fuzzing.py`; the test suite runs them on a few hundred inputs
(`tests/test_fuzz.py`).
"""

import argparse
import json
import os
import pathlib
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1]))  # the tests' helpers

# imports no JAX: the dtype is chosen first (`_setup`)
from tests.fuzzing import PARTS, fuzz  # noqa: E402


def _setup(dtype: str):
    if dtype == "float32":
        os.environ["JAX_ENABLE_X64"] = "0"
    import jax

    jax.config.update("jax_enable_x64", dtype == "float64")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=10_000, help="inputs per function and kind")
    parser.add_argument("--dtype", choices=("float64", "float32"), default="float64")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch", type=int, default=None, help="vmap batch size (default: n)")
    parser.add_argument("--parts", nargs="*", default=list(PARTS), choices=PARTS)
    args = parser.parse_args(argv)
    _setup(args.dtype)
    json.dump(fuzz(args.n, args.seed, args.dtype, args.batch, args.parts), sys.stdout, indent=1)
    print()


if __name__ == "__main__":
    main()
