"""Image metrics (``draaw_mi.bench.metrics``): closed forms and side effects."""
from __future__ import annotations

import subprocess
import sys

import numpy as np

from draaw_mi.bench import metrics as image_metrics


def test_rmse_and_relmse_closed_forms():
    gt = np.full((2, 2, 3), 0.5)
    img = gt + np.array([0.1, -0.1, 0.0])
    assert np.isclose(image_metrics.rmse(img, gt), np.sqrt(0.02 / 3))
    assert np.isclose(image_metrics.relmse(img, gt), (0.02 / 3) / (0.25 + 1e-2))


def test_a_delta_e_leaves_numpy_print_options_as_they_were():
    """colour-science's import sets ``np.set_printoptions(legacy='1.13')`` for the process:
    after the first CIEDE2000 a user's arrays printed the old way (1e39 as
    9.9999999999999994e+38). Run in a fresh interpreter, where colour is not yet imported."""
    code = ("import numpy as np\n"
            "from draaw_mi.bench.metrics import ciede2000\n"
            "before = np.get_printoptions()\n"
            "ciede2000(np.full((2, 2, 3), 0.2), np.full((2, 2, 3), 0.3))\n"
            "import colour\n"
            "print(np.get_printoptions() == before, repr(np.float64(1e39)))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["True", "np.float64(1e+39)"], out
