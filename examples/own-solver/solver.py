"""A stand-in for your own solver, run by parcelfit as a command (``solver.yaml`` beside it).

parcelfit fills in ``params.tmpl``, writes it as ``params.txt`` into a fresh work folder and
runs, in that folder::

    python3 solver.py params.txt trajectory.csv RIG CONSIGNMENT SPEED_SETTING

A solver must then write ``trajectory.csv`` (columns t [s], x [m], y [m], theta [rad]: the
parcel's centre and heading in the rig's frame, at any rate) and may write ``transit.txt`` (the
transit time [s] between the rig's light barriers); it exits with status 0, or with another
status and a line on stderr saying what went wrong. Your solver runs its own model here. This
stand-in runs parcelfit's MuJoCo model of the rig and parcel of ``examples/own-rig`` through
``parcelfit simulate``, so that the example calibrates against that folder's dataset.
"""

import re
import subprocess
import sys
from pathlib import Path

params_file, output_file, rig, consignment, setting = sys.argv[1:6]
params = {}
for line in Path(params_file).read_text().splitlines():
    if "=" in line and not line.lstrip().startswith("#"):
        key, value = line.split("=", 1)
        params[key.strip()] = float(value)

own = Path(__file__).resolve().parent.parent / "own-rig"
command = [
    sys.executable,
    "-m",
    "parcelfit",
    "simulate",
    *("--rig", str(own / f"{rig}.yaml"), "--consignment", str(own / f"{consignment}.yaml")),
    *("--setting", setting, "--set", f"mu_d_BePa={params['mu_d_BePa']}", "--out", output_file),
]
done = subprocess.run(command, capture_output=True, text=True)
if done.returncode != 0:
    sys.stderr.write(done.stderr)
    sys.exit(done.returncode)
transit = re.search(r"transit time: ([0-9.eE+-]+) s", done.stdout)
if transit:  # no file: the run crossed no second light barrier
    Path("transit.txt").write_text(transit.group(1) + "\n")
