"""The README's example runs as printed: its first Python block, executed in a fresh
namespace, studies 16 noise seeds in one call and differentiates each run through a gain."""

import re
from pathlib import Path

import numpy as np

README = Path(__file__).resolve().parents[1] / "README.md"


def _first_python_block() -> str:
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "README.md has no ```python block"
    return blocks[0]


def test_readme_example_runs_and_differentiates():
    namespace = {"__name__": "readme_example"}
    exec(compile(_first_python_block(), str(README), "exec"), namespace)

    errors = np.asarray(namespace["errors"])
    slopes = np.asarray(namespace["slopes"])
    assert errors.shape == slopes.shape == (16,), (errors.shape, slopes.shape)
    # every seed ran to the end: a finite, positive error and a finite gradient
    assert np.all(np.isfinite(errors)) and np.all(errors > 0), errors
    assert np.all(np.isfinite(slopes)) and np.all(slopes != 0), slopes
    # the seeds drew different noise (the vmap is over seeds, not one run repeated)
    assert np.ptp(errors) > 0, errors
    # what the README says it prints: 0.314 m/s and 0.096 (medians over the seeds)
    np.testing.assert_allclose(np.median(errors), 0.314, atol=1e-3)
    np.testing.assert_allclose(np.median(slopes), 0.096, atol=1e-3)
