"""Generate the SYNTHETIC E3 / KPBW twin dataset used by examples/e3-kpbw (speed settings 1, 2).

python scripts/make_e3_twin.py
"""

from pathlib import Path

from parcelfit.runs import TestCase
from parcelfit.synth import make_twin_dataset

OUT = Path(__file__).resolve().parents[1] / "examples" / "e3-kpbw" / "data"
TRUTH = {"KPBW": {"mu_d_BePa": 0.40, "mu_d_MePa": 0.30, "E_Pa": 600.0, "k_MePa": 400.0}}

if __name__ == "__main__":
    make_twin_dataset(
        OUT,
        [TestCase("E3", "KPBW", 1), TestCase("E3", "KPBW", 2)],
        TRUTH,
        seed=11,
        name="e3-kpbw-twin",
        progress=print,
    )
    print(f"wrote {OUT}")
